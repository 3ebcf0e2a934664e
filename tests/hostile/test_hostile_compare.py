"""Hostile run folders and files, second pass (issue 30): compare_runs never deletes or writes through
a link and says when it could not judge; EXR headers are checked before any pixel is read
(decompression bombs); --junit never overwrites the run's files; make_references survives a
truncated pass record and a full disk; the panel follows no recorded baseline out of its place.

Real EXR files (tests/exr_craft.py crafts the bombs from a strip OpenEXR writes), real
subprocesses for the command lines, real renders where a run is needed."""
import contextlib
import hashlib
import io
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tracemalloc
import types

import numpy as np
import OpenEXR
import pytest

import exr_craft
import run_fuzz
from conftest import HAND_MADE, ROOT, run_batch
from spectral_bench.batch import exr, run_folder, spectral_exr
from spectral_bench.batch.verdict import baseline, references
from noisy_runs import noisy_run_folder

COMPARE = ROOT / "batch" / "compare_runs.py"
MAKE_REFERENCES = ROOT / "batch" / "make_references.py"


def compare_runs_cli(*args, cwd=ROOT):
    """The real command line, in a child process."""
    return subprocess.run([sys.executable, str(COMPARE), *map(str, args)], capture_output=True, text=True,
                          timeout=600, cwd=cwd)


def compare_runs(*args, cwd=ROOT):
    """compare_runs' main() in this process (a child costs seconds of imports under load): its exit
    status and what it printed, as the command line gives them."""
    from spectral_bench.batch import compare_runs as cr
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), contextlib.chdir(cwd):
        code = cr.main([str(a) for a in args])
    return types.SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


def _pair(tmp_path):
    old, new = tmp_path / "old", tmp_path / "new"
    noisy_run_folder(old, 1, {"a": 1.0, "b": 1.0})
    noisy_run_folder(new, 2, {"a": 1.0, "b": 1.0})
    for f in (old, new):
        (f / HAND_MADE).write_text("written by a test\n")
    return old, new


def _edit(folder, job, **fields):
    data = json.loads((folder / "metrics.json").read_text())
    data["runs"][job].update(fields)
    (folder / "metrics.json").write_text(json.dumps(data))


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


# -- compare_runs: its output folder ---------------------------------------------------------------
@pytest.mark.slow
def test_the_same_output_twice_deletes_nothing(tmp_path):
    """Run twice with the same -o DIR: the second is refused (exit 2, naming DIR), DIR and all in it
    as they were. Without -o: NEW/compare, then NEW/compare-2; the first comparison untouched."""
    old, new = _pair(tmp_path)
    out = tmp_path / "cmp"
    first = compare_runs_cli(old, new, "-o", out)
    assert first.returncode == 0, first.stderr
    (out / "mine.txt").write_text("the user's file in that folder\n")
    before = run_fuzz.snapshot(tmp_path)
    second = compare_runs_cli(old, new, "-o", out)
    assert second.returncode == 2 and str(out) in second.stderr and "not an empty folder" in second.stderr, second.stderr
    assert run_fuzz.snapshot(tmp_path) == before

    a = compare_runs(old, new)
    kept = run_fuzz.snapshot(new / "compare")
    b = compare_runs(old, new)
    assert a.returncode == b.returncode == 0, b.stderr
    assert run_fuzz.snapshot(new / "compare") == kept
    assert json.loads((new / "compare-2" / "compare.json").read_text())["jobs"]
    assert f"written to {new / 'compare-2'}" in b.stderr


def test_an_output_that_is_holds_or_lies_inside_a_run_is_refused(tmp_path):
    """-o . in a project folder that holds both runs, -o NEW, -o OLD, a folder inside either: exit 2
    naming the option and the run; nothing in the project changes."""
    old, new = _pair(tmp_path)
    (tmp_path / "source.py").write_text("print('the project')\n")
    before = run_fuzz.snapshot(tmp_path)
    for out, words in ((".", "contains OLD"), ("new", "is NEW"), ("old", "is OLD"), ("new/sub", "lies inside NEW"),
                       ("old/compare", "lies inside OLD"), (str(tmp_path), "contains OLD")):
        proc = compare_runs("old", "new", "-o", out, cwd=tmp_path)
        assert proc.returncode == 2 and f"-o {out}" in proc.stderr and words in proc.stderr, (out, proc.stderr)
        assert "Traceback" not in proc.stderr
    (tmp_path / "alias").symlink_to(old, target_is_directory=True)
    proc = compare_runs("old", "alias", cwd=tmp_path)  # NEW is OLD: its default NEW/compare would be inside OLD
    assert proc.returncode == 2 and "the output folder alias/compare" in proc.stderr and "lies inside OLD" in proc.stderr
    (tmp_path / "alias").unlink()
    assert run_fuzz.snapshot(tmp_path) == before


