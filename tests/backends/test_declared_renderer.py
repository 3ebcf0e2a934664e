"""Renderers declared in TOML (batch/backends/command.py) and the one pass loop every backend
renders through (batch/backends/passes.py).

The fast tests drive the loop with small stand-alone renderer scripts written here (real child
processes writing real EXR files: a renderer whose image is its seed, one that fails once, one
that always fails, one that writes NaN or the wrong size, one that hangs). The slow ones render
the canonical copper scenes with the example renderer of examples/your_renderer/ at default
settings: judged ok on its own noise, failed when 1 % too bright, unsupported where a scene needs
polarisation.
"""
import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
from spectral_bench.batch import backends, cli, exr  # noqa: E402
from spectral_bench.batch.backends import command, passes  # noqa: E402
from spectral_bench.exporters import ir_json  # noqa: E402

from fake_renderer import render  # noqa: E402 - the stand-in renderer's pass loop (tests/fake_renderer.py)

EXAMPLE = ROOT / "examples" / "your_renderer"
RUN = ROOT / "batch" / "run.py"

# -- the pass loop ------------------------------------------------------------------------------
def test_loop_mean_and_standard_error_from_independent_seeds(tmp_path):
    """The image of pass k is its seed (seed + k * SEED_STRIDE): the mean and the standard error
    of the mean written are exactly those of the seeds, so the loop gives every pass its own seed
    and its own share of the samples."""
    info = render(tmp_path, "seed", passes_n=3, seed=5)
    seeds = np.array([5 + k * passes.SEED_STRIDE for k in range(3)], dtype=float)
    names, img, se = exr.read_image_and_stderr(tmp_path / "render.exr")
    assert names == ["R", "G", "B"]
    # stored as half floats (batch/exr.py stored_render): the mean within a quarter of its standard
    # error (no bits below it are kept), the standard error at least the seeds' and at most
    # 1/16 (rounded up) and 0.8 % (the mean's rounding) above it
    s0 = seeds.std(ddof=1) / math.sqrt(3)
    assert np.all(np.abs(img[..., 0] - seeds.mean()) <= s0 / 4) and np.all(np.abs(img[..., 2] - 3 * seeds.mean()) <= 3 * s0 / 4)
    assert np.all(se[..., 0] >= s0) and np.all(se[..., 0] <= s0 * (1 + 1 / 16) * math.sqrt(1 + 1 / 64))
    assert info["passes"] == 3 and info["spp"] == 12 and len(info["pass_times"]) == 3
    assert info["versions"]["fake_seed"].startswith("Python 3")  # the version command's first line


def test_failed_pass_is_retried_once(tmp_path, monkeypatch):
    state = tmp_path / "state"
    state.mkdir()
    monkeypatch.setenv("FAKE_STATE", str(state))
    info = render(tmp_path, "fail_once", passes_n=2)
    assert [r["pass"] for r in info["retried"]] == [0, 1]
    assert "transient failure" in info["retried"][0]["error"]
    assert "failed (attempt 1)" in (tmp_path / "render.log").read_text()


def test_pass_failing_twice_fails_the_render_with_its_stderr(tmp_path):
    with pytest.raises(passes.BackendFailure) as err:
        render(tmp_path, "fail")
    text = str(err.value)
    assert "pass 1/3 (seed 0) failed twice" in text and "out of memory while building the BVH" in text
    assert (tmp_path / "render.log").read_text().count("$ ") == 2  # two tries of the pass; the version command is not logged


def test_pass_over_its_time_limit_is_stopped_not_retried(tmp_path):
    with pytest.raises(passes.BackendFailure) as err:
        render(tmp_path, "hang", passes_n=2, timeout=600, declared={"timeout": 1})  # the declaration's limit wins
    assert "timed out" in str(err.value) and "pass 1/2" in str(err.value)
    assert (tmp_path / "render.log").read_text().count("$ ") == 1


@pytest.mark.parametrize("mode, words", [("nan", "NaN"), ("size", "dataWindow: 9x6, expected 8x6"),
                                         ("silent", "wrote no pass0.exr")])
def test_pass_output_is_checked(tmp_path, mode, words):
    with pytest.raises(passes.BackendFailure) as err:
        render(tmp_path, mode, passes_n=1)
    assert words in str(err.value)


# -- declarations -------------------------------------------------------------------------------
GOOD = {"command": ["ring", "{scene}", "-o", "{output}", "--spp", "{spp}", "--seed", "{seed}"],
        "reads": "json", "writes": "rgb", "models": ["spectral"], "version": ["ring", "--version"]}


