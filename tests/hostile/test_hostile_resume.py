"""A run folder is data (issue 30): ``--resume OUT`` runs no command, environment or executable that
OUT/metrics.json records (a declared renderer comes from the --renderers file the user gives again,
-e from -e given again, each compared with the run's), and every value it keeps from the file is of
the type and range the runner writes (schemas/metrics.schema.json) or the resume is refused, naming
the field, before anything is written.

One real run of a declared renderer (a small script writing an EXR) is the folder every test
edits a copy of."""
import copy
import json
import shutil
import textwrap

import pytest

from conftest import GOLDEN, run_batch, write_hand_made_metrics
from fake_renderer import FAKE

pytestmark = pytest.mark.slow  # every test here costs over ~1 s of CPU, its children and module fixtures counted (benchmarks/TESTS.md)

GOOD = GOLDEN / "ggx_copper_50_isolated.json"
TINY = ("--scale", 0.0625, "--spp", 4, "--passes", 2, "--no-flip")


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """(the renderers file, a finished run of its renderer) made once for the module."""
    here = tmp_path_factory.mktemp("declared")
    (here / "fake.py").write_text(FAKE)
    decl = here / "fake.toml"
    decl.write_text(textwrap.dedent('''
        [renderers.fake]
        command = ["{python}", "{here}/fake.py", "seed", "{output}", "{spp}", "{seed}", "{width}", "{height}", "{scene}"]
        reads = "json"
        models = ["spectral"]
        '''))
    out = here / "run"
    proc = run_batch("-i", GOOD, "--renderers", decl, "-r", "fake", *TINY, "-o", out)
    assert proc.returncode in (0, 1, 3), proc.stderr[-3000:]
    data = json.loads((out / "metrics.json").read_text())
    assert [r["backend"] for r in data["runs"]] == ["fake"] and data["runs"][0]["job"], data["runs"]
    return decl, out


def edited(finished, tmp_path, edit):
    """A copy of the finished run whose metrics.json ``edit`` changed (in place), its job marked
    interrupted (so a resume would render it again)."""
    out = tmp_path / "run"
    shutil.copytree(finished[1], out)
    data = json.loads((out / "metrics.json").read_text())
    data["runs"][0]["interrupted"] = True
    edit(data)
    write_hand_made_metrics(out, data)
    return out


def snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_recorded_command_never_runs(finished, tmp_path, run_batch_here):
    """A hand-edited command (``/bin/sh -c 'touch MARKER'``) is not run: without --renderers the
    resume is refused saying what to pass; with the user's file it is refused naming the field that
    differs; a recorded -e executable is never used either. Nothing in the folder changes."""
    decl, _ = finished
    marker = tmp_path / "MARKER"
    hostile = ["/bin/sh", "-c", 'touch "$0"', str(marker), "{scene}", "{output}", "{spp}", "{seed}"]

    def edit(data):
        data["options"]["renderers"]["fake"]["command"] = hostile
        data["options"]["renderers"]["fake"]["env"] = {"LD_PRELOAD": "/tmp/evil.so"}
    out = edited(finished, tmp_path, edit)
    before = snapshot(out)
    proc = run_batch("--resume", out)  # a real child: the way a user meets it
    assert proc.returncode == 2 and "--renderers FILE" in proc.stderr and "'fake'" in proc.stderr, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    proc = run_batch_here("--resume", out, "--renderers", decl)
    assert proc.returncode == 2 and "--renderers differs" in proc.stderr and "'fake'.command" in proc.stderr, proc.stderr
    out2 = edited(finished, tmp_path / "e", lambda d: d["options"].update(exec={"fake": "/bin/sh"}))
    proc = run_batch_here("--resume", out2, "--renderers", decl)
    assert proc.returncode == 2 and "-e NAME=PATH" in proc.stderr and "'fake'" in proc.stderr, proc.stderr
    proc = run_batch_here("--resume", out2, "--renderers", decl, "-e", "fake=/bin/true")
    assert proc.returncode == 2 and "-e/--exec differs" in proc.stderr and "/bin/sh" in proc.stderr, proc.stderr
    assert not marker.exists()
    assert snapshot(out) == before