def test_links_in_a_hostile_new_are_never_written_through(tmp_path):
    """NEW/compare a link to a user's folder; NEW/compare/compare.md a link to a user's file; an -o
    that is a link to an empty folder; NEW/compare/compare.md a folder: nothing of the user's changes,
    the comparison goes to a folder compare_runs makes (or is refused), never a traceback."""
    old, new = _pair(tmp_path)
    user = tmp_path / "user"
    user.mkdir()
    (user / "notes.md").write_text("the user's notes\n")
    (tmp_path / "empty").mkdir()
    (new / "compare").symlink_to(user, target_is_directory=True)
    mine = run_fuzz.snapshot(user)
    proc = compare_runs(old, new)
    assert proc.returncode == 0 and f"written to {new / 'compare-2'}" in proc.stderr, proc.stderr
    assert run_fuzz.snapshot(user) == mine and (new / "compare").is_symlink()
    assert not (new / "compare-2").is_symlink() and (new / "compare-2" / "compare.md").is_file()

    (new / "compare").unlink()
    (new / "compare").mkdir()
    (new / "compare" / "compare.md").symlink_to(user / "notes.md")
    proc = compare_runs(old, new)
    assert proc.returncode == 0 and f"written to {new / 'compare-3'}" in proc.stderr, proc.stderr
    assert (user / "notes.md").read_text() == "the user's notes\n"

    (tmp_path / "link").symlink_to(tmp_path / "empty", target_is_directory=True)
    proc = compare_runs(old, new, "-o", tmp_path / "link")
    assert proc.returncode == 2 and "link" in proc.stderr and not os.listdir(tmp_path / "empty"), proc.stderr

    taken = tmp_path / "taken"
    (taken / "compare.md").mkdir(parents=True)
    proc = compare_runs(old, new, "-o", taken)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and str(taken) in proc.stderr, proc.stderr
    shutil.rmtree(new / "compare")
    (new / "compare" / "compare.md").mkdir(parents=True)
    proc = compare_runs(old, new)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert (new / "compare" / "compare.md").is_dir() and not os.listdir(new / "compare" / "compare.md")


# -- compare_runs: what it could not judge -------------------------------------------------------------
def _garbage(folder):
    (folder / "a" / "results" / "mitsuba" / "render.exr").write_bytes(b"garbage, not an image")


def _one_pass(folder):
    path = folder / "a" / "results" / "mitsuba" / "render.exr"
    names, img = exr.read_image(path)
    path.unlink()
    exr.write_image(path, names, img)


def _bomb(folder):
    exr_craft.bomb(folder / "a" / "results" / "mitsuba" / "render.exr", 20000, 20000)


@pytest.mark.parametrize("which, change, words", [
    ("old", _garbage, "not a readable OpenEXR file"),
    ("old", lambda f: (f / "a" / "results" / "mitsuba" / "render.exr").unlink(), "is not a file inside its run folder"),
    ("old", _one_pass, "no per-pixel noise (one pass"),
    ("new", lambda f: _edit(f, 0, pass_times=[1e300, 1e-300]), "NEW's pass_times is not"),
    ("old", lambda f: _edit(f, 0, pass_times="fast"), "OLD's pass_times is not"),
    ("old", lambda f: _edit(f, 0, probes=5), "OLD's probes is int, not a list"),
    ("new", lambda f: _edit(f, 0, probes={"p": 1}), "NEW's probes is dict, not a list"),
    pytest.param("old", _bomb, "dataWindow: 20000x20000, expected 16x16", marks=pytest.mark.slow),  # ~1 s of CPU
], ids=["garbage_exr", "missing_baseline_image", "one_pass", "absurd_pass_times", "pass_times_text",
        "probes_int", "probes_dict", "exr_bomb"])