@pytest.mark.parametrize("change, words", [
    ({"colour": "red"}, "unknown key 'colour'"),
    ({"command": ["ring", "{scene}", "--spp", "{spp}", "--seed", "{seed}"]}, "missing placeholder {output}"),
    ({"command": ["ring", "-o", "{output}", "--spp", "{spp}", "--seed", "{seed}"]}, "missing placeholder {scene}"),
    ({"command": ["ring", "{scene}", "{output}", "{spp}"]}, "missing placeholder {seed}"),
    ({"command": ["ring", "{scene}", "{output}", "{spp}", "{seed}", "{frames}"]}, "unknown placeholder {frames}"),
    ({"command": ["ring", "{scene}", "{output}", "{spp:04d}", "{seed}"]}, "unknown placeholder {spp:04d}"),
    ({"command": ["ring", "{scene.__class__}", "{output}", "{spp}", "{seed}"]}, "unknown placeholder"),
    ({"command": ["ring", "{scene", "{output}", "{spp}", "{seed}"]}, "literal braces"),
    ({"reads": "pbrt"}, "reads: must be one of json, mitsuba, art, luxcore, cycles"),
    ({"writes": "png"}, "writes: must be one of rgb, spectral"),
    ({"models": ["spectral", "subsurface"]}, "unknown needs ['subsurface']"),
    ({"observer": "cie1964"}, "observer: only a renderer that writes = \"spectral\""),
    ({"version": ["ring", "{scene}"]}, "version: only {here} and {python}"),
    ({"timeout": -1}, "timeout: must be seconds per pass"),
    ({"env": {"A=B": "x"}}, "env: must be a table"),
])
def test_bad_declaration_names_file_renderer_and_key(change, words):
    table = dict(GOOD, **change)
    with pytest.raises(command.DeclarationError) as err:
        command.parse("ring", table, "my/renderers.toml")
    assert words in str(err.value) and "my/renderers.toml" in str(err.value) and "'ring'" in str(err.value)


def test_missing_key_and_bad_names():
    table = {k: v for k, v in GOOD.items() if k != "models"}
    with pytest.raises(command.DeclarationError, match="missing key 'models'"):
        command.parse("ring", table, "f.toml")
    with pytest.raises(command.DeclarationError, match="taken by a built-in backend"):
        command.parse("mitsuba", GOOD, "f.toml")
    with pytest.raises(command.DeclarationError, match="renderer name"):
        command.parse("../ring", GOOD, "f.toml")


def test_scene_needing_more_than_declared_is_unsupported_naming_the_need(tmp_path):
    b = backends.get("ring", declaration=command.parse("ring", GOOD, "f.toml"))
    pol = ir_json.load(ROOT / "golden" / "ir" / "polarizing_plane_0.json")
    mode, why = b.mode_for(pol)
    assert mode is None and "does not model polarization" in why and "f.toml" in why
    assert b.mode_for(ir_json.load(ROOT / "golden" / "ir" / "ggx_copper_50.json")) == ("rgb", None)
    ok, why = b.availability()
    assert not ok and "'ring' not found" in why and "-e ring=PATH" in why


def write_toml(path, text):
    path.write_text(textwrap.dedent(text))
    return path


def test_command_line_and_settings_declare_renderers(tmp_path):
    f = write_toml(tmp_path / "ring.toml", '''
        [renderers.ring]
        command = ["ring", "{scene}", "-o", "{output}", "--spp", "{spp}", "--seed", "{seed}"]
        reads = "json"
        models = ["spectral"]
        groups = ["mine"]
        ''')
    opts = cli.parse(["--renderers", str(f), "-r", "ring", "-e", "ring=/opt/ring/bin/ring"])
    assert opts["renderers"]["ring"]["reads"] == "json" and opts["exec"] == {"ring": "/opt/ring/bin/ring"}
    assert backends.expand(["mine", "mitsuba"], opts["renderers"]) == ["ring", "mitsuba"]
    settings = write_toml(tmp_path / "s.toml", '''
        renderer = ["ring"]
        [renderers.ring]
        command = ["ring", "{scene_dir}", "{output}", "{spp}", "{seed}"]
        reads = "mitsuba"
        models = []
        ''')
    opts = cli.parse(["--settings", str(settings)])
    assert opts["renderers"]["ring"]["reads"] == "mitsuba" and opts["renderer"] == ["ring"]
    with pytest.raises(cli.UsageError, match="declared twice"):
        cli.parse(["--settings", str(settings), "--renderers", str(f)])


@pytest.mark.parametrize("args, words", [
    (["-r", "ring"], "'ring': unknown backend, group or declared renderer"),
    (["-e", "ring=/x/ring"], "'ring' is no backend or declared renderer"),
    (["--renderers", "{bad}"], "bad.toml"),
    (["--renderers", "{missing}"], "missing.toml"),
])
def test_runner_refuses_unknown_renderers_with_exit_2(tmp_path, run_batch_here, args, words):
    """The first case through a real child, the others through batch/run.py's main() in this process."""
    bad = write_toml(tmp_path / "bad.toml", '''
        [renderers.ring]
        command = ["ring", "{scene}"]
        reads = "json"
        models = []
        ''')
    args = [a.format(bad=bad, missing=tmp_path / "missing.toml") for a in args]
    if args == ["-r", "ring"]:
        proc = subprocess.run([sys.executable, str(RUN), *args, "--list", "-o", str(tmp_path / "out")],
                              capture_output=True, text=True, timeout=300)
    else:
        proc = run_batch_here(*args, "--list", "-o", tmp_path / "out")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert words in proc.stderr


