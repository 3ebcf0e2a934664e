"""Issue 20, item 5: render until decided (``--detect S``, batch/verdict/sequential.py).

The renders are real (the example renderer of examples/your_renderer/, its 1 % brighter twin and
the real command line); the false-alarm guarantee of the repeated looks is checked by simulation on
the stored noise model of a committed reference (as tests/verdict/test_power.py does), not by rendering."""

import numpy as np
import pytest

from conftest import GOLDEN, ROOT, metrics, run_batch
from spectral_bench.batch import cli, exr
from spectral_bench.batch.backends import passes
from spectral_bench.batch.jobs import plan
from spectral_bench.batch.verdict import compare, references, sequential
from test_power import clopper_pearson

EXAMPLE = ROOT / "examples" / "your_renderer"
SCENE = GOLDEN / "ggx_copper_50.json"
QUARTER = ("--scale", "0.25", "--no-flip")


def test_schedule_doubles_to_the_cap_and_spends_alpha_over_its_looks():
    assert sequential.schedule(2, 16) == [2, 4, 8, 16]
    assert sequential.schedule(2, 12) == [2, 4, 8, 12]
    assert sequential.schedule(4, 4) == [4] and sequential.schedule(8, 2) == [8]
    assert sequential.alpha_per_look(0.01, 4) == pytest.approx(0.0025)


@pytest.mark.parametrize("args", [["--detect", "0"], ["--detect", "1"], ["--detect", "nan"], ["--detect", "-0.1"],
                                  ["--max-passes", "0"], ["--max-passes", "100000"]])
def test_a_bad_detect_option_exits_2_naming_it(args, capsys):
    with pytest.raises(SystemExit) as info:
        cli.parse(args)
    assert info.value.code == 2 and args[0] in capsys.readouterr().err


def test_detect_from_a_settings_file_and_in_the_verdict_only_when_set(tmp_path):
    good, bad = tmp_path / "good.toml", tmp_path / "bad.toml"
    good.write_text("detect = 0.01\nmax_passes = 8\n")
    bad.write_text("detect = 1.5\n")
    opts = cli.parse(["--settings", str(good)])
    assert opts["detect"] == 0.01 and opts["max_passes"] == 8
    with pytest.raises(cli.SettingsError, match="detect"):
        cli.parse(["--settings", str(bad)])
    # the job's verdict settings (hashed into its id) carry it; without it they are as before
    assert plan.verdict_settings(opts)["detect"] == 0.01
    plain = plan.verdict_settings(cli.parse([]))
    assert "detect" not in plain and "max_passes" not in plain


def _runs(out):
    return {r["backend"]: r for r in metrics(out)["runs"]}


@pytest.mark.slow
def test_unbiased_render_stops_once_detectable_and_a_brighter_one_fails(tmp_path):
    """toy (unbiased) at a quarter of ggx_copper_50: detectable 0.51 % at 2 passes, 0.37 % at 4,
    so --detect 0.0045 stops at the second look, below the cap of 16; toy_brighter (every pass
    1 % too bright) fails. The continued render equals the same passes rendered in one go."""
    out = tmp_path / "detect"
    proc = run_batch("-i", SCENE, "--renderers", EXAMPLE / "toy.toml", "--renderers", EXAMPLE / "toy_brighter.toml",
                     "-r", "toy", "-r", "toy_brighter", "--spp", 64, "--passes", 2, "--detect", 0.0045,
                     "--max-passes", 16, *QUARTER, "-o", out)
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    runs = _runs(out)
    ok, bright = runs["toy"], runs["toy_brighter"]
    seq = ok["sequential"]
    assert ok["status"] == "ok", ok
    assert seq["stopped"] == "detectable" and seq["planned_looks"] == 4 and seq["alpha_per_look"] == pytest.approx(0.0025)
    looks = seq["looks"]
    assert [lk["passes"] for lk in looks] == [2, 4] and all(lk["pass"] for lk in looks)
    assert looks[0]["detectable"] > 0.0045 >= looks[-1]["detectable"], looks
    assert ok["passes"] == 4 < seq["max_passes"] and ok["spp"] == 128 and len(ok["pass_times"]) == 4
    # the final verdict is the last look's, at the alpha spent per look
    assert ok["test"]["alpha"] == pytest.approx(0.0025) and ok["detectable"]["alpha"] == pytest.approx(0.0025)
    assert ok["detectable"]["scale"] == pytest.approx(looks[-1]["detectable"], rel=1e-9)
    log = (out / "ggx_copper_50" / "results" / "toy" / "render.log").read_text()
    assert log.count("--seed") == 4, log[-2000:]  # no pass rendered twice
    assert bright["status"] == "failed" and "noise test" in bright["reason"], bright
    assert bright["sequential"]["stopped"] == "failed" and bright["sequential"]["looks"][-1]["pass"] is False
    assert metrics(out)["runs"]  # the reader validated the file against the schema

    # the same four passes (32 spp each, seeds 0, 1000, 2000, 3000) in one go: the same image
    once = tmp_path / "once"
    proc = run_batch("-i", SCENE, "--renderers", EXAMPLE / "toy.toml", "-r", "toy", "--spp", 128, "--passes", 4,
                     *QUARTER, "-o", once)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    a = exr.read_image_and_stderr(out / "ggx_copper_50" / "results" / "toy" / "render.exr")
    b = exr.read_image_and_stderr(once / "ggx_copper_50" / "results" / "toy" / "render.exr")
    assert a[0] == b[0] and np.array_equal(a[1], b[1]) and np.array_equal(a[2], b[2])
    assert "sequential" not in _runs(once)["toy"]