def test_what_cannot_be_judged_exits_3_and_is_never_same(tmp_path, which, change, words):
    """Exit 3 naming the job and why on stderr, the row UNJUDGED (never ``same``), no traceback; a
    job that changed as well as one not judged: exit 1 (a change is a finding)."""
    old, new = _pair(tmp_path)
    change({"old": old, "new": new}[which])
    proc = (compare_runs_cli if change is _bomb else compare_runs)(old, new)
    assert proc.returncode == 3, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr and words in proc.stderr and "error: a / mitsuba m: not judged" in proc.stderr
    rows = {l.split(" | ")[1]: l.split(" | ")[0] for l in proc.stdout.splitlines() if l.startswith("| ") and " | a | " in l
            or l.startswith("| ") and " | b | " in l}
    assert rows == {"a": "| UNJUDGED", "b": "| same"}, rows
    page = (new / "compare" / "compare.html").read_text()
    assert "<td>UNJUDGED</td>" in page and "1 not judged" in page
    _edit(new, 1, status="failed")
    assert compare_runs(old, new).returncode == 1


# -- EXR headers before pixels -------------------------------------------------------------------
def test_crafted_exrs_are_real_files():
    """The bombs are OpenEXR files: a small one reads whole through the library, a 20000x20000 one's
    header says so."""
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory() as d:
        small = exr_craft.bomb(Path(d) / "small.exr", 300, 64)
        with OpenEXR.File(str(small), separate_channels=True) as f:
            assert {n: c.pixels.shape for n, c in f.channels().items()} == {c: (64, 300) for c in "BGR"}
        big = exr_craft.bomb(Path(d) / "big.exr", 20000, 20000)
        assert big.stat().st_size < 3_000_000
        with OpenEXR.File(str(big), header_only=True) as f:
            assert [list(v) for v in f.header()["dataWindow"]] == [[0, 0], [19999, 19999]]


def test_decompression_bomb_is_refused_from_its_header(tmp_path):
    """A 20000x20000 EXR of 2.4 MB is refused by every reader before any pixel is read (no
    allocation beyond the header: traced), naming the file and the field; an image of another size
    than the job's, too many channels, a multi-part or truncated file likewise."""
    bomb = exr_craft.bomb(tmp_path / "bomb.exr", 20000, 20000)
    tracemalloc.start()
    for reader in (exr.read, exr.read_rgb, exr.read_image, exr.read_image_and_stderr):
        with pytest.raises(exr.EXRLimitError, match=r"bomb\.exr: header: dataWindow: 20000x20000 exceeds"):
            reader(bomb)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 8 << 20, peak  # the header's megabyte at most, never the 2.4 GB of pixels
    spectral = exr_craft.bomb(tmp_path / "spectral.exr", 20000, 20000, channels=("S0.500nm", "S0.600nm"))
    with pytest.raises(spectral_exr.SpectralEXRError, match=r"spectral\.exr: header: dataWindow: 20000x20000"):
        spectral_exr.read(spectral)
    with pytest.raises(spectral_exr.SpectralEXRError, match=r"dataWindow: 20000x20000, expected 64x64"):
        spectral_exr.read_render(spectral, "spectral", expect=(64, 64))

    small = exr_craft.bomb(tmp_path / "small.exr", 300, 64)
    assert exr.read_rgb(small, expect=(300, 64)).shape == (64, 300, 3)
    with pytest.raises(exr.EXRLimitError, match=r"small\.exr: header: dataWindow: 300x64, expected 64x64"):
        exr.read_image(small, expect=(64, 64))
    many = {f"c{i:04d}": np.zeros((1, 1), np.float16) for i in range(exr.MAX_CHANNELS + 1)}
    exr.write_channels(tmp_path / "many.exr", many)
    with pytest.raises(exr.EXRLimitError, match=r"many\.exr: header: channels: more than 1024"):
        exr.read(tmp_path / "many.exr")
    parts = [OpenEXR.Part({"type": OpenEXR.scanlineimage, "compression": OpenEXR.ZIP_COMPRESSION},
                          {"R": np.zeros((4, 4), np.float32)}, name=name) for name in "ab"]
    with OpenEXR.File(parts) as f:
        f.write(str(tmp_path / "parts.exr"))
    with pytest.raises(exr.EXRLimitError, match=r"parts\.exr: header: version flags: a multi-part file"):
        exr.read(tmp_path / "parts.exr")
    (tmp_path / "cut.exr").write_bytes(small.read_bytes()[:40])
    with pytest.raises(exr.EXRLimitError, match=r"cut\.exr: header: .*(truncated|runs past)"):
        exr.read(tmp_path / "cut.exr")


