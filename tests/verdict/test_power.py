"""Issue 20: every judged run states its power (``detectable``), the noise test's scale test, and
any integer fraction of a reference's resolution (independent per axis) is judged; a scene that
--scale divides into no integer fraction renders at the nearest scale that does (issue 23: the
tiny suite's 0.125 and the 620x420 charts), and a scale above 1 is refused (exit 2).

The power test simulates on the stored noise model of a committed reference (its mean, its
per-sample variance and its own standard error), not by rendering: planted uniform scale errors of
the size ``detectable`` states must be detected about 90 % of the time."""

import numpy as np
import pytest
from scipy import stats as st

from conftest import GOLDEN, metrics, run_batch
from spectral_bench.batch import cli
from spectral_bench.batch.jobs import plan
from spectral_bench.batch.verdict import compare, references


def clopper_pearson(k, n, conf=0.99):
    a = (1 - conf) / 2
    return (0.0 if k == 0 else st.beta.ppf(a, k, n - k + 1)), (1.0 if k == n else st.beta.ppf(1 - a, k + 1, n - k))


def test_reference_box_filters_by_independent_integer_factors():
    rng = np.random.default_rng(1)
    mean, se = rng.uniform(0.1, 1, (8, 12, 3)), rng.uniform(0.01, 0.02, (8, 12, 3))
    at = compare.reference_at(mean, se, 64, (2, 4, 3))  # fy = 4, fx = 3
    tile = (slice(4, 8), slice(3, 6))
    assert np.allclose(at.mean[1, 1], mean[tile].mean(axis=(0, 1)))
    assert np.allclose(at.var_of_mean[1, 1], (se[tile] ** 2).sum(axis=(0, 1)) / 12**2)
    assert at.dof == 12 * 7
    # the charts: 620x420 at 1/5 x 1/5 and 1/10 x 1/10 judged, 78x52 (0.125) is no fraction
    big = np.ones((420, 620, 3))
    assert compare.reference_at(big, big * 0.01, 64, (84, 124, 3)).mean.shape == (84, 124, 3)
    assert compare.reference_at(big, big * 0.01, 64, (42, 62, 3)).mean.shape == (42, 62, 3)
    assert compare.reference_at(big, big * 0.01, 64, (420, 155, 3)).mean.shape == (420, 155, 3)  # fy 1, fx 4
    with pytest.raises(ValueError, match="integer in each axis"):
        compare.reference_at(big, big * 0.01, 64, (52, 78, 3))


def test_a_scale_no_resolution_divides_moves_to_the_nearest_judged_one(golden):
    chart = [("macbeth_chart_D65", golden["macbeth_chart_D65"])]
    assert plan.scale_for(620, 420, 0.125) == 0.1  # 78x52 is no fraction; 0.1 (62x42) is nearer than 0.2
    assert plan.scale_for(620, 420, 0.15) == 0.2 and plan.scale_for(512, 512, 0.125) == 0.125
    assert plan.scale_for(620, 420, 0.2) == 0.2 and plan.scale_for(620, 420, 0.05) == 0.05
    changes = plan.scale_changes(chart, 0.125)
    assert changes == [(0.1, [("macbeth_chart_D65", (620, 420), (62, 42))])], changes
    both = chart + [("ggx_glass", golden["ggx_glass"])]
    assert [n for _, moved in plan.scale_changes(both, 0.125) for n, _, _ in moved] == ["macbeth_chart_D65"]
    assert plan.scale_changes(both, 0.25) == [] and plan.scale_changes(both, 1.0) == []
    assert plan.for_run(golden["macbeth_chart_D65"], {"scale": 0.125})["render"]["width"] == 62
    assert plan.for_run(golden["macbeth_chart_D65"], {"scale": 0.125}, judged=False)["render"]["width"] == 78
    assert plan.scale_problem(both, 0.125) is None and plan.scale_problem(both, 1.0) is None
    assert "ggx_glass" in plan.scale_problem(both, 2.0)  # larger than the reference: nothing to box-filter


def test_help_says_which_scales_are_judged():
    text = cli.parser().format_help()
    text = " ".join(text.split())  # argparse wraps lines
    assert "integer" in text and "nearest scale" in text and "exit 2" in text


@pytest.mark.slow
def test_non_dividing_scale_renders_at_the_nearest_judged_one(tmp_path, run_batch_here):
    """--scale 0.125 does not divide 620x420: the chart renders at 0.1 (62x42), said in the log, and
    that render is judged like one asked for at --scale 0.1 (noise test, scale test, detectable
    size with the patches' colour difference); a scale above 1 is refused (exit 2, nothing written)."""
    moved = run_batch("-i", GOLDEN / "macbeth_chart_D65.json", "-r", "mitsuba", "--scale", "0.125", "--spp", "4",
                      "--no-flip", "-o", tmp_path / "moved")
    assert moved.returncode in (0, 1), moved.stderr[-2000:]
    assert "--scale 0.125 is no integer fraction of 620x420: macbeth_chart_D65 renders at 0.1 (62x42)" \
        in moved.stderr, moved.stderr[-2000:]
    run = metrics(tmp_path / "moved")["runs"][0]
    assert run["resolution"] == [62, 42]
    assert run["test"]["pass"] is not None, run["test"]
    assert run["test"]["scale_test"]["pass"] is not None
    det = run["detectable"]
    assert det["power"] == 0.9 and det["alpha"] == 0.01 and 0 < det["scale"] < 1, det
    assert det["patch_de00"] > 0 and det["probes"], det
    finer = run_batch_here("-i", GOLDEN / "macbeth_chart_D65.json", "-r", "mitsuba", "--scale", "2", "--spp", "4",
                           "--no-flip", "-o", tmp_path / "finer")  # refused before anything renders: in this process
    assert finer.returncode == 2 and "macbeth_chart_D65" in finer.stderr, finer.stderr[-2000:]
    assert not (tmp_path / "finer" / "metrics.json").exists()


