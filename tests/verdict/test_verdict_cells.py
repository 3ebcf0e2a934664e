"""Issue 45, items 6 and 8, on real renders of a declared renderer whose film has Mitsuba's 0.1 %
bias (tests/data/plant_renderers.toml ``plant_none``: tests/plant_renderer.py with Mitsuba's RGB
film, against references made with the CMF film).

At a quarter of the resolution and 1024 spp the noise test detects about 0.11 % with 90 % power, so
that bias sits at the edge of its power: whether the render passes follows the seed. Two runs of
the same build with other seeds then differ in status while their images agree within noise
(item 6: compare_runs, --baseline and the panel call that an unstable verdict, not a change), and
the failing one fails by its scale test while its block test passes (item 8: every noise-test cell
names the scale test with its own figures first). A third build, 0.3 % brighter, is a real change
that only the two-sample scale test sees: still CHANGED, exit 1.

The renders use fixed seeds (the same job gives the same image: tests/jobs/test_engines.py); the seeds
of the second run are tried in turn until its status differs from the first's, and every premise
(the flip, which part failed) is asserted, so the tests cannot pass on a case they were not made
for. About 30 s."""
import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from markupsafe import escape

from conftest import ROOT, run_batch, run_bpy
from spectral_bench.batch import records
from spectral_bench.batch.report import results

pytestmark = pytest.mark.slow  # every test here costs over ~1 s of CPU, its children and module fixtures counted (benchmarks/TESTS.md)

PLANTS = ROOT / "tests" / "data" / "plant_renderers.toml"
SCENE = "ggx_copper_50"
SETTINGS = ["-r", "plant_none", "-s", SCENE, "--scale", "0.25", "--spp", "1024", "--no-flip"]
SEEDS = (50, 60, 10, 20, 30, 40, 70, 80)  # the second run's, tried in turn until its status differs
TESTS = str(ROOT / "tests")


