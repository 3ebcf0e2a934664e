"""Observer layers against hostile names, records and files (issue 40, items 1, 7 and 10 in part).

A scene name may hold dots: the old layer file ``<scene>.<observer>.exr`` beside the reference
was also the reference of a scene named ``<scene>.<observer>``, and a layer written there replaced
that reference without a word. Layers now live in ``layers/<scene>/<observer>.exr`` (a folder no
scene name reaches); a folder still in the old layout is read with a clear message, migrated with
``--migrate-layers``, and a write that would replace another scene's file is refused, naming both.
An observer-layer record or file that cannot be used never fails a verdict: the reference is used
and the layer is one of the run's reference problems. ``--layers-only`` at another ``--scale`` than
the reference's is a usage error naming the scene and both sizes.

Real renders throughout (a 16x16 scene through the real batch/make_references.py and
batch/run.py in child processes), real EXR files."""
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, metrics, run_batch
from spectral_bench.batch import exr
from spectral_bench.batch.verdict import observer_layers, references

SMALL = ["--spp", "8", "--passes", "2"]


def maker(*args, timeout=600):
    return subprocess.run([sys.executable, str(ROOT / "batch" / "make_references.py"), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def tiny_scene(folder, name):
    """ggx_copper_50_isolated as a 16x16 scene named ``name``, written as ``<name>.json``."""
    scene = json.loads((ROOT / "golden" / "ir" / "ggx_copper_50_isolated.json").read_text())
    scene["name"] = name
    scene["render"].update(width=16, height=16, spp=8)
    path = folder / f"{name}.json"
    path.write_text(json.dumps(scene))
    return path


def layer_path(folder, scene, obs="mitsuba3"):
    return observer_layers.path_for(folder / f"{scene}.exr", obs)


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """The issue's two commands, in its order: the reference of a scene named ``tiny.mitsuba3``,
    then scene ``tiny`` through the CMF film with its ``mitsuba3`` layer, into one folder."""
    root = tmp_path_factory.mktemp("layers")
    scenes = root / "scenes"
    scenes.mkdir()
    refs = root / "refs"
    first = maker("-i", tiny_scene(scenes, "tiny.mitsuba3"), "--out", refs, *SMALL)
    assert first.returncode == 0, first.stdout + first.stderr
    before = {p.name: p.read_bytes() for p in refs.iterdir() if p.is_file()}
    second = maker("-i", tiny_scene(scenes, "tiny"), "--film", "cmf", "--layers", "mitsuba3", "--out", refs, *SMALL)
    return scenes, refs, before, second


@pytest.mark.slow
def test_a_layer_never_replaces_the_reference_of_a_scene_named_like_it(made):
    scenes, refs, before, second = made
    assert second.returncode == 0, second.stdout + second.stderr
    assert before.keys() == {"tiny.mitsuba3.exr", "tiny.mitsuba3.json"}
    for name, data in before.items():  # the first scene's reference, byte for byte
        assert (refs / name).read_bytes() == data, name
    found = references.search("tiny.mitsuba3", refs)
    assert found.ref is not None and found.problems == [], found.problems
    tiny = references.load("tiny", refs)
    layers, bad = observer_layers.check(tiny)
    assert set(layers) == {"mitsuba3"} and bad == {}
    assert layer_path(refs, "tiny") == refs / "layers" / "tiny" / "mitsuba3.exr"
    assert tiny.provenance["observer_layers"]["mitsuba3"]["file"] == "layers/tiny/mitsuba3.exr"


def _old_layout(refs, folder, scene):
    """``scene``'s reference copied from ``refs`` into ``folder`` with its layer where it was kept
    before issue 40 (``<scene>.mitsuba3.exr`` beside the reference, its record naming that file): a
    references folder as an older checkout holds it."""
    for f in (f"{scene}.exr", f"{scene}.json"):
        shutil.copy(refs / f, folder / f)
    meta = json.loads((folder / f"{scene}.json").read_text())
    old = folder / f"{scene}.mitsuba3.exr"
    shutil.copy(refs / meta["observer_layers"]["mitsuba3"]["file"], old)
    meta["observer_layers"]["mitsuba3"]["file"] = old.name
    (folder / f"{scene}.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return old


@pytest.mark.slow
def test_an_old_layout_is_named_refused_as_another_scenes_file_and_migrated(made, tmp_path):
    scenes, refs, _before, _second = made
    folder = tmp_path / "refs"
    folder.mkdir()
    old = _old_layout(refs, folder, "tiny")
    data = old.read_bytes()
    # read where it is? no: that name is scene tiny.mitsuba3's reference; the problem says what to do
    tiny = references.load("tiny", folder)
    assert tiny is not None and observer_layers.load(tiny) == {}
    why = observer_layers.problem_of(tiny)
    assert "old layout" in why and "--migrate-layers" in why and f"--out {folder}" in why
    # a reference of scene tiny.mitsuba3 would replace scene tiny's layer: refused, naming both, nothing rendered
    proc = maker("-i", scenes / "tiny.mitsuba3.json", "--out", folder, "--replace", *SMALL)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "tiny.mitsuba3: refusing to write its reference" in proc.stdout
    assert "scene 'tiny''s observer layer mitsuba3 in the old layout" in proc.stdout
    assert old.read_bytes() == data and not (folder / "history").exists() and not (folder / "tiny.mitsuba3.json").exists()
    # migrated: the same bytes in the new place, the record pointing there, the layer used again
    proc = maker("--migrate-layers", "--out", folder, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"tiny: {old} -> {layer_path(folder, 'tiny')}" in proc.stdout
    assert not old.exists() and layer_path(folder, "tiny").read_bytes() == data
    tiny = references.load("tiny", folder)
    assert tiny.provenance["observer_layers"]["mitsuba3"]["file"] == "layers/tiny/mitsuba3.exr"
    assert set(observer_layers.load(tiny)) == {"mitsuba3"} and observer_layers.problem_of(tiny) is None
    # and now scene tiny.mitsuba3 has its own place
    proc = maker("-i", scenes / "tiny.mitsuba3.json", "--out", folder, *SMALL)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert references.search("tiny.mitsuba3", folder).ref is not None
    assert layer_path(folder, "tiny").read_bytes() == data


@pytest.mark.slow
def test_a_reference_of_a_name_differing_in_case_is_not_replaced(made, tmp_path):
    """Where a file system ignores case, tiny.json is TINY's record: a reference of scene tiny would
    replace scene TINY's. Refused, naming both, before anything renders (shown here on a record that
    says so: on this file system the two names are two files)."""
    scenes, refs, _before, _second = made
    folder = tmp_path / "refs"
    folder.mkdir()
    for f in ("tiny.exr", "tiny.json"):
        shutil.copy(refs / f, folder / f)
    meta = json.loads((folder / "tiny.json").read_text())
    (folder / "tiny.json").write_text(json.dumps(dict(meta, scene="TINY"), indent=1, sort_keys=True) + "\n")
    before = {f: (folder / f).read_bytes() for f in ("tiny.exr", "tiny.json")}
    proc = maker("-i", scenes / "tiny.json", "--out", folder, "--replace", *SMALL)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "tiny: refusing to write its reference" in proc.stdout and "record of scene 'TINY'" in proc.stdout
    assert {f: (folder / f).read_bytes() for f in before} == before and not (folder / "history").exists()
    assert not (folder / ".work" / "tiny").exists()  # nothing rendered


@pytest.mark.slow
def test_layers_only_at_another_scale_is_a_usage_error_naming_scene_and_sizes(made, tmp_path):
    scenes, refs, _before, _second = made
    folder = tmp_path / "refs"
    folder.mkdir()
    for f in ("tiny.exr", "tiny.json"):
        shutil.copy(refs / f, folder / f)
    record = (folder / "tiny.json").read_bytes()
    proc = maker("-i", scenes / "tiny.json", "--film", "cmf", "--layers", "mitsuba3", "--layers-only",
                 "--scale", "0.5", "--out", folder, *SMALL)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "--scale 0.5: scene tiny's reference" in proc.stderr and "is 16x16" in proc.stderr
    assert "would be 8x8" in proc.stderr and "broadcast" not in proc.stdout + proc.stderr
    assert (folder / "tiny.json").read_bytes() == record and not (folder / "layers").exists()
    assert not (folder / ".work" / ".layers").exists()  # nothing rendered


# -- item 7: an unusable layer never fails a verdict -------------------------------------------------
def _copy_with_layer(name, folder):
    """A committed reference and its mitsuba3 layer copied into ``folder`` (whatever layout this
    checkout keeps them in: the record says where)."""
    folder.mkdir(parents=True, exist_ok=True)
    for suffix in (".exr", ".json"):
        shutil.copy(ROOT / "references" / f"{name}{suffix}", folder)
    rel = json.loads((folder / f"{name}.json").read_text())["observer_layers"]["mitsuba3"]["file"]
    target = layer_path(folder, name)
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(ROOT / "references" / rel, target)
    return folder / f"{name}.json", target


def _record(meta_path, edit):
    meta = json.loads(meta_path.read_text())
    edit(meta["observer_layers"])
    meta_path.write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")


def _long_key(meta_path, target):
    """A key that is no observer's name and longer than 40 characters (shown cut short)."""
    _record(meta_path, lambda layers: layers.update({"../" + "x" * 60: {"sha256": "0" * 64, "file": "x"}}))
    return meta_path


def _wrong_size(meta_path, target):
    """A well-formed layer file of another size than the reference, its hash recorded."""
    exr.write_channels(target, {c: np.zeros((16, 16), np.float32) for c in
                                ("R", "G", "B", "stderr.R", "stderr.G", "stderr.B")})
    _record(meta_path, lambda layers: layers["mitsuba3"].update(sha256=references.sha256_of(target)))
    return target


def _corrupt(meta_path, target):
    """A layer file cut short, its hash recorded (a writer that recorded a bad file)."""
    data = target.read_bytes()
    target.write_bytes(data[: len(data) // 3])
    _record(meta_path, lambda layers: layers["mitsuba3"].update(sha256=references.sha256_of(target)))
    return target


@pytest.mark.slow
def test_an_unusable_layer_is_a_reference_problem_and_the_verdict_stands(tmp_path):
    """Three scenes, each with a different unusable layer record or file: every render is judged
    against its reference (the noise test runs), and each layer is a reference problem with its
    file in metrics.json, the console and summary.md."""
    faults = {"ggx_copper_50_isolated": _long_key, "ggx_copper_60_isolated": _wrong_size,
              "ggx_copper_70_isolated": _corrupt}
    folder = tmp_path / "refs"
    bad_file = {name: fault(*_copy_with_layer(name, folder)) for name, fault in faults.items()}
    out = tmp_path / "out"
    proc = run_batch("-i", *[ROOT / "golden" / "ir" / f"{n}.json" for n in faults], "--scale", "0.0625", "--spp", "4",
                     "-r", "mitsuba", "--references", folder, "-o", out)
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert set(runs) == set(faults), proc.stdout[-2000:] + proc.stderr[-3000:]
    assert "verdict failed" not in proc.stdout + proc.stderr
    summary = (out / "summary.md").read_text()
    for name, r in runs.items():
        assert "verdict failed" not in str(r.get("reason")), r.get("reason")
        assert r["reference"]["path"] == str(folder / f"{name}.exr")
        assert r["test"].get("p_min") is not None, r["test"]  # judged against the reference
        layer = [p for p in r["reference_problems"] if "observer layer" in p["problem"]]
        assert [p["file"] for p in layer] == [str(bad_file[name])], r["reference_problems"]
        assert "the reference itself is used" in layer[0]["problem"]
        assert r["reference"]["observer_layers_problem"]
        assert str(bad_file[name]) in summary
        assert f"{bad_file[name]}: {layer[0]['problem']}" in proc.stdout + proc.stderr
    assert "mitsuba3" in runs["ggx_copper_50_isolated"]["reference"]["observer_layers"]  # the sound layer still used
