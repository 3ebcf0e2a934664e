"""Speed against accuracy: the sweep's ladder, charts, tables and its convergence flag, which
must pass an unbiased method and flag a biased one (Mitsuba's RGB mode on the ColorChecker,
whose reflectance spectra it reduces to RGB)."""
import numpy as np
import pytest

from conftest import metrics, run_batch
from spectral_bench.batch.studies import sweep


def test_prediction_and_slope_arithmetic():
    sigma2, var = np.full((4, 4, 3), 2.0), np.full((4, 4, 3), 0.0)
    assert sweep.predicted_rmse(sigma2, var, 8) == pytest.approx(0.5)
    pts = [{"spp": s, "rmse": 1 / np.sqrt(s)} for s in (4, 16, 64)]
    assert sweep.fit_slope([p["spp"] for p in pts], [p["rmse"] for p in pts]) == pytest.approx(-0.5)
    # the fit reports the error floor; the verdict is the top rung's noise test
    biased = [{"spp": s, "rmse": np.sqrt(2.0 / s + 0.05 ** 2)} for s in (4, 64, 1024)]
    biased[-1]["test"] = {"pass": False, "z_max": 9.0, "p_min": 1e-12, "threshold": 1e-4}
    verdict = sweep.analyse(biased, sigma2, var)
    assert verdict["converges"] is False and verdict["error_floor_rmse"] == pytest.approx(0.05, rel=0.05)
    unbiased = [{"spp": s, "rmse": np.sqrt(2.0 / s)} for s in (4, 64, 1024)]
    unbiased[-1]["test"] = {"pass": True}
    assert sweep.analyse(unbiased, sigma2, var)["converges"] is True
    unbiased[-1].pop("test")
    assert sweep.analyse(unbiased, sigma2, var)["converges"] is None  # not judged is not converged
    assert sweep.fit_noise_model([4, 64, 1024], [np.sqrt(2.0 / s + 0.01) for s in (4, 64, 1024)]) == pytest.approx((2.0, 0.01), rel=1e-6)


@pytest.fixture(scope="module")
def sweep_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "out"
    proc = run_batch("-r", "mitsuba", "-s", "macbeth_chart_D65", "--scale", 0.25, "--sweep", "--ladder", "16,256,4096",
                     "--sweep-modes", "llvm_ad_spectral,llvm_ad_rgb", "--no-flip", "-o", out, timeout=1200)
    return proc, out, metrics(out)


def test_sweep_flags_the_biased_mode_and_passes_the_unbiased_one(sweep_run):
    proc, out, data = sweep_run
    lines = {l["mode"]: l for l in data["sweeps"]}
    assert set(lines) == {"llvm_ad_spectral", "llvm_ad_rgb"}
    spectral, rgb = lines["llvm_ad_spectral"], lines["llvm_ad_rgb"]
    assert [p["spp"] for p in spectral["points"]] == [16, 256, 4096]
    assert spectral["converges"] is True and spectral["slope"] == pytest.approx(-0.5, abs=0.05)
    assert all(p["test"]["noise"] == "own" for p in spectral["points"])
    assert rgb["converges"] is False and "does not converge" in rgb["flag"]
    # rendered as jobs on the engine, the sweep keeps the metrics.json layout readers rely on
    assert {"scene", "backend", "mode", "points", "slope", "tail_slope", "noise_floor_rmse", "own_variance",
            "error_floor_rmse", "top_ratio_to_reference_noise", "converges", "flag", "chart", "equal"} <= set(spectral)
    assert {"spp", "time_s", "wall_s", "rmse", "relmse", "mape", "predicted_rmse", "test"} <= set(spectral["points"][-1])
    assert all(p["time_s"] > 0 for l in lines.values() for p in l["points"])


def test_sweep_writes_charts_and_tables(sweep_run):
    _, out, data = sweep_run
    assert (out / "sweeps" / "macbeth_chart_D65.png").stat().st_size > 1000
    assert "<svg" in (out / "sweeps" / "macbeth_chart_D65.svg").read_text()
    eq = data["sweeps"][0]["equal"]
    assert eq["time_s"] > 0 and len(eq["rows"]) == 2
    assert all(r["rmse_at_equal_time"] is not None for r in eq["rows"])
    text = (out / "summary.md").read_text()
    assert "## Speed against accuracy" in text and "NO: does not converge" in text
