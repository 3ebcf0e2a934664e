"""Every script in benchmarks/ starts and finishes with tiny settings (issue 23: six had stopped at
start-up after a refactor and nothing noticed).

Each script runs as a user runs it, in a child process, with the arguments in SMOKE (its own size
flags, or ``--smoke`` where it had none): it must exit 0, print its table (or, for the GPU benchmark
on a machine without CUDA, the record that it was not measured and why) and write nothing into
benchmarks/ (``--write`` is never given). The runs together take minutes on 2 cores: they are
slow tests; the fast one checks that every script has a smoke run.
"""
import re
import subprocess
import sys

import pytest

from conftest import ROOT

BENCH = ROOT / "benchmarks"
LIBRARIES = {"record.py"}  # imported by the scripts, not run
NEEDS = {"crosscheck_fluorescence.py": "art"}  # a script that needs another renderer skips without it, naming why
TABLE = r"(?m)^\|[-|: ]+\|\s*$"  # a Markdown table's separator row
SMOKE = {  # script -> (arguments that make it run in seconds, what its output must contain: a regex)
    # one cell (bgr: a plant and the correct render, 2 runs; flip has two cells, 3 runs: 16.8 -> 11.7 s of CPU)
    "bench_diagnosis.py": (["--seeds", "1", "--only", "bgr", "--workers", "1", "--out", "{tmp}/DIAGNOSIS.md",
                            "--results", "{tmp}/runs.jsonl"], TABLE),
    "bench_dispersion.py": (["--size", "16", "--spp", "4", "--repeat", "1", "--calls", "1"], TABLE),
    "bench_engines.py": (["--smoke"], TABLE),
    "bench_export_render.py": (["--smoke"], TABLE),
    "bench_fixed_cost.py": (["--smoke", "--flip", "on"], TABLE),  # --flip on: its FLIP hooks run (a broken hook fails it)
    "bench_fluorescence.py": (["--scale", "0.1", "--spp", "4", "--rounds", "1", "--repeat", "1"], TABLE),
    "bench_gpu.py": (["--smoke"], TABLE + r"|Not measured: no CUDA device \(.+\)"),
    "bench_rgb_backends.py": (["--smoke", "--scale", "0.25", "--passes", "2", "--repeats", "1", "--out", "{tmp}"], TABLE),
    "bench_thin_film.py": (["--scale", "0.05", "--spp", "4", "--repeat", "1"], TABLE),
    "calibrate_fluorescence.py": (["--smoke"], TABLE),
    # its render half (the judge half reads what render cached: CALIBRATION.md has both commands)
    "calibrate_glass_false_alarms.py": (["render", "--seeds", "1", "--scale", "0.25", "-s", "ggx_glass", "--cache", "{tmp}"],
                                        r"ggx_glass seed 0: [0-9.]+ s"),
    "calibrate_ggx_probe.py": (["--smoke"], TABLE),
    "calibrate_noise_test.py": (["--smoke", "-s", "ggx_copper_50"], TABLE),
    "calibrate_prism_probe.py": (["--smoke"], TABLE),
    "calibrate_rgb_colorchecker.py": (["--smoke"], TABLE),
    "calibrate_thin_film_probe.py": (["--smoke"], TABLE),
    "compare_records.py": (["--smoke"], r"1 jobs compared, 0 differences"),
    "crosscheck_fluorescence.py": (["--size", "16", "--spp", "4", "--passes", "2", "-s", "fluorescent_sphere_lone"], TABLE),
    "ggx_multiscatter.py": (["--scene", "furnace_ggx_030", "--spp", "4"], TABLE),
    "furnace_depth.py": (["--rho", "0.9", "--spp", "2", "--size", "8", "--config", "3"], TABLE),
    "fuzz_scenes.py": (["--count", "40", "--schema-count", "4", "--chunk", "20", "--workers", "1"], TABLE),
    "ggx_shadowing_scene.py": (["--spp", "2", "--passes", "2"], r"height-correlated / separable, image mean"),
    "measure_determinism.py": (["--only", "mitsuba", "--size", "8", "--spp", "2", "--repeats", "2"], r'"bit_identical": (true|false)'),
    "pbrt_writer_checks.py": (["--smoke"], TABLE + r"|Not measured: no pbrt-v4"),
    "plugin_lane_estimators.py": ([], r"variance one-lane / mixture"),
    "power_by_scene.py": (["-s", "ggx_copper_50"], TABLE),
    "profile_verdicts.py": (["--smoke"], r"1 jobs compared, 0 differences"),
    "reference_colour_change.py": (["--smoke", "{tmp}"], TABLE),
    "reference_storage.py": (["--smoke"], TABLE),
    "rgb_microfacet_check.py": (["--smoke", "--spp", "4", "--passes", "2"], TABLE),
}


def test_every_benchmark_script_has_a_smoke_run():
    scripts = {p.name for p in BENCH.glob("*.py")} - LIBRARIES
    assert scripts == set(SMOKE), f"give each new script tiny settings here: {sorted(scripts ^ set(SMOKE))}"


def recorded_files():
    return {p.name: p.stat().st_mtime_ns for p in BENCH.iterdir() if p.is_file()}


@pytest.mark.slow
@pytest.mark.parametrize("script", sorted(SMOKE))
def test_benchmark_script_runs(script, tmp_path):
    args, expected = SMOKE[script]
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]  # a script's output folder, where it takes one
    if script in NEEDS:
        from spectral_bench.batch import backends
        ok, why = backends.get(NEEDS[script]).availability()
        if not ok:
            pytest.skip(f"{script} needs {NEEDS[script]}: {why}")
    before = recorded_files()
    proc = subprocess.run([sys.executable, str(BENCH / script), *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=600, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, f"{script} exited {proc.returncode}:\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
    assert re.search(expected, proc.stdout), f"{script} printed no table:\n{proc.stdout[-3000:]}"
    assert recorded_files() == before, f"{script} wrote into benchmarks/ without --write"