# -- the example renderer, end to end ---------------------------------------------------------------
def run_batch(out, *args):
    proc = subprocess.run([sys.executable, str(RUN), *args, "-o", str(out)], capture_output=True, text=True,
                          timeout=1800, cwd=ROOT)
    runs = json.loads((out / "metrics.json").read_text())["runs"]
    return proc, {(r["scene"], r["backend"]): r for r in runs}


BRIGHTER_SCALE = "0.25"  # the planted 1 % needs far less than full resolution: the runs assert their own power


def assert_brighter_fails_with_power(runs, backend, planted=0.01):
    """Every copper job of ``backend`` (output 1 % too bright) failed the noise test, and its run
    could see the planted error: its own ``detectable`` scale (90 % power at alpha) is below it,
    so a render too small to see 1 % fails here loudly instead of passing by luck."""
    for name in ("ggx_copper_50", "ggx_copper_70"):
        bright = runs[(name, backend)]
        assert bright["status"] == "failed" and "noise test" in bright["reason"], bright
        assert bright["detectable"]["scale"] < planted, (name, bright["detectable"])


@pytest.mark.slow
def test_example_renderer_ok_brighter_failed_polarisation_unsupported(tmp_path):
    """Done-when of the 'your renderer' issue: a renderer given only by a TOML file and a script
    renders the copper scenes and is judged ok on its own noise from its passes at default
    settings (full resolution, 2 passes); its version line is in metrics.json; a scene needing
    polarisation is unsupported naming the need. The same renderer with its output 1 % brighter
    fails: judged in a second run at a quarter of the resolution (1/16 of the cost), where its own
    ``detectable`` figure (0.5-0.6 %) shows it still has the power to see 1 %."""
    common = ["--renderers", str(EXAMPLE / "toy.toml"), "--renderers", str(EXAMPLE / "toy_brighter.toml"),
              "-s", "ggx_copper_50", "-s", "ggx_copper_70", "-s", "polarizing_plane_0"]
    proc, runs = run_batch(tmp_path / "out", *common, "-r", "toy")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in ("ggx_copper_50", "ggx_copper_70"):
        ok = runs[(name, "toy")]
        assert ok["status"] == "ok" and ok["resolution"] == [512, 512], ok
        assert ok["versions"] == {"toy": "toy_renderer 1.0"} and ok["passes"] == 2 and len(ok["pass_times"]) == 2
    proc, bright = run_batch(tmp_path / "bright", *common, "-r", "toy_brighter", "--scale", BRIGHTER_SCALE)
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert_brighter_fails_with_power(bright, "toy_brighter")
    for backend, r in (("toy", runs), ("toy_brighter", bright)):
        r = r[("polarizing_plane_0", backend)]
        assert r["status"] == "unsupported" and "does not model polarization" in r["reason"]


@pytest.mark.slow
def test_example_renderer_writing_spectral_exr(tmp_path):
    """The same with ``writes = "spectral"``: the example writes the Fichet 2021 layout (5 nm box
    bands, declared ``bands = "box"``), which the benchmark integrates with the CIE 1931 observer
    through the bands' histospline. Against the references in the scene format's colour it is `ok`
    at default settings (full resolution, 2 passes: the noise test detects about 0.1 %) with no
    known deviation (issue 33: it needed one against the Mitsuba-made references), and its band
    checks hold. 1 % brighter still fails on both copper scenes: judged in a second run at a
    quarter of the resolution, whose own ``detectable`` figure (about 0.6-0.7 %) shows the power to
    see 1 %."""
    common = ["--renderers", str(EXAMPLE / "toy.toml"), "--renderers", str(EXAMPLE / "toy_brighter.toml"),
              "-s", "ggx_copper_50", "-s", "polarizing_plane_0"]
    proc, runs = run_batch(tmp_path / "out", *common, "-r", "toy_spectral")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]  # ok and unsupported: no failure
    ok = runs[("ggx_copper_50", "toy_spectral")]
    assert ok["status"] == "ok" and ok["mode"] == "spectral" and ok["resolution"] == [512, 512], ok
    assert ok["known"] == [] and ok["test"]["pass"] and ok["detectable"]["scale"] < 0.002, ok
    assert runs[("polarizing_plane_0", "toy_spectral")]["status"] == "unsupported"
    proc, bright = run_batch(tmp_path / "bright", *common, "-s", "ggx_copper_70", "-r", "toy_spectral_brighter",
                             "--scale", BRIGHTER_SCALE)
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert_brighter_fails_with_power(bright, "toy_spectral_brighter")