def test_a_reference_that_is_a_bomb_is_a_named_problem(tmp_path):
    """A reference folder whose image is a bomb (its record's sha256 matching): the reference is
    refused naming the file and the data window, nothing read."""
    bomb = exr_craft.bomb(tmp_path / "ggx_copper_50.exr", 20000, 20000)
    meta = json.loads((ROOT / "references" / "ggx_copper_50.json").read_text())
    meta["exr_sha256"] = _sha(bomb)
    (tmp_path / "ggx_copper_50.json").write_text(json.dumps(meta))
    ref, problem = references.examine(tmp_path, "ggx_copper_50")
    assert ref is None and problem["file"] == str(bomb) and "dataWindow: 20000x20000" in problem["problem"], problem


BOMB_RENDERER = """
import sys
sys.path.insert(0, {tests!r})
import exr_craft
exr_craft.bomb(sys.argv[1], 20000, 20000)
"""


def test_declared_renderer_writing_a_bomb_fails_its_pass_naming_it(tmp_path):
    """A declared renderer whose output is a 20000x20000 EXR for an 8x6 scene: the pass fails naming
    the file, the data window and the size the job asked for; nothing of its pixels is read."""
    from spectral_bench.batch import backends
    from spectral_bench.batch.backends import command, passes
    from spectral_bench.exporters import ir_json
    (tmp_path / "bomb.py").write_text(BOMB_RENDERER.format(tests=str(ROOT / "tests")))
    decl = command.parse("bomber", {"command": ["{python}", "{here}/bomb.py", "{output}", "{scene}", "{spp}", "{seed}"],
                                    "reads": "json", "writes": "rgb", "models": ["spectral"]},
                         str(tmp_path / "renderers.toml"), tmp_path)
    b = backends.get("bomber", declaration=decl)
    sc = ir_json.load(ROOT / "golden" / "ir" / "ggx_copper_50.json")
    sc["render"].update(width=8, height=6)
    path = b.export(sc, tmp_path / "export")
    with pytest.raises(passes.BackendFailure) as err:
        b.render(path, b.mode_for(sc)[0], 4, tmp_path / "render.exr", passes=1, seed=0, timeout=120,
                 log_path=tmp_path / "render.log")
    assert "pass0.exr: header: dataWindow: 20000x20000, expected 8x6" in str(err.value), str(err.value)


# -- --junit never over the run's own files ------------------------------------------------------------
@pytest.mark.slow
def test_junit_inside_the_run_folder_is_refused(tmp_path):
    """--junit OUT/metrics.json (or any file below OUT but a new top-level *.xml): exit 2 naming
    --junit, nothing rendered, nothing written; with --resume the finished run's files untouched."""
    out = tmp_path / "out"
    out.mkdir()
    for target in (out / "metrics.json", out / "summary.md", out / "ggx_copper_50" / "x.xml"):
        target.parent.mkdir(exist_ok=True)
        proc = run_batch("-o", out, "-s", "ggx_copper_50", "--scale", "0.125", "--spp", "4", "--junit", target)
        assert proc.returncode == 2 and f"--junit {target}: inside the output folder" in proc.stderr, proc.stderr[-2000:]
        assert not (out / "metrics.json").exists()
    run = tmp_path / "run"
    noisy_run_folder(run, 1, {"a": 1.0})
    before = run_fuzz.snapshot(run)
    proc = run_batch("--resume", run, "--junit", run / "metrics.json")
    assert proc.returncode == 2 and "--junit" in proc.stderr and run_fuzz.snapshot(run) == before, proc.stderr[-2000:]