def compare_runs(*args):
    return subprocess.run([sys.executable, str(ROOT / "batch" / "compare_runs.py"), *map(str, args)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)


def job(out):
    (entry,) = json.loads((Path(out) / "metrics.json").read_text())["runs"]
    return entry


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{"a": first run, "b": the same build with another seed (made with --baseline a and --junit),
    whose status differs from a's; "c": the build 0.3 % brighter (same renderer name), "failed":
    whichever of a and b failed}."""
    base = tmp_path_factory.mktemp("verdict_cells")
    a = base / "a"
    proc = run_batch("-o", a, "--renderers", PLANTS, *SETTINGS, "--seed", "0")
    assert proc.returncode in (0, 1), proc.stderr[-3000:]
    for seed in SEEDS:
        b = base / f"b{seed}"
        proc = run_batch("-o", b, "--renderers", PLANTS, *SETTINGS, "--seed", seed, "--baseline", a,
                         "--junit", base / f"junit{seed}.xml")
        assert proc.returncode in (0, 1), proc.stderr[-3000:]
        if job(b)["status"] != job(a)["status"]:
            break
    else:
        pytest.fail(f"no seed of {SEEDS} flips the status of {SCENE} against seed 0: the bias is not at the "
                    "edge of the test's power at these settings")
    brighter = base / "brighter.toml"
    script = (ROOT / "tests" / "plant_renderer.py").as_posix()
    brighter.write_text(f"""
[renderers.plant_none]
command = ["{{python}}", "{script}", "{{scene}}", "--out", "{{output}}", "--spp", "{{spp}}", "--seed", "{{seed}}",
           "--plant", "scale=1.003"]
reads = "mitsuba"
models = ["spectral"]
version = ["{{python}}", "{script}", "--version"]
""")
    c = base / "c"
    proc = run_batch("-o", c, "--renderers", brighter, *SETTINGS, "--seed", "100")
    assert proc.returncode in (0, 1), proc.stderr[-3000:]
    failed = a if job(a)["status"] == "failed" else b
    return {"a": a, "b": b, "c": c, "failed": failed, "junit": base / f"junit{seed}.xml"}


def _cell_parts(test):
    """The scale test's and the block test's figures as the record gives them (the parts the cell
    must quote, each its own)."""
    sc = test["scale_test"]
    return (f"p {sc['p_min']:.3g} (threshold {sc['threshold']:.3g})",
            f"p_min {test['p_min']:.3g} (threshold {test['threshold']:.3g}), z_max {test['z_max']:.2f}")


# -- item 8: a failing cell says what failed -----------------------------------------------------------
@pytest.mark.slow
def test_the_failing_cell_names_the_scale_test_with_its_own_figures(runs):
    """The run that failed, failed by its scale test while its block test passed: summary.md's,
    report.html's and JUnit's noise-test cell names the scale test first, with its own p and
    threshold and how far off it measured the render, then the block test that passed; the test's
    reason quotes the scale test, not the block test's p as if it had failed."""
    out = runs["failed"]
    r = job(out)
    test = r["test"]
    assert r["status"] == "failed" and test["pass"] is False, r["reason"]
    assert test["block_pass"] is True and test["scale_test"]["pass"] is False, test  # the case of the issue
    scale_figures, block_figures = _cell_parts(test)
    cell = records.noise_test_text(test)
    assert cell.startswith("FAIL: scale test failed: ") and f"{scale_figures}; block test passed: {block_figures}" in cell, cell
    sc = test["scale_test"]
    worst = max(range(3), key=lambda c: abs(sc["z"][c]))
    assert f"{'RGB'[worst]} {abs(sc['s'][worst] - 1) * 100:.2g} % {'bright' if sc['s'][worst] > 1 else 'dark'}" in cell
    assert "scale test: " in test["reason"] and scale_figures in test["reason"] and "min p =" not in test["reason"]

    summary = (out / "summary.md").read_text()
    # the status cell: "failed", with what cross-checked the reference where something did (ggx_copper_50: pbrt-v4)
    row = next(l for l in summary.splitlines() if l.startswith("| failed") and f" | {SCENE} | " in l)
    assert row.startswith(f"| failed ({results.crosscheck_note(r)}) | ") if results.crosscheck_note(r) else row.startswith("| failed | "), row
    assert f"| {cell}; detects " in row, row
    page = (out / "report.html").read_text()
    assert str(escape(f"Sidak): {cell}")) in page
    if out == runs["b"]:  # the run made with --junit
        case = ET.parse(runs["junit"]).getroot().find(".//testcase")
        props = {p.get("name"): p.get("value") for p in case.find("properties")}
        assert props["noise test"] == cell and f"noise test: {cell}" in case.find("system-out").text


# -- item 6: comparing two builds of the same renderer never cries wolf ------------------------------------
@pytest.mark.slow
def test_a_verdict_that_flips_within_noise_is_unstable_not_changed(runs):
    """The same build, another seed: the status differs, the images agree within noise. compare_runs
    names the unstable verdict with the deviation both runs measure against what the test detects,
    lists the job as unstable, not CHANGED, and exits 0; the run made with --baseline says the same
    in its record, summary.md and report.html."""
    a, b = runs["a"], runs["b"]
    ra, rb = job(a), job(b)
    assert ra["status"] != rb["status"] and {ra["status"], rb["status"]} == {"ok", "failed"}
    cmp = compare_runs(a, b)
    assert cmp.returncode == 0, cmp.stdout[-3000:] + cmp.stderr[-2000:]
    (j,) = json.loads((b / "compare" / "compare.json").read_text())["jobs"]
    assert j["changed"] is False and j["changes"] == [] and j["baseline"]["status"] == "same", j
    m = re.search(r"verdict unstable: the deviation ([0-9.]+) % is at the test's detectable ([0-9.]+) % "
                  r"\(status (\w+) -> (\w+), noise test against the reference (\w+) -> (\w+); the images agree within noise\)",
                  j["unstable"])
    assert m, j["unstable"]
    dev, det = float(m.group(1)) / 100, float(m.group(2)) / 100
    assert m.group(3, 4) == (ra["status"], rb["status"])
    assert det == pytest.approx(min(rb["detectable"]["tests"].values()), rel=0.05)
    # the deviation both runs measure: between the smallest and largest of their own scale estimates
    own = [abs(s - 1) for r in (ra, rb) for s in r["test"]["scale_test"]["s"]]
    assert min(own) <= dev * 1.05 and dev <= max(own) * 1.05 and 0.5 <= dev / det <= 1.5, (dev, det, own)
    line = next(l for l in cmp.stdout.splitlines() if l.startswith("| unstable | " + SCENE))
    assert j["unstable"] in line and "| CHANGED |" not in cmp.stdout
    assert "1 of them with a verdict that flipped within noise" in cmp.stdout

    rec = rb["baseline"]  # --baseline a: the same record, the same words
    assert rec["status"] == "same" and rec["unstable"] == rec["reason"] == j["unstable"], rec
    against = (b / "summary.md").read_text().split("## Jobs")[0]
    assert j["unstable"] in against and f"| unstable | {SCENE} |" in against and "1 unstable" in against, against
    assert str(escape(j["unstable"])) in (b / "report.html").read_text()  # as the report's autoescaping writes it


@pytest.mark.slow
def test_a_change_only_the_scale_test_sees_is_still_changed(runs):
    """The build 0.3 % brighter against the failing run, both failing (no status to flip): the
    two-sample block test does not see 0.3 % (it detects about 0.9 %), the scale test does; the job is
    CHANGED, the change names the scale test with its figures, and compare_runs exits 1."""
    old, new = runs["failed"], runs["c"]
    assert job(old)["status"] == job(new)["status"] == "failed"
    cmp = compare_runs(old, new)
    assert cmp.returncode == 1, cmp.stdout[-3000:] + cmp.stderr[-2000:]
    (j,) = json.loads((new / "compare" / "compare.json").read_text())["jobs"]
    t = j["baseline"]["test"]
    assert t["block_pass"] is True and t["scale_test"]["pass"] is False, t  # what the case is about
    assert j["changed"] is True and j["unstable"] is None
    scale_figures = f"p {t['scale_test']['p_min']:.3g} (threshold {t['scale_test']['threshold']:.3g})"
    assert any(c.startswith("image differs beyond noise: scale test: ") and scale_figures in c for c in j["changes"]), j
    assert f"| CHANGED | {SCENE} |" in cmp.stdout
    for ratio, se in j["baseline"]["ratio"]:
        assert abs(ratio - 1.003) < 4 * se, j["baseline"]["ratio"]


# -- the panel: the same cell, the same unstable verdict ------------------------------------------------
@pytest.mark.slow
def test_the_panel_shows_the_failing_part_and_the_unstable_verdict(runs):
    """The Results panel on the second run with the first as its baseline: its noise-test label is
    the cell of summary.md, and the job's baseline says unstable with the deviation, both from the
    run's own --baseline record and after the panel's Compare (compare_runs' code)."""
    a, b = runs["a"], runs["b"]
    out = run_bpy(f"""
        sys.path.insert(0, {TESTS!r})
        import layout_recorder as lr
        s = bpy.context.window_manager.spectral_bench_run
        s.output_dir = {str(b)!r}
        s.baseline_dir = {str(a)!r}
        def labels():
            calls = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark_results, lr.Context())
            return [c[2].get("text") for c in calls if c[1] == "label"]
        before = labels()
        r = bpy.ops.spectral_bench.compare_baseline()
        print(json.dumps({{"before": before, "after": labels(), "r": list(r)}}))
    """)
    assert out["r"] == ["FINISHED"]
    rb = job(b)
    for labels in (out["before"], out["after"]):
        assert "noise test: " + records.noise_test_text(rb["test"]) in labels, labels
        assert any(t and t.startswith("verdict unstable: the deviation ") and "is at the test's detectable" in t
                   for t in labels), labels
        assert any(t and t.startswith("baseline: unstable") for t in labels), labels  # compare_runs' word
    if rb["status"] == "failed":
        assert any(t and t.startswith("noise test: FAIL: scale test failed: ") for t in out["before"])


# -- a probe's verdict that flips within noise (real EXRs, hand-made records) ------------------------------
def _probe_run(out, seed, measured):
    """A run folder of one job: a real EXR render with its own noise (4 passes of the same image)
    and a probe measuring ``measured`` against 1.0 with standard error 0.01, judged by the project's
    test (stats.compare_means at alpha 0.01); the status follows the probe."""
    import numpy as np
    from spectral_bench.batch import exr
    from spectral_bench.batch.verdict import stats
    rng = np.random.default_rng(seed)
    truth = np.broadcast_to(np.linspace(0.2, 1.0, 16)[None, :, None], (16, 16, 3))
    passes = truth[None] + rng.normal(0.0, 0.05, (4,) + truth.shape)
    mean, se = passes.mean(axis=0), passes.std(axis=0, ddof=1) / 2
    res = out / "s" / "results" / "mitsuba"
    res.mkdir(parents=True)
    exr.write_image(res / "render.exr", ["R", "G", "B"], mean.astype(np.float32),
                    {f"stderr.{c}": se[..., i].astype(np.float32) for i, c in enumerate("RGB")})
    judged = stats.compare_means([measured], [1.0], [0.01], alpha=0.01)
    stat = {"measured": [measured], "expected": [1.0], "se": [0.01], "threshold": float(judged["threshold"])}
    passed = bool(judged["pass"])
    run = {"scene": "s", "case": "c", "backend": "mitsuba", "mode": "m", "status": "ok" if passed else "failed",
           "reason": "" if passed else "failed: p", "spp": 4096, "passes": 4, "resolution": [16, 16],
           "image": "s/results/mitsuba/render.exr", "channels": ["R", "G", "B"], "metrics": {},
           "probes": [{"name": "p", "pass": passed, "stat": stat}], "pass_times": [1.0, 1.1, 0.9, 1.0],
           "detectable": {"scale": None, "probes": {"p": stats.detectable_scale(stat)}}}
    (out / "metrics.json").write_text(json.dumps({"options": {"alpha": 0.01, "block": 4}, "runs": [run]}))
    return run


# the probe's unstable-verdict test on these run folders: tests/verdict/test_unstable_verdict.py (in process)
