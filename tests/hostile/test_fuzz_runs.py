"""Property-based fuzzing of run folders (tests/run_fuzz.py): a copy of one real run (Mitsuba,
one small scene at tiny settings, made once per module), its metrics.json and files mutated,
compared with an untouched copy by batch/compare_runs.py: exit 2 with a named error, 3 naming
what it could not judge, or a correct result; never an exception; nothing written outside the
output folder. A bounded number of examples here; the bigger run is marked slow."""
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings

import exr_craft
import run_fuzz
from conftest import HAND_MADE, run_batch

pytestmark = pytest.mark.slow  # every test here costs over ~1 s of CPU, its children and module fixtures counted (benchmarks/TESTS.md)


TINY = ("-r", "mitsuba", "-s", "ggx_copper_50", "--scale", "0.125", "--spp", "4", "--no-flip")


def fuzz(examples):
    """Derandomised (the same examples on every run: CI is reproducible), no example database."""
    return settings(max_examples=examples, deadline=None, database=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """(a real run folder, a folder of things outside any run: secret.exr, user.json, user_dir/, bomb.exr)."""
    root = tmp_path_factory.mktemp("fuzz_runs")
    (root / "run").mkdir()
    proc = run_batch("-o", root / "run", *TINY, "--junit", root / "run" / "junit.xml")
    assert proc.returncode in (0, 1, 3), proc.stderr[-3000:]
    assert (root / "run" / "junit.xml").is_file()  # a new top-level *.xml in the run folder is allowed
    outside = root / "outside"
    outside.mkdir()
    shutil.copyfile(root / "run" / run_fuzz.IMAGE, outside / "secret.exr")
    (outside / "user.json").write_text('{"user": "data"}\n')
    (outside / "user_dir").mkdir()
    (outside / "user_dir" / "notes.md").write_text("the user's notes\n")
    exr_craft.bomb(outside / "bomb.exr", 20000, 20000)
    return root / "run", outside


def _compare_mutated(real_run, changes, use_default_out):
    run, outside = real_run
    with tempfile.TemporaryDirectory() as d:
        root = Path(d)
        folders = {"old": root / "old", "new": root / "new"}
        for f in folders.values():
            shutil.copytree(run, f, symlinks=True)
            (f / HAND_MADE).write_text("mutated by tests/hostile/test_fuzz_runs.py\n")
        shutil.copytree(outside, root / "outside", symlinks=True)
        for change in changes:
            run_fuzz.apply(change, folders, root / "outside")
        return run_fuzz.check(folders["old"], folders["new"], root, None if use_default_out else root / "out")[0]


def test_untouched_copies_are_same_and_the_checker_sees_changes(real_run):
    """The oracle itself: a copy compared with itself is 0 (same), a removed render 3 (named)."""
    assert _compare_mutated(real_run, [], True) == 0
    assert _compare_mutated(real_run, [("file", "old", "remove", 0)], False) == 3


@fuzz(12)
@given(run_fuzz.mutations())
def test_mutated_run_folders_give_named_errors_or_correct_results(real_run, changes):
    assert _compare_mutated(real_run, changes, use_default_out=len(changes) % 2 == 0) in (0, 1, 2, 3)


@pytest.mark.slow
@fuzz(150)
@given(run_fuzz.mutations())
def test_mutated_run_folders_many(real_run, changes):
    assert _compare_mutated(real_run, changes, use_default_out=len(changes) % 2 == 0) in (0, 1, 2, 3)


def test_baseline_whose_render_is_a_bomb_is_unjudged_naming_it(real_run, tmp_path):
    """--baseline OLD where OLD's render is a 20000x20000 EXR of 2.4 MB: the run goes on, the job's
    baseline record is ``unjudged`` naming the file and the data window (its header was refused
    against the resolution the record gives); compare_runs exits 3 naming it."""
    run, outside = real_run
    old = tmp_path / "old"
    shutil.copytree(run, old, symlinks=True)
    (old / run_fuzz.IMAGE).unlink()
    shutil.copyfile(outside / "bomb.exr", old / run_fuzz.IMAGE)
    proc = run_batch("-o", tmp_path / "new", *TINY, "--baseline", old)
    assert proc.returncode in (0, 1, 3), proc.stderr[-3000:]
    import json
    rec = json.loads((tmp_path / "new" / "metrics.json").read_text())["runs"][0]["baseline"]
    assert rec["status"] == "unjudged" and f"{old / run_fuzz.IMAGE}: header: dataWindow: 20000x20000, expected 64x64" \
        in rec["reason"], rec
    code, text = run_fuzz.check(old, tmp_path / "new", tmp_path)
    assert code == 3 and "dataWindow: 20000x20000" in text