@pytest.mark.slow
def test_the_same_declaration_given_again_resumes(finished, tmp_path, run_batch_here):
    """The run's own file, named by another path to the same file: the interrupted job renders
    again with the user's declaration; a file declaring a renderer the run did not have, or a
    declared run resumed with another renderer, is refused naming it."""
    decl, _ = finished
    out = edited(finished, tmp_path, lambda d: None)
    proc = run_batch_here("--resume", out, "--renderers", decl.parent / "." / ".." / decl.parent.name / decl.name)
    assert proc.returncode in (0, 1, 3), proc.stderr[-3000:]
    assert "[1/1] ggx_copper_50_isolated (fake)" in proc.stderr, proc.stderr[-3000:]  # rendered again
    data = json.loads((out / "metrics.json").read_text())
    assert len(data["runs"]) == 1 and not data["runs"][0].get("interrupted") and data["runs"][0]["passes"] == 2
    # the same job: the declaration (and the file it names, as the run recorded it) is the run's
    job = json.loads((finished[1] / "metrics.json").read_text())["runs"][0]["job"]
    assert data["runs"][0]["job"] == job and data["options"]["renderers"]["fake"]["source"] == str(decl)
    other = tmp_path / "other.toml"
    other.write_text(decl.read_text().replace("[renderers.fake]", "[renderers.fake2]"))
    proc = run_batch_here("--resume", out, "--renderers", decl, "--renderers", other)
    assert proc.returncode == 2 and "'fake2' (not in the run)" in proc.stderr, proc.stderr


RUN_FIELDS = [
    ("spp", "<script>alert(1)</script>", "runs/0/spp"),
    ("resolution", [16], "runs/0/resolution"),
    ("resolution", ["<b>16</b>", 16], "runs/0/resolution/0"),
    ("metrics", {"rmse": "very small", "relmse": None, "mape": None, "flip": None}, "runs/0/metrics/rmse"),
    ("sanity", {"nan": "<i>0</i>", "inf": 0, "negative": 0}, "runs/0/sanity/nan"),
    ("passes", -3, "runs/0/passes"),
    ("status", "<img src=x>", "runs/0/status"),
]


@pytest.mark.parametrize("field, value, where", RUN_FIELDS, ids=[f"{f}={v!r}" for f, v, _ in RUN_FIELDS])
def test_a_kept_value_of_the_wrong_type_is_refused_naming_it(finished, tmp_path, run_batch_here, field, value, where):
    """A finished job's values would go verbatim into summary.md, report.html and the JUnit XML
    (a string rmse, a one-item resolution crashed them, so no JUnit file was written): refused with
    exit 2 naming the field, and nothing in the folder changes, the JUnit file is not started."""
    decl, _ = finished

    def edit(data):
        data["runs"][0].pop("interrupted")
        data["runs"][0][field] = copy.deepcopy(value)
    out = edited(finished, tmp_path, edit)
    before = snapshot(out)
    proc = run_batch_here("--resume", out, "--renderers", decl, "--junit", tmp_path / "junit.xml")
    assert proc.returncode == 2 and f"{where}:" in proc.stderr and str(out / "metrics.json") in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert snapshot(out) == before and not (tmp_path / "junit.xml").exists()


def test_a_sweep_point_of_the_wrong_type_is_refused_naming_it(finished, tmp_path, run_batch_here):
    """A study job's sweep point goes into summary.md's sweep table as a number (a string time
    crashed it): typed in the schema, refused naming it."""
    decl, _ = finished
    point = {"spp": 4, "time_s": "<b>slow</b>", "wall_s": 1.0, "rmse": 0.1}
    job = {"job": "0" * 20, "kind": "sweep", "scene": "ggx_copper_50_isolated", "backend": "fake", "mode": "rgb",
           "status": "rendered", "point": point}
    out = edited(finished, tmp_path, lambda d: (d["runs"][0].pop("interrupted"), d.update(jobs=[job])))
    proc = run_batch_here("--resume", out, "--renderers", decl)
    assert proc.returncode == 2 and "jobs/0/point/time_s:" in proc.stderr, proc.stderr


def test_an_untouched_run_resumes_with_its_junit(finished, tmp_path, run_batch_here):
    """The control: the same finished run resumed as the runner wrote it keeps its job and writes
    the JUnit file."""
    decl, _ = finished
    out = tmp_path / "run"
    shutil.copytree(finished[1], out)
    proc = run_batch_here("--resume", out, "--renderers", decl, "--junit", tmp_path / "junit.xml")
    assert proc.returncode in (0, 1, 3) and "1 jobs kept, 0 to run" in proc.stderr, proc.stderr[-3000:]
    assert "<testcase" in (tmp_path / "junit.xml").read_text()
