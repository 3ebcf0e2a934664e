"""Command line: Blender-style and plain Python argv give the same jobs; settings files;
export-only layout."""
import json

import pytest

from conftest import ALL_SCENES, GOLDEN, ROOT, metrics, run_batch
from spectral_bench.batch import cli
from spectral_bench.batch.jobs import runner

ARGS = ["-c", "reflectance", "-s", "ggx_glass", "-s", "ggx_copper_60", "-r", "mitsuba", "--spp", "8",
        "--scale", "0.25"]


def test_blender_and_python_argv_give_the_same_jobs():
    blender = ["blender", "-b", str(ROOT / "scenes.blend"), "-P", "batch/run.py", "--", *ARGS]
    python = ["batch/run.py", *ARGS]
    a, b = cli.parse(cli.split_argv(blender)), cli.parse(cli.split_argv(python))
    assert a == b
    jobs_a, _ = runner.plan(a)
    jobs_b, _ = runner.plan(b)
    assert jobs_a == jobs_b == [("ggx_copper_60", "reflectance", "mitsuba"), ("ggx_glass", "reflectance", "mitsuba")]


@pytest.mark.slow
def test_list_through_real_processes_with_and_without_separator():
    with_sep = run_batch("--", *ARGS, "--list")
    without = run_batch(*ARGS, "--list")
    assert with_sep.returncode == without.returncode == 0, with_sep.stderr
    jobs = [[line for line in p.stdout.splitlines() if "\t" in line] for p in (with_sep, without)]
    assert jobs[0] == jobs[1] and len(jobs[0]) == 2
    assert "ggx_glass\treflectance\tmitsuba" in without.stdout


def test_settings_file_and_command_line_wins(tmp_path):
    toml = tmp_path / "s.toml"
    toml.write_text('scene = ["ggx_copper_50", "ggx_copper_80"]\nspp = 99\nscale = 0.5\nalpha = 0.05\n')
    opts = cli.parse(["--settings", str(toml), "--spp", "7"])
    assert opts["scene"] == ["ggx_copper_50", "ggx_copper_80"]
    assert opts["spp"] == 7 and opts["scale"] == 0.5 and opts["alpha"] == 0.05
    js = tmp_path / "s.json"
    js.write_text(json.dumps({"renderer": "mitsuba", "export-only": True}))
    opts = cli.parse(["--settings", str(js)])
    assert opts["renderer"] == ["mitsuba"] and opts["export_only"] is True


def test_settings_file_with_unknown_key_is_an_error(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("sample_count = 3\n")
    with pytest.raises(cli.SettingsError, match="sample_count"):
        cli.parse(["--settings", str(bad)])


# The tests below read scene JSON files through batch/run.py's main() in this process: reading
# scenes.blend costs a bpy start in the runner's process, so the default input is left to the real
# children of test_export_only_writes_every_format_per_scene and test_json_input_runs_like_the_blend.
def test_unknown_scene_is_reported_not_ignored(tmp_path, run_batch_here):
    out = tmp_path / "o"
    proc = run_batch_here("-i", GOLDEN / "ggx_glass.json", "-s", "no_such_scene", "--export-only", "-o", out)
    assert proc.returncode == 1
    run = metrics(out)["runs"][0]
    assert run["scene"] == "no_such_scene" and run["status"] == "failed"


@pytest.mark.slow
def test_export_only_writes_every_format_per_scene(tmp_path):
    out = tmp_path / "exports"
    proc = run_batch("--export-only", "--format", "mitsuba", "--format", "json", "-o", out)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ALL_SCENES:
        assert (out / name / "mitsuba" / "scene.xml").is_file()
        exported = json.loads((out / name / "json" / f"{name}.json").read_text())
        assert exported == json.loads((GOLDEN / f"{name}.json").read_text())
    statuses = {(r["scene"], r["backend"]): r["status"] for r in metrics(out)["runs"]}
    assert len(statuses) == 2 * len(ALL_SCENES) and set(statuses.values()) == {"ok"}


@pytest.mark.slow
def test_json_input_runs_like_the_blend(tmp_path):
    out = tmp_path / "o"
    proc = run_batch("-r", "mitsuba", "-i", GOLDEN / "ggx_copper_80.json", "--scale", "0.125", "--spp", "16", "--no-flip", "-o", out)
    runs = metrics(out)["runs"]
    assert [r["scene"] for r in runs] == ["ggx_copper_80"]
    # the JSON is the same scene as the .blend's: its reference judges it, on the render's own noise
    assert runs[0]["status"] == "ok" and runs[0]["test"]["pass"] and runs[0]["test"]["noise"] == "own", runs[0]
    assert runs[0]["resolution"] == [64, 64] and runs[0]["spp"] == 16
    assert (out / "summary.md").read_text().count("ggx_copper_80") == 1
    assert proc.returncode == 0


def test_log_option_writes_the_log_to_a_file(tmp_path, run_batch_here):
    log = tmp_path / "run.log"
    out = tmp_path / "o"
    proc = run_batch_here("-i", GOLDEN / "ggx_glass.json", GOLDEN / "ggx_copper_50.json", "-s", "ggx_glass",
                          "--export-only", "--format", "json", "-l", log, "-o", out)
    assert proc.returncode == 0, proc.stderr[-1000:]
    text = log.read_text()
    assert f"writing to {out}" in text and "ggx_glass" in text


def test_a_backend_missing_for_every_scene_is_one_line_of_the_log(tmp_path, run_batch_here):
    """ART missing: the log says so once with the count, not once per scene (the summary likewise
    has one row: batch/report/grouping.py); every scene's entry is still in metrics.json."""
    missing = tmp_path / "no-such-artist"
    proc = run_batch_here("-r", "art", "-e", f"art={missing}", "-i", *(GOLDEN / f"{name}.json" for name in ALL_SCENES),
                          "-s", "ggx_copper_50", "-s", "ggx_glass", "-s", "polarizing_spheres", "--scale", "0.125",
                          "-o", tmp_path / "o")
    log = proc.stdout + proc.stderr
    lines = [l for l in log.splitlines() if l.startswith("SKIPPED")]
    assert len(lines) == 1 and lines[0].startswith("SKIPPED  art on 3 scenes: "), lines
    assert sorted(r["scene"] for r in metrics(tmp_path / "o")["runs"]) == ["ggx_copper_50", "ggx_glass", "polarizing_spheres"]
    assert proc.returncode == 4  # nothing ran
