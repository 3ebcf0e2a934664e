"""One reader of run folders (issue 45 item 3): batch/run_folder.py opens metrics.json, finds a job's
images and makes the panel's RGB copies; the Blender panel, batch/compare_runs.py, the baseline and
the report call it. On a real run (and copies of it made hostile: paths through '..', absolute,
through a link out, with backslashes; odd scene names), the panel's image lookup, the report's
viewer and compare_runs name the same files, or all refuse; nothing above the reader builds a path
of a run folder itself."""
import ast
import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, run_batch, run_bpy, write_hand_made_metrics
from spectral_bench.batch import compare_runs, exr, records, run_folder
from spectral_bench.batch.report import html

SCENE, BACKEND = "macbeth_chart_D65", "mitsuba"
IMAGE = f"{SCENE}/results/{BACKEND}/render.exr"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A small real run: one Mitsuba render with two passes (its own noise: compare_runs judges it)."""
    out = tmp_path_factory.mktemp("run_folder") / "run"
    proc = run_batch("-r", BACKEND, "-s", SCENE, "--scale", 0.0625, "--spp", 4, "--passes", 2, "-o", out)
    assert (out / "metrics.json").is_file(), proc.stdout[-2000:] + proc.stderr[-2000:]
    return out


def _entry_of(folder):
    return json.loads((folder / "metrics.json").read_text())


def _hostile(tmp_path, run, variant):
    """(prev, new, scene): two copies of the run beside ``outside`` (a third copy, not theirs); in
    ``new`` the record made hostile as ``variant`` says (and the scene renamed in both where it says)."""
    prev, new, outside = tmp_path / "runs" / "prev", tmp_path / "runs" / "new", tmp_path / "outside"
    for folder in (prev, new, outside):
        shutil.copytree(run, folder, ignore=shutil.ignore_patterns("compare*", "*.js", "*_rgb.exr", "diff_*.exr"))
    scene = SCENE
    data, old = _entry_of(new), _entry_of(prev)
    e = data["runs"][0]
    e["status"] = old["runs"][0]["status"] = "failed"  # the report's tev line: every file it names
    ref = e["reference"]["image"]
    if variant == "as written":
        pass
    elif variant == "dotdot":
        e["image"] = f"../../outside/{IMAGE}"
    elif variant == "dots inside":
        e["image"] = f"{SCENE}/results/../results/{BACKEND}/render.exr"
    elif variant == "absolute inside":
        e["image"] = str(new / IMAGE)
    elif variant == "absolute outside":
        e["image"] = str(outside / IMAGE)
    elif variant == "link out":
        os.symlink(outside / SCENE, new / "linked")
        e["image"] = f"linked/results/{BACKEND}/render.exr"
    elif variant == "render is a link out":
        render = new / IMAGE
        render.unlink()
        os.symlink(outside / IMAGE, render)
    elif variant == "backslashes":
        e["image"] = IMAGE.replace("/", "\\")
    elif variant == "reference outside":
        e["reference"]["image"] = f"../../outside/{ref}"
    elif variant == "reference through a link":
        (new / ref).unlink()
        os.symlink(outside / ref, new / ref)
    elif variant in ("dotted scene", "scene '..'"):
        scene = "chart.v1..2" if variant == "dotted scene" else ".."
        for folder, d in ((new, data), (prev, old)):
            r = d["runs"][0]
            r["scene"] = scene
            if variant == "dotted scene":
                (folder / SCENE).rename(folder / scene)
                r["image"], r["reference"]["image"] = (x.replace(SCENE, scene, 1) for x in (r["image"], r["reference"]["image"]))
        if variant == "scene '..'":
            data["runs"][0]["image"] = f"../outside/{IMAGE}"
    else:
        raise AssertionError(variant)
    write_hand_made_metrics(new, data)
    write_hand_made_metrics(prev, old)
    return prev, new, scene


EXPECT = {  # variant: (render found, reference found)
    "as written": (True, True), "dotdot": (False, False), "dots inside": (False, False),
    "absolute inside": (False, False), "absolute outside": (False, False), "link out": (False, False),
    "render is a link out": (False, False), "backslashes": (True, True), "reference outside": (True, False),
    "reference through a link": (True, False), "dotted scene": (True, True), "scene '..'": (False, False)}


def _report_files(new, scene):
    """What the report's viewer of the job shows: {kind: path} from its tev line and views, or None
    when it shows no viewer."""
    data = html.load(new)
    entry = next(r for r in data["runs"] if r.get("scene") == scene)
    viewer = html._viewer(new, entry, {})
    if viewer is None:
        return None
    files = viewer["tev"].split()[1:]
    out = {"render": new / files[0]}
    named = {Path(f).name: new / f for f in files[1:]}
    for kind in ("zscore", "flip", "block_stderr"):
        if run_folder.JOB_FILES[kind] in named:
            out[kind] = named.pop(run_folder.JOB_FILES[kind])
    if "reference" in viewer["views"]:
        out["reference"] = next(iter(named.values()))
    assert ("z-score" in viewer["views"]) == ("zscore" in out) and ("FLIP" in viewer["views"]) == ("flip" in out)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("variant", sorted(EXPECT))
def test_the_panel_the_report_and_compare_runs_find_the_same_files(run, tmp_path, variant):
    prev, new, scene = _hostile(tmp_path, run, variant)
    has_render, has_ref = EXPECT[variant]
    job = run_folder.job(new, scene, BACKEND)  # what the panel's load_result_image and image_kinds call
    panel = {k: job.path(k) for k in ("render", "reference", "zscore", "flip", "block_stderr")}
    assert (panel["render"] is not None) == has_render and (panel["reference"] is not None) == has_ref, panel
    for p in filter(None, panel.values()):  # nothing the reader gives leaves the folder
        assert p.resolve().is_relative_to(new.resolve()), p
    report = _report_files(new, scene)
    assert (report or {}) == {k: p for k, p in panel.items() if p is not None}
    kinds = job.kinds()
    assert ("diff_abs" in kinds) == (has_render and has_ref) and ("render" in kinds) == has_render

    result, cmp_dir, _text = compare_runs.run(prev, new)
    rec = result["jobs"][0]["baseline"]
    if has_render:
        assert rec["status"] in ("same", "changed"), rec
        # the z-map goes below the same job folder the panel and the report found
        assert rec["zmap"] == (panel["render"].parent.relative_to(new) / run_folder.ZMAP).as_posix()
        found = run_folder.baseline_records(new, run_folder.load(new), prev).get((scene, BACKEND))
        assert run_folder.baseline_image(found, "baseline_zscore") == cmp_dir / rec["zmap"]
        assert run_folder.baseline_image(found, "baseline_render").resolve() == run_folder.job(prev, scene, BACKEND).path("render").resolve()
    else:
        assert rec["status"] == "unjudged" and "is not a file inside its run folder" in rec["reason"], rec
    # and the page links only files inside the folder
    page = html.render(new)
    for src in re.findall(r"""(?:src|href)=['"]([^'"#]+)['"]""", page):
        if "://" not in src and not src.startswith(("data:", "?")):
            assert (new / src).resolve().is_relative_to(new.resolve()), src


@pytest.mark.slow
def test_the_real_panel_loads_what_the_reader_names(run, tmp_path):
    """Real bpy: the panel's image buttons and load_result_image for the run as written and for a
    hostile copy (its render behind '..'): the same files as run_folder, none outside."""
    prev, new, _ = _hostile(tmp_path, run, "as written")
    bad = tmp_path / "bad"
    shutil.copytree(new, bad, symlinks=True)
    data = _entry_of(bad)
    data["runs"][0]["image"] = f"../outside/{IMAGE}"
    write_hand_made_metrics(bad, data)
    out = run_bpy(f"""
        from spectral_bench.addon import benchmark
        res = {{}}
        for folder in ({str(new)!r}, {str(bad)!r}):
            kinds = benchmark.image_kinds(folder, {SCENE!r}, {BACKEND!r})
            loaded = {{}}
            for kind in ("render", "reference", "zscore", "flip", "diff_abs"):
                try:
                    loaded[kind] = bpy.path.abspath(benchmark.load_result_image(folder, {SCENE!r}, {BACKEND!r}, kind).filepath)
                except FileNotFoundError:
                    loaded[kind] = None
            res[folder] = {{"kinds": kinds, "loaded": loaded}}
        print(json.dumps(res))
    """)
    job = run_folder.job(new, SCENE, BACKEND)
    assert out[str(new)]["kinds"] == job.kinds() and {"render", "reference", "diff_abs", "zscore"} <= set(job.kinds())
    for kind, path in out[str(new)]["loaded"].items():
        if kind not in job.kinds():  # FLIP: computed only where the verdict is not ok
            assert path is None, kind
            continue
        assert Path(path) == run_folder.plain_rgb(job.path(kind)), kind  # the render's RGB copy beside it
    assert out[str(bad)] == {"kinds": [], "loaded": dict.fromkeys(("render", "reference", "zscore", "flip", "diff_abs"))}


@pytest.mark.slow
def test_plain_rgb_copies_a_layered_render_and_keeps_an_rgb_one(run, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(run, out)
    job = run_folder.job(out, SCENE, BACKEND)
    render = job.path("render")
    assert set(exr.read(render)) > {"R", "G", "B"}  # two passes: the render carries its standard error
    rgb = run_folder.plain_rgb(render)
    assert rgb == render.with_name("render_rgb.exr") and set(exr.read(rgb)) == {"R", "G", "B"}
    assert np.array_equal(exr.read_rgb(rgb), exr.read_rgb(render))
    assert run_folder.plain_rgb(job.path("zscore")) == job.path("zscore")


@pytest.mark.slow
def test_strict_and_lenient_reads_name_the_problem(run, tmp_path):
    with pytest.raises(run_folder.NotARun, match="no such folder"):
        run_folder.read(tmp_path / "nowhere")
    with pytest.raises(run_folder.NotARun, match="holds no metrics.json"):
        run_folder.read(tmp_path)
    assert run_folder.load(tmp_path) is None and run_folder.last_status(tmp_path) == {}
    newer = tmp_path / "newer"
    shutil.copytree(run, newer)
    data = _entry_of(newer)
    data["schema_version"] = records.SCHEMA_VERSION + 1
    write_hand_made_metrics(newer, data)
    with pytest.raises(run_folder.NotARun, match="newer spectral_bench"):
        run_folder.read(newer)
    lenient = run_folder.load(newer)
    assert lenient.problems and run_folder.job(newer, SCENE, BACKEND).path("render") == newer / IMAGE
    write_hand_made_metrics(newer, "[1, 2")
    assert run_folder.load(newer) is None and run_folder.job(newer, SCENE, BACKEND).path("render") is None
    assert run_folder.read(run)["runs"][0]["image"] == IMAGE  # paths relative to the folder, as the file holds them


# -- nothing above the reader builds a run folder's paths ------------------------------------------
READERS = sorted([*(ROOT / "addon").glob("*.py"), *(ROOT / "batch" / "report").glob("*.py"),
                  ROOT / "batch" / "compare_runs.py", ROOT / "batch" / "verdict" / "baseline.py"])
# the names of a run folder's files and folders, which only the reader and the writers spell
FOLDER_NAMES = re.compile(r"^results$|(^|/)(render|zscore|flip|reference|block_stderr|probe_residual|diff_abs|"
                          r"diff_rel|baseline_zscore)\.(exr|png)$|^metrics\.json$|^stokes_$|^_rgb\.exr$|"
                          r"^reference_$|^reference_\d+x\d+\.exr$|(^|/)json/|^summary\.md$|^report\.html$")
WRITERS = {("batch/report/summary.py", "summary.md"),  # the file it writes
           ("batch/report/html.py", "report.html")}   # its template's name
RULES = {"inside_parts", "FILE_NAME", "BLOCK_STDERR", "PROBE_RESIDUAL", "resolved", "shared_reference_name"}


def _strings_and_names(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and n.body and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    for n in ast.walk(tree):
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs:
            yield n.lineno, n.value
        elif isinstance(n, ast.Attribute):
            yield n.lineno, f".{n.attr}"
            if n.attr == "read" and isinstance(n.value, ast.Name) and n.value.id == "records":
                yield n.lineno, "records.read"


def test_nothing_above_the_reader_builds_a_run_folders_paths():
    """The panel (addon/), the report (batch/report/), compare_runs and the baseline name no file or
    folder of a run folder (render.exr, "results", metrics.json, ...) and call neither the rule nor
    batch/records.py's reader: batch/run_folder.py does (the writers, batch/jobs/ and
    batch/verdict/judge.py, spell the names they write)."""
    found = []
    for path in READERS:
        for line, text in _strings_and_names(path):
            if (str(path.relative_to(ROOT)), text) in WRITERS:
                continue
            if FOLDER_NAMES.search(text) or text.lstrip(".") in RULES or text == "records.read":
                found.append(f"{path.relative_to(ROOT)}:{line}: {text!r}")
    assert not found, "\n".join(found)


def test_the_rule_is_spelt_once():
    """records.inside_parts (the rule: relative, no '..', no link out) is called by the reader and by
    records' own array files only."""
    callers = sorted(str(p.relative_to(ROOT)) for top in ("addon", "batch", "exporters")
                     for p in (ROOT / top).rglob("*.py") if "inside_parts" in p.read_text(encoding="utf-8"))
    assert callers == ["batch/records.py", "batch/run_folder.py"]


def test_the_planted_checks_catch_a_path_built_above_the_reader(tmp_path):
    """The check above sees a path built in a reader (not only in its docstring)."""
    p = tmp_path / "x.py"
    p.write_text('"""render.exr in a docstring is fine"""\n\ndef f(out, scene):\n'
                 '    return out / scene / "results" / "mitsuba" / "render.exr"\n')
    hits = [t for _line, t in _strings_and_names(p) if FOLDER_NAMES.search(t)]
    assert sorted(hits) == ["render.exr", "results"]