def _sequential_false_alarm(mu, sigma2, ref_var, per_pass, alpha, spend, rng):
    """One simulated --detect run of an unbiased renderer (Gaussian passes of per_pass samples,
    R, G, B fully correlated as a path tracer's are) against a reference drawn around the truth:
    True when the procedure ends in a fail. Every look states a detectable error above the target,
    so all K looks are taken: stopping for power only removes looks, so this is the worst case
    (and it spares the bisection of ``detectable``). ``spend``: test each look at alpha / K (the
    implementation) or at alpha (no accounting for the repeated looks)."""
    ref = compare.ReferenceAt(mu + np.sqrt(ref_var) * rng.standard_normal(mu.shape), ref_var, sigma2, 8 * 7)
    acc = passes.Accumulation(per_pass=per_pass)
    sd = np.sqrt(sigma2 / per_pass)

    def render_to(n):
        while acc.count < n:
            acc.add(mu + sd * rng.standard_normal(mu.shape[:2] + (1,)))

    def look(a):
        zt = compare.z_test(acc.mean, ref, per_pass * acc.count, own_var_of_mean=acc.var_of_mean(),
                            own_passes=acc.count, alpha=a if spend else alpha)
        return zt.passed, 1.0

    return sequential.run(render_to, look, 2, 16, 0.5, alpha)["stopped"] == "failed"


@pytest.mark.slow
def test_repeated_looks_false_alarm_at_most_alpha_by_simulation():
    """The committed ggx_copper_50 reference at 32x32 as the noise model; every run takes all
    K = 4 looks (2, 4, 8, 16 passes): the worst case for false alarms. At alpha 0.2 (large, to
    measure the rate in 800 trials): with alpha / K per look the whole procedure false-alarms at
    most at alpha; testing every look at alpha false-alarms more often (the repeated looks add
    up; that it stays below 0.2 here is the noise test's own conservatism at few passes)."""
    ref = references.load("ggx_copper_50")
    at = compare.reference_at(ref.mean, ref.stderr, ref.spp, (32, 32, 3), ref.provenance.get("passes", 8))
    mu, sigma2, ref_var = at.mean[..., :3], np.maximum(at.sigma2[..., :3], 1e-12), at.var_of_mean[..., :3]
    rng = np.random.default_rng(5)
    trials, alpha = 800, 0.2
    spent = sum(_sequential_false_alarm(mu, sigma2, ref_var, 32, alpha, True, rng) for _ in range(trials))
    naive = sum(_sequential_false_alarm(mu, sigma2, ref_var, 32, alpha, False, rng) for _ in range(trials))
    lo, hi = clopper_pearson(spent, trials)
    nlo, nhi = clopper_pearson(naive, trials)
    print(f"false alarms over {trials}: alpha/K per look {spent} (99 % CI [{lo:.3f}, {hi:.3f}]), "
          f"alpha per look {naive} ([{nlo:.3f}, {nhi:.3f}])")
    assert lo <= alpha, (spent, trials)
    assert hi < nlo, (spent, naive, trials)  # the spending is what keeps it down


@pytest.mark.slow
def test_resume_keeps_a_detect_run_and_refuses_another_target(tmp_path):
    """--detect and --max-passes are options of the run like the others: a resumed run takes them
    from metrics.json and keeps the finished render; a different target is refused (exit 2)."""
    out = tmp_path / "o"
    proc = run_batch("-i", GOLDEN / "ggx_copper_50_isolated.json", "-r", "mitsuba", "--scale", 0.0625, "--spp", 4,
                     "--detect", 0.2, "--max-passes", 4, "--no-flip", "-o", out)
    assert proc.returncode in (0, 1), proc.stderr[-2000:]
    run = metrics(out)["runs"][0]
    assert run["sequential"]["target"] == 0.2 and run["sequential"]["max_passes"] == 4, run
    stamp = (out / run["image"]).read_bytes()
    proc = run_batch("--resume", out)
    assert "1 jobs kept, 0 to run" in proc.stderr, proc.stderr[-2000:]
    assert metrics(out)["options"]["detect"] == 0.2 and (out / run["image"]).read_bytes() == stamp
    for args, option in ((["--detect", "0.1"], "--detect"), (["--max-passes", "8"], "--max-passes")):
        proc = run_batch("--resume", out, *args)
        assert proc.returncode == 2 and option in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
