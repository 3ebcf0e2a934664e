"""The pbrt-v4 writer (exporters/pbrt_writer.py): every IR parameter it maps, read back from the
written scene.pbrt by a small parser of pbrt's format (directives, typed parameter lists); the
light normalisation; what pbrt-v4 cannot express named per object and field; hostile names; the
golden files. Rendering the exports with pbrt itself is tests/backends/test_pbrt.py's part."""
import copy
import json
import re
import shlex

import numpy as np
import pytest

import scene_fuzz
from conftest import ALL_SCENES, ROOT, metrics, run_batch
from spectral_bench.exporters import dispersion, ir, names, pbrt_writer, spectra

GOLDEN_PBRT = ROOT / "golden" / "pbrt"
# the canonical scenes pbrt-v4 can express exactly (the rest: test_unsupported_canonical_scenes)
EXPRESSIBLE = sorted({"dispersion_fringes", "ggx_glass", "macbeth_chart_D50", "macbeth_chart_D65", "yellow_sphere_F8",
                      *(f"ggx_copper_{a}{s}" for a in (50, 60, 70, 80) for s in ("", "_isolated")), "ggx_copper_grazing"})


# -- a reader of the written format --------------------------------------------------------------
def _tokens(text):
    """pbrt's tokens: comments dropped, strings kept quoted, brackets apart."""
    lex = shlex.shlex(text, posix=False, punctuation_chars="[]")
    lex.commenters = "#"
    lex.wordchars += ".-+:/"
    lex.whitespace_split = False
    return [t for t in lex]


def parse(path):
    """[(directive, first argument or None, {name: (type, [values])})] of a .pbrt file."""
    toks, out, i = _tokens(path.read_text()), [], 0
    while i < len(toks):
        directive = toks[i]
        assert re.fullmatch(r"[A-Z][A-Za-z]+", directive), (directive, toks[i - 5:i + 5])
        i += 1
        args = []
        while i < len(toks) and not re.fullmatch(r"[A-Z][A-Za-z]+", toks[i]):
            args.append(toks[i])
            i += 1
        first, params = None, {}
        if directive in ("Transform", "Translate"):
            nums = [a for a in args if a not in "[]"]
            out.append((directive, [float(x) for x in nums], {}))
            continue
        j = 0
        if args and args[0].startswith('"'):
            first = args[0].strip('"')
            j = 1
        while j < len(args):
            decl = args[j].strip('"').split()
            assert len(decl) == 2, (directive, args[j])
            j += 1
            values = []
            if args[j] == "[":
                j += 1
                while args[j] != "]":
                    values.append(args[j])
                    j += 1
                j += 1
            else:
                values.append(args[j])
                j += 1
            kind = decl[0]
            conv = {"float": float, "integer": int, "spectrum": float, "point3": float,
                    "bool": lambda v: v == "true", "string": lambda v: v.strip('"')}[kind]
            params[decl[1]] = (kind, [conv(v) for v in values])
        out.append((directive, first, params))
    return out


def blocks(parsed):
    """The directives of each AttributeBegin ... AttributeEnd, in order."""
    out, cur = [], None
    for d in parsed:
        if d[0] == "AttributeBegin":
            cur = []
        elif d[0] == "AttributeEnd":
            out.append(cur)
            cur = None
        elif cur is not None:
            cur.append(d)
    return out


def one(parsed, directive, first=None):
    found = [d for d in parsed if d[0] == directive and (first is None or d[1] == first)]
    assert len(found) == 1, (directive, first, len(found))
    return found[0]


def spectrum(params, name):
    kind, v = params[name]
    assert kind == "spectrum"
    return np.array(v[0::2]), np.array(v[1::2])


def y_sum(wl, vals):
    """pbrt's SpectrumToPhotometric: the CIE Y table times the spectrum at every whole nanometre."""
    cmf_wl, _x, yb, _z = spectra.cie_1931_cmfs()
    return float(np.sum(yb * np.interp(cmf_wl, wl, vals)))


def write(scene, tmp_path, name="out"):
    return parse(pbrt_writer.write(scene, tmp_path / name))


def _obj(scene, name):
    return next(o for o in scene["objects"] if o["name"] == name)


def _block_of(parsed, scene, name):
    """The attribute block written for object ``name`` (objects are written in order)."""
    written = [o["name"] for o in scene["objects"]]
    return blocks(parsed)[written.index(name)]


# -- golden ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ALL_SCENES)
def test_writer_output_matches_golden_folder(golden, tmp_path, name):
    """Any change of the pbrt writer shows as a reviewable diff of golden/pbrt/ (regenerate with
    scripts/update_golden.py)."""
    expected = GOLDEN_PBRT / name
    pbrt_writer.write(golden[name], tmp_path)
    written = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if p.is_file())
    assert written == sorted(p.relative_to(expected) for p in expected.rglob("*") if p.is_file())
    for rel in written:
        assert (tmp_path / rel).read_bytes() == (expected / rel).read_bytes(), rel  # meshes are binary PLY


@pytest.mark.parametrize("name", ALL_SCENES)
def test_every_golden_file_parses_and_names_what_it_left_out(golden, name):
    parsed = parse(GOLDEN_PBRT / name / "scene.pbrt")
    assert [d[0] for d in parsed].count("WorldBegin") == 1
    text = (GOLDEN_PBRT / name / "scene.pbrt").read_text()
    problems = pbrt_writer.unsupported(golden[name])
    assert (name in EXPRESSIBLE) == (not problems), problems
    for o, f, _m in problems:
        assert f"# NOT EXPRESSED (left out): {names.comment_text(o)}.{f}" in text


