"""Broken, wrong-sized and stale references (issue 18): every folder's candidate is checked, a bad
one is passed over for the next folder and reported with its file (metrics.json, console,
summary.md, the panel); a render judged without a usable reference says so. References are
saved as one step (a crash between the two renames is seen, never a new image with an old
record), by one maker at a time, and never replaced unless asked.

Real files throughout: committed references copied into temporary folders and damaged, real
tiny runs of the command line, real Blender drawing."""
import json
import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from conftest import ROOT, metrics, run_batch, run_bpy
from spectral_bench.batch import exr
from spectral_bench.batch.verdict import judge, references

TESTS = str(ROOT / "tests")
SCALE = ["--scale", "0.0625", "--spp", "4", "-r", "mitsuba"]  # 512x512 scenes render at 32x32
SHAPE, NAMES = (32, 32, 3), ["R", "G", "B"]


def _copy(name, folder):
    """A committed reference, whole: its image, its record and its observer layers (an unusable
    layer is a reference problem of its own, issue 40)."""
    folder.mkdir(parents=True, exist_ok=True)
    for suffix in (".exr", ".json"):
        shutil.copy(ROOT / "references" / f"{name}{suffix}", folder)
    if (ROOT / "references" / "layers" / name).is_dir():
        shutil.copytree(ROOT / "references" / "layers" / name, folder / "layers" / name)
    return folder / f"{name}.exr", folder / f"{name}.json"


def _rehash(exr_path, meta_path):
    """The record describes the damaged image (a writer that wrote a bad pair consistently), so that
    the check under test, not the sha256 that guards every pair first, is what refuses it."""
    meta = json.loads(meta_path.read_text())
    if "exr_sha256" in meta:
        meta_path.write_text(json.dumps(dict(meta, exr_sha256=references.sha256_of(exr_path))))


def damage(kind, name, folder):
    """A committed reference copied into ``folder`` and damaged; returns (the file at fault, a
    word its problem must contain)."""
    exr_path, meta_path = _copy(name, folder)
    try:
        return _damage(kind, exr_path, meta_path)
    finally:
        if kind in ("truncated", "wrong_size", "no_noise"):
            _rehash(exr_path, meta_path)