# -- make_references: pass records, a full disk, permissions ------------------------------------------
def make_references(*args, limit=None, umask=0o022):
    def child():
        os.umask(umask)
        if limit:  # a file may grow to ``limit`` bytes; a longer write fails (EFBIG) as on a full disk
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return subprocess.run([sys.executable, str(MAKE_REFERENCES), "-s", "ggx_copper_50", "--spp", "8", "--passes", "2",
                           *map(str, args)], capture_output=True, text=True, timeout=600, cwd=ROOT, preexec_fn=child)


@pytest.mark.slow
def test_truncated_pass_record_is_named_and_rendered_again(tmp_path):
    """A done.json cut short (a crash while it was written): named, its pass rendered again, the
    reference written (exit 0), readable by every user (0644 under umask 022), not a traceback."""
    refs = tmp_path / "refs"
    done = refs / ".work" / "ggx_copper_50" / "pass0" / "done.json"
    done.parent.mkdir(parents=True)
    done.write_text('{"status": "rendered", "time_s": 0.1, "jo')
    proc = make_references("--scale", "0.125", "--out", refs)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert f"{done}: not a readable pass record" in proc.stdout and "that pass renders again" in proc.stdout
    for name in ("ggx_copper_50.exr", "ggx_copper_50.json"):
        assert oct((refs / name).stat().st_mode & 0o777) == oct(0o644), name
    ref, problem = references.examine(refs, "ggx_copper_50")
    assert problem is None and ref.mean.shape == (64, 64, 3)


def test_reference_permissions_follow_the_umask(tmp_path):
    """A saved reference gets 0666 less the umask (0640 under 027), not mkstemp's 0600."""
    sc = json.loads((ROOT / "golden" / "ir" / "ggx_copper_50.json").read_text())
    old = os.umask(0o027)
    try:
        references.save(sc, ["R", "G", "B"], np.ones((4, 4, 3)), np.full((4, 4, 3), 0.1), {"backend": "mitsuba"}, tmp_path)
    finally:
        os.umask(old)
    for name in ("ggx_copper_50.exr", "ggx_copper_50.json"):
        assert oct((tmp_path / name).stat().st_mode & 0o777) == oct(0o640), name


@pytest.mark.slow
def test_full_disk_keeps_the_old_reference_and_says_so(tmp_path):
    """The new reference's passes rendered (kept in .work: a replacement refused), then written where
    a file cannot grow past 8 KB (RLIMIT_FSIZE: the write fails as on a full disk): exit 1 with a
    clear error naming the file, no traceback, the old reference byte for byte as it was, no
    history folder left; the same command with room writes it."""
    refs = tmp_path / "refs"
    assert make_references("--scale", "0.125", "--out", refs).returncode == 0
    old = {n: _sha(refs / n) for n in ("ggx_copper_50.exr", "ggx_copper_50.json")}
    refused = make_references("--scale", "0.1", "--out", refs, "--replace", "--seed", "7")
    assert refused.returncode == 1 and "NOT replaced" in refused.stdout, refused.stdout[-2000:]
    full = make_references("--scale", "0.1", "--out", refs, "--replace", "--accept", "--seed", "7", limit=8192)
    assert full.returncode == 1 and "Traceback" not in full.stderr, full.stdout[-2000:] + full.stderr[-2000:]
    assert f"ggx_copper_50: cannot write the reference into {refs}: " in full.stdout and "File too large" in full.stdout and "the old reference" in full.stdout, full.stdout
    assert {n: _sha(refs / n) for n in old} == old
    assert not list((refs / "history").glob("*/*")) if (refs / "history").exists() else True
    room = make_references("--scale", "0.1", "--out", refs, "--replace", "--accept", "--seed", "7")
    assert room.returncode == 0, room.stdout[-2000:] + room.stderr[-2000:]
    assert references.examine(refs, "ggx_copper_50")[0].mean.shape == (51, 51, 3)