def _simulate(mu, sigma2, ref_var, spp, scale, rng, correlated=True):
    """Two passes of a render whose truth is ``scale`` x mu (per-sample variance sigma2), and a
    reference drawn around mu with variance ref_var: (ReferenceAt, render mean, its stderr^2)."""
    shape = mu.shape if not correlated else mu.shape[:2] + (1,)
    passes = [scale * mu + np.sqrt(sigma2 / (spp / 2)) * rng.standard_normal(shape) for _ in range(2)]
    mean = (passes[0] + passes[1]) / 2
    var = (passes[0] - passes[1]) ** 2 / 4  # (a - b)^2 / 4 = sample variance of the mean of two, 1 dof
    ref_mean = mu + np.sqrt(ref_var) * rng.standard_normal(mu.shape)
    return compare.ReferenceAt(ref_mean, ref_var, sigma2, 8 * 7), mean, var


@pytest.mark.slow
@pytest.mark.parametrize("scene,spp", [("ggx_copper_50", 64), ("ggx_glass", 256)])
def test_planted_errors_of_the_detectable_size_are_detected_90_percent(scene, spp):
    """The stored noise model of the committed reference at 64x64 (its mean as the truth, its
    per-sample variance for the render, its own standard error for the reference); 400 trials."""
    ref = references.load(scene)
    at = compare.reference_at(ref.mean, ref.stderr, ref.spp, (64, 64, 3), ref.provenance.get("passes", 8))
    mu, sigma2, ref_var = at.mean[..., :3], np.maximum(at.sigma2[..., :3], 1e-12), at.var_of_mean[..., :3]
    rng = np.random.default_rng(20)
    ra, mean, var = _simulate(mu, sigma2, ref_var, spp, 1.0, rng)
    det = compare.z_test(mean, ra, spp, own_var_of_mean=var, own_passes=2).detectable()
    eps = det["scale"]
    assert 0 < eps < 0.2, det
    trials = 400
    hits = fa = 0
    for _ in range(trials):
        ra, mean, var = _simulate(mu, sigma2, ref_var, spp, 1.0 + eps, rng)
        hits += not compare.z_test(mean, ra, spp, own_var_of_mean=var, own_passes=2).passed
        ra, mean, var = _simulate(mu, sigma2, ref_var, spp, 1.0, rng)
        fa += not compare.z_test(mean, ra, spp, own_var_of_mean=var, own_passes=2).passed
    lo, hi = clopper_pearson(hits, trials)
    # power at the stated size: about 90 % (a lower bound by construction; 99 % Clopper-Pearson)
    assert lo <= 0.93 and hi >= 0.9, (hits, trials, lo, hi, det)
    # and half that error is detected far less often: the figure is not loose
    half = 0
    for _ in range(100):
        ra, mean, var = _simulate(mu, sigma2, ref_var, spp, 1.0 + eps / 2, rng)
        half += not compare.z_test(mean, ra, spp, own_var_of_mean=var, own_passes=2).passed
    print(f"{scene}: detectable {eps:.5f} ({det['by']}), detected {hits}/{trials} (99 % CI [{lo:.3f}, {hi:.3f}]), "
          f"half of it {half}/100, false alarms {fa}/{trials}")
    assert half < 60, half
    assert clopper_pearson(fa, trials)[0] <= 0.01, fa


def test_run_scale_counts_radiance_probes_only():
    """A probe of radiance (a patch) counts towards detectable.scale; band positions, which a
    uniform scale does not move, keep their own figure only."""
    from spectral_bench.batch.verdict import judge, stats
    patch = {"name": "lambert patch_white", "unit": "dE00", "pass": True,
             "stat": stats.compare_means([0.9, 0.9, 0.9], [0.9, 0.9, 0.9], [0.0009, 0.0009, 0.0009], dof=500, tests=3)}
    bands = {"name": "prism band positions, beam on screen", "unit": "sigma", "pass": True,
             "stat": stats.compare_means([10.0], [10.0], [1e-6], tests=1)}
    det = judge.detectable(None, [patch, bands], alpha=0.01)
    assert det["by"] == "lambert patch_white"
    # closed form: (t* + z_0.9) standard errors of the patch, relative (normal at 500 dof, nearly)
    t_star = st.t.isf(stats.sidak_threshold(0.01, 3) / 2, 500)
    assert det["scale"] == pytest.approx((t_star + st.t.isf(0.1, 500)) * 0.001, rel=0.02)
    assert det["probes"]["prism band positions, beam on screen"] < 1e-5
    assert det["patch_de00"] > 0


def test_rough_glass_blocks_pool_more_samples_never_fewer():
    assert compare.min_samples_for("ggx_glass", 65536) == compare.min_samples_for("beckmann_glass", 65536) == 262144
    assert compare.min_samples_for("ggx_glass", 1 << 20) == 1 << 20  # a larger --min-samples wins
    assert compare.min_samples_for("ggx_copper_50", 65536) == 65536
    assert compare.block_size(256, (512, 512), compare.min_samples_for("ggx_glass")) == 32