def _damage(kind, exr_path, meta_path):
    if kind == "truncated":
        data = exr_path.read_bytes()
        exr_path.write_bytes(data[: len(data) // 3])
        return exr_path, "unreadable EXR"
    if kind == "wrong_size":  # a real reference of 500x500: no integer multiple of a 32x32 render
        names, mean, stderr = exr.read_image_and_stderr(exr_path)
        exr.write_image(exr_path, names, mean[:500, :500],
                        {f"stderr.{n}": stderr[:500, :500, i] for i, n in enumerate(names)})
        meta = json.loads(meta_path.read_text())
        meta_path.write_text(json.dumps(dict(meta, resolution=[500, 500])))
        return exr_path, "cannot judge a 32x32 render"
    if kind == "corrupt_json":
        meta_path.write_text(meta_path.read_text()[:40])
        return meta_path, "unreadable record"
    if kind == "stale":
        meta = json.loads(meta_path.read_text())
        meta_path.write_text(json.dumps(dict(meta, fingerprint="0" * 64)))
        return exr_path, "stale"
    if kind == "no_noise":
        names, mean, _stderr = exr.read_image_and_stderr(exr_path)
        exr.write_image(exr_path, names, mean)
        return exr_path, "noise channels"
    if kind == "mismatched_pair":  # a record naming another image (an interrupted save)
        meta = json.loads(meta_path.read_text())
        meta_path.write_text(json.dumps(dict(meta, exr_sha256="1" * 64)))
        return exr_path, "sha256 differs"
    if kind == "no_record":
        meta_path.unlink()
        return exr_path, "no record"
    raise ValueError(kind)


KINDS = ["truncated", "wrong_size", "corrupt_json", "stale", "no_noise", "mismatched_pair", "no_record"]


@pytest.mark.parametrize("kind", KINDS)
def test_a_bad_candidate_is_passed_over_for_the_next_folder(tmp_path, golden, kind):
    name = "ggx_copper_50_isolated"
    bad_file, word = damage(kind, name, tmp_path / "A")
    good, _ = _copy(name, tmp_path / "B")
    scene = golden[name]
    ref, unusable, problems = judge.find_reference(name, scene, [tmp_path / "A", tmp_path / "B"],
                                                   shape=SHAPE, names=NAMES)
    assert unusable is None and ref.path == good
    assert [p["file"] for p in problems] == [str(bad_file)] and word in problems[0]["problem"], problems
    # the older entry point passes it over too (the extension's callers)
    assert references.load(name, [tmp_path / "A", tmp_path / "B"], scene=scene, shape=SHAPE).path == good
    # alone, it is no reference, and the reason names the file
    ref, unusable, problems = judge.find_reference(name, scene, [tmp_path / "A"], shape=SHAPE, names=NAMES)
    assert ref is None and str(bad_file) in unusable and word in unusable


def test_references_without_a_recorded_hash_are_accepted(golden, tmp_path):
    """Records written before the image's sha256 was recorded stay usable as they are."""
    name = "ggx_copper_50_isolated"
    exr_path, meta_path = _copy(name, tmp_path)
    meta = json.loads(meta_path.read_text())
    del meta["exr_sha256"]
    meta_path.write_text(json.dumps(meta))
    found = references.search(name, tmp_path, scene=golden[name], shape=SHAPE, names=NAMES)
    assert found.ref.path == exr_path and found.problems == []


@pytest.mark.slow
def test_a_run_uses_the_next_folder_and_names_every_problem(tmp_path):
    """Four scenes, each with a different fault in the first folder and a sound reference in the
    second: every render is judged against the second, and every problem is listed with its file
    in metrics.json, the console and summary.md."""
    faults = {"ggx_copper_50_isolated": "truncated", "ggx_copper_60_isolated": "wrong_size",
              "ggx_copper_70_isolated": "corrupt_json", "ggx_copper_80_isolated": "stale"}
    want = {}
    for name, kind in faults.items():
        want[name] = damage(kind, name, tmp_path / "A")
        _copy(name, tmp_path / "B")
    out = tmp_path / "out"
    proc = run_batch("-i", *[ROOT / "golden" / "ir" / f"{n}.json" for n in faults], *SCALE,
                     "--references", tmp_path / "A", "--references", tmp_path / "B", "-o", out)
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert set(runs) == set(faults), proc.stderr[-3000:]
    summary = (out / "summary.md").read_text()
    assert "## Reference problems" in summary
    for name, (bad_file, word) in want.items():
        r = runs[name]
        assert r["reference"]["path"] == str(tmp_path / "B" / f"{name}.exr"), r
        assert r["test"].get("p_min") is not None  # judged against it
        assert [p["file"] for p in r["reference_problems"]] == [str(bad_file)]
        problem = r["reference_problems"][0]["problem"]
        assert word in problem
        assert f"| {bad_file} | {problem.replace('|', '/')} | {name} / mitsuba" in summary
        assert f"{bad_file}: {problem}" in proc.stdout + proc.stderr  # the console, one line per problem


@pytest.mark.slow
def test_with_no_usable_reference_the_reason_says_judged_without_it(tmp_path):
    """Every reference bad: the renders are judged by their probes, and the reason, the summary
    and metrics.json say that they were judged without a reference and why."""
    faults = {"ggx_copper_50_isolated": "truncated", "ggx_copper_80_isolated": "stale"}
    want = {name: damage(kind, name, tmp_path / "A") for name, kind in faults.items()}
    out = tmp_path / "out"
    proc = run_batch("-i", *[ROOT / "golden" / "ir" / f"{n}.json" for n in faults], *SCALE,
                     "--references", tmp_path / "A", "-o", out)
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert set(runs) == set(faults), proc.stderr[-3000:]
    summary = (out / "summary.md").read_text()
    for name, (bad_file, word) in want.items():
        r = runs[name]
        assert "reference" not in r and r["reference_problems"][0]["file"] == str(bad_file)
        if r["status"] == "unjudged":
            assert "no usable reference" in r["reason"] and str(bad_file) in r["reason"]
        else:  # judged by its probes: never a plain ok
            assert r["reason"].startswith("judged by probes alone: no usable reference (")
            assert str(bad_file) in r["reason"] and word in r["reason"]
            assert f"| {r['status']} (without reference) | {name} |" in summary
    assert "judged without a usable reference" in summary and "## Reference problems" in summary


def _save(scene, folder, value):
    mean = np.full((8, 8, 3), value, dtype=np.float32)
    return references.save(scene, ["R", "G", "B"], mean, np.full_like(mean, 1e-3), {"spp": 64, "passes": 8}, folder)


def test_a_crash_between_the_two_renames_is_seen_and_passed_over(tmp_path, golden, monkeypatch):
    """The replacement of a reference is one step for every reader: a save interrupted between
    its two renames (os.replace failing the second time) leaves a pair the loader reports and
    passes over; interrupted before them, the old pair stays whole. Temporary files are unique,
    beside the reference, and never left behind."""
    scene = golden["ggx_copper_50"]
    name = scene["name"]
    a, b = tmp_path / "A", tmp_path / "B"
    _save(scene, a, 0.25)
    _save(scene, b, 0.5)
    real_replace, calls = os.replace, []

    def crash_on(n):
        def replace(src, dst):
            calls.append((str(src), str(dst)))
            if len(calls) == n:
                raise OSError("simulated crash")
            return real_replace(src, dst)
        return replace

    # a crash before the first rename: nothing changed, the old pair is whole and used
    monkeypatch.setattr(os, "replace", crash_on(1))
    with pytest.raises(OSError, match="simulated crash"):
        _save(scene, a, 0.75)
    ref = references.load(name, [a, b], scene=scene)
    assert ref.path == a / f"{name}.exr" and float(ref.mean.mean()) == 0.25
    # a crash between the two renames
    calls.clear()
    monkeypatch.setattr(os, "replace", crash_on(2))
    with pytest.raises(OSError, match="simulated crash"):
        _save(scene, a, 0.75)
    monkeypatch.setattr(os, "replace", real_replace)
    for src, dst in calls:
        assert os.path.dirname(src) == os.path.dirname(dst) and src not in (dst + ".tmp", dst[:-4] + ".exr.tmp",
                                                                         dst[:-5] + ".json.tmp")
    assert sorted(p.name for p in a.iterdir() if p.name != ".work") == [f"{name}.exr", f"{name}.json"]
    assert references.load(name, [a, b], scene=scene).path == b / f"{name}.exr"  # passed over
    found = references.search(name, [a, b], scene=scene)
    assert found.ref.path == b / f"{name}.exr"
    assert found.problems == [{"file": str(a / f"{name}.exr"), "problem": found.problems[0]["problem"]}]
    assert "sha256 differs" in found.problems[0]["problem"]
    # the next save repairs it
    _save(scene, a, 0.75)
    found = references.search(name, [a, b], scene=scene)
    assert found.ref.path == a / f"{name}.exr" and float(found.ref.mean.mean()) == 0.75 and found.problems == []


def _maker(*args):
    return subprocess.run([sys.executable, str(ROOT / "batch" / "make_references.py"), *map(str, args)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)


@pytest.mark.slow
def test_make_references_never_replaces_a_reference_unasked(tmp_path):
    """An existing reference (current or not) is left as it is and named unless --replace asks."""
    name = "ggx_copper_50_isolated"
    out = tmp_path / "refs"
    exr_path, _word = damage("stale", name, out)
    meta_path = out / f"{name}.json"
    before = (exr_path.read_bytes(), meta_path.read_bytes())
    proc = _maker("-i", ROOT / "golden" / "ir" / f"{name}.json", "--out", out, "--spp", "2", "--passes", "2")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (exr_path.read_bytes(), meta_path.read_bytes()) == before
    assert f"{name}: its reference exists but is not usable: {exr_path}: stale" in proc.stdout
    assert "left as it is (--replace renders it again)" in proc.stdout


@pytest.mark.slow
def test_make_references_replace_writes_a_hashed_pair(tmp_path, golden):
    name = "ggx_copper_50_isolated"
    out = tmp_path / "refs"
    damage("stale", name, out)
    proc = _maker("-i", ROOT / "golden" / "ir" / f"{name}.json", "--out", out, "--spp", "2", "--passes", "2",
                  "--replace")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    meta = json.loads((out / f"{name}.json").read_text())
    assert meta["exr_sha256"] == references.sha256_of(out / f"{name}.exr") and meta["spp"] == 2
    found = references.search(name, out, scene=golden[name], shape=SHAPE, names=NAMES)
    assert found.ref is not None and found.problems == []


@pytest.mark.slow
def test_two_makers_of_one_scene_take_turns(tmp_path):
    """While another process holds the scene's lock, a maker writes nothing for that scene and says so."""
    name = "ggx_copper_50_isolated"
    out = tmp_path / "refs"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        from spectral_bench.batch.verdict import references
        with references.scene_lock({str(out)!r}, {name!r}):
            print("held", flush=True)
            sys.stdin.read()  # until the test closes it
    """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        proc = _maker("-i", ROOT / "golden" / "ir" / f"{name}.json", "--out", out, "--spp", "2", "--passes", "2")
    finally:
        holder.stdin.close()
        holder.wait(timeout=60)
    assert proc.returncode == 1 and "another make_references is writing this reference" in proc.stdout
    assert not (out / f"{name}.exr").exists() and not (out / f"{name}.json").exists()


@pytest.mark.slow
def test_the_results_panel_draws_every_reference_problem(tmp_path):
    out_dir = tmp_path / "outputs"
    out_dir.mkdir()
    # a short path of its own: the panel cuts a reason at 160 characters, and tmp_path's length
    # varies (pytest-xdist workers add a folder); the file is only named, never opened
    bad = "/no/such/A/ggx_copper_50.exr"
    run = {"scene": "ggx_copper_50", "case": "c", "backend": "mitsuba", "mode": "m", "status": "ok",
           "reason": f"judged by probes alone: no usable reference ({bad}: unreadable EXR: truncated)",
           "reference_problem": f"no usable reference ({bad}: unreadable EXR: truncated)",
           "reference_problems": [{"file": bad, "problem": "unreadable EXR: truncated"}],
           "spp": 4, "resolution": [8, 8], "time_s": 0.1, "image": None, "channels": ["R", "G", "B"],
           "metrics": {"rmse": None, "relmse": None, "mape": None, "flip": None}, "probes": []}
    (out_dir / "metrics.json").write_text(json.dumps({"started": "now", "options": {}, "runs": [run]}))
    out = run_bpy(f"""
        sys.path.insert(0, {TESTS!r})
        import layout_recorder as lr
        bpy.context.window_manager.spectral_bench_run.output_dir = {str(out_dir)!r}
        calls = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark_results, lr.Context())
        print(json.dumps([[c[2].get("text"), c[2].get("icon")] for c in calls if c[1] == "label"]))
    """)
    assert [f"reference problem: {bad}: unreadable EXR: truncated", "ERROR"] in out
    assert [run["reason"], "ERROR"] in out