# -- the panel: a recorded baseline is followed only beside the run -----------------------------------
def test_panel_follows_a_recorded_baseline_only_beside_the_run(tmp_path):
    """run_folder.baseline_records / baseline_image (what the Results panel draws and loads): a run's own --baseline
    record naming a sibling run shows that run's render; an absolute path elsewhere, a '..' walk or
    a folder that is no run shows none (the z-map, inside the run, still shows)."""
    runs = tmp_path / "runs"
    prev, cur, elsewhere = runs / "prev", runs / "cur", tmp_path / "elsewhere"
    for folder in (prev, cur, elsewhere):
        noisy_run_folder(folder, 1, {"a": 1.0})
    zmap = cur / "a" / "results" / "mitsuba" / baseline.ZMAP
    zmap.write_bytes((cur / "a" / "results" / "mitsuba" / "render.exr").read_bytes())
    image = "a/results/mitsuba/render.exr"
    for run, expected in (("prev", prev / image), (str(elsewhere), None), ("../elsewhere", None),
                          ("prev/../../elsewhere", None), ("a", None), ("", None), (5, None)):
        data = json.loads((cur / "metrics.json").read_text())
        data["runs"][0]["baseline"] = {"run": run, "status": "same", "image": image,
                                       "zmap": "a/results/mitsuba/" + baseline.ZMAP}
        found = run_folder.baseline_records(cur, data).get(("a", "mitsuba"))
        got = run_folder.baseline_image(found, "baseline_render")
        assert (got.resolve() if got else None) == (expected.resolve() if expected else None), (run, got)
        assert run_folder.baseline_image(found, "baseline_zscore") == zmap


def test_images_written_beside_a_render_replace_a_planted_link(tmp_path):
    """The copies the panel writes beside a render (RGB of a layered EXR, a Stokes component) and the
    previews: a link planted at that name (a run folder from someone else) is replaced by the new
    file, the file it pointed at untouched, even a dangling one not created."""
    user = tmp_path / "user.exr"
    user.write_bytes(b"the user's file")
    (tmp_path / "render_rgb.exr").symlink_to(user)
    (tmp_path / "stokes_S1.exr").symlink_to(tmp_path / "nowhere.exr")
    for name in ("render_rgb.exr", "stokes_S1.exr"):
        exr.replace_file(tmp_path / name, lambda tmp: exr.write(tmp, np.ones((2, 2, 3), np.float32)))
        assert not (tmp_path / name).is_symlink() and exr.read_rgb(tmp_path / name).shape == (2, 2, 3)
    assert user.read_bytes() == b"the user's file" and not (tmp_path / "nowhere.exr").exists()


@pytest.mark.slow
def test_results_panel_does_not_follow_a_recorded_baseline_elsewhere(tmp_path):
    """Real bpy: a run whose --baseline record names an absolute folder elsewhere (a hand-edited
    metrics.json) draws no button for the baseline's render and loading it is refused; the same
    record naming the sibling run loads that run's render."""
    from conftest import run_bpy
    runs = tmp_path / "runs"
    prev, cur, elsewhere = runs / "prev", runs / "cur", tmp_path / "elsewhere"
    for folder in (prev, cur, elsewhere):
        noisy_run_folder(folder, 1, {"a": 1.0})
    out = {}
    for run in (str(elsewhere), "prev"):
        data = json.loads((cur / "metrics.json").read_text())
        data["runs"][0]["baseline"] = {"run": run, "status": "same", "image": "a/results/mitsuba/render.exr"}
        (cur / "metrics.json").write_text(json.dumps(data))
        out[run] = run_bpy(f"""
            sys.path.insert(0, {str(ROOT / 'tests')!r})
            import layout_recorder as lr
            s = bpy.context.window_manager.spectral_bench_run
            s.output_dir = {str(cur)!r}
            calls = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark_results, lr.Context())
            kinds = [c[2]["properties"]["kind"] for c in calls
                     if c[1] == "operator" and c[2]["operator"] == "spectral_bench.load_result"]
            try:
                r = list(bpy.ops.spectral_bench.load_result(scene="a", backend="mitsuba", kind="baseline_render"))
                path = bpy.data.images["a mitsuba baseline_render"].filepath
            except RuntimeError as exc:
                r, path = str(exc), None
            print(json.dumps({{"kinds": kinds, "r": r, "path": path}}))
        """)
    far, near = out[str(elsewhere)], out["prev"]
    assert "baseline_render" not in far["kinds"] and "render" in far["kinds"], far
    assert far["path"] is None and "no baseline_render image" in far["r"], far
    assert "baseline_render" in near["kinds"] and near["path"].startswith(str(prev)), near
