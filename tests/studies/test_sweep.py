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
    """The chart at scale 0.1 (62x42, the smallest scale its reference box-filters to exactly; 1/6
    of the pixels of 0.25): the RGB mode's bias is still seen far beyond noise at the top rung
    (max |z| in the hundreds), the spectral line's slope is -0.50."""
    out = tmp_path_factory.mktemp("sweep") / "out"
    proc = run_batch("-r", "mitsuba", "-s", "macbeth_chart_D65", "--scale", 0.1, "--sweep", "--ladder", "16,256,4096",
                     "--sweep-modes", "llvm_ad_spectral,llvm_ad_rgb", "--no-flip", "-o", out, timeout=1200)
    return proc, out, metrics(out)


@pytest.mark.slow
def test_sweep_flags_the_biased_mode_and_passes_the_unbiased_one(sweep_run):
    proc, out, data = sweep_run
    lines = {l["mode"]: l for l in data["sweeps"]}
    assert set(lines) == {"llvm_ad_spectral", "llvm_ad_rgb"}
    spectral, rgb = lines["llvm_ad_spectral"], lines["llvm_ad_rgb"]
    assert [p["spp"] for p in spectral["points"]] == [16, 256, 4096]
    assert spectral["converges"] is True and spectral["slope"] == pytest.approx(-0.5, abs=0.05)
    assert all(p["test"]["noise"] == "own" for p in spectral["points"])
    assert rgb["converges"] is False and "does not converge" in rgb["flag"]
    assert rgb["points"][-1]["test"]["z_max"] > 50  # the bias is seen with power to spare at this size
    # rendered as jobs on the engine, the sweep keeps the metrics.json layout readers rely on
    assert {"scene", "backend", "mode", "points", "slope", "tail_slope", "noise_floor_rmse", "own_variance",
            "error_floor_rmse", "top_ratio_to_reference_noise", "converges", "flag", "chart", "equal"} <= set(spectral)
    assert {"spp", "time_s", "wall_s", "rmse", "relmse", "mape", "predicted_rmse", "test"} <= set(spectral["points"][-1])
    assert all(p["time_s"] > 0 for l in lines.values() for p in l["points"])


def _line(mode, times, rmses):
    return {"scene": "s", "backend": "mitsuba", "mode": mode, "slope": -0.5, "converges": True, "flag": "",
            "points": [{"spp": 16 * 16 ** k, "time_s": t, "rmse": e} for k, (t, e) in enumerate(zip(times, rmses))]}


def test_equal_time_and_error_where_the_lines_overlap():
    spectral = _line("llvm_ad_spectral", [0.5, 2.0, 8.0], [0.1, 0.025, 0.00625])  # error ~ 1/time
    rgb = _line("llvm_ad_rgb", [0.2, 0.8, 3.2], [0.12, 0.05, 0.04])
    eq = sweep.equal_time_and_error([spectral, rgb])
    assert eq["time_overlap"] is True and eq["error_overlap"] is True
    assert eq["time_s"] == 3.2 and eq["rmse"] == 0.04  # the longest common time, the smallest common error
    rows = {r["mode"]: r for r in eq["rows"]}
    assert rows["llvm_ad_spectral"]["rmse_at_equal_time"] == pytest.approx(0.025 * 2.0 / 3.2)
    assert rows["llvm_ad_rgb"]["rmse_at_equal_time"] == pytest.approx(0.04)
    assert rows["llvm_ad_spectral"]["time_at_equal_error"] == pytest.approx(0.1 * 0.5 / 0.04)
    assert rows["llvm_ad_rgb"]["time_at_equal_error"] == pytest.approx(3.2)
    # ranges that only touch overlap in one point, and both lines have a value there
    touching = sweep.equal_time_and_error([_line("a", [0.1, 0.3], [0.3, 0.1]), _line("b", [0.3, 0.9], [0.1, 0.03])])
    assert [r["rmse_at_equal_time"] for r in touching["rows"]] == pytest.approx([0.1, 0.1])
    assert [r["time_at_equal_error"] for r in touching["rows"]] == pytest.approx([0.3, 0.3])


def test_a_line_that_sets_the_equal_time_has_a_value_there():
    """The common time is one line's own longest time, and the common error another's smallest:
    those lines are read at their own points. (Compared in logarithms, numpy's vectorised log and
    math.log differ in the last bit for about one value in four on an AVX-512 machine, and a
    line's own end fell outside its range: rows of None in about one sweep in six.)"""
    for x in [8.781187632286317, *np.geomspace(1.0, 20.0, 300)]:
        a = _line("a", [0.1, 0.7, x], [0.02, 0.007, 0.0035])
        b = _line("b", [0.2, 1.0, 30.0], [0.04, 0.009, 0.0024])
        eq = sweep.equal_time_and_error([a, b])
        assert eq["time_s"] == x and eq["rows"][0]["rmse_at_equal_time"] == pytest.approx(0.0035), x
        assert eq["rmse"] == 0.0035 and eq["rows"][0]["time_at_equal_error"] == pytest.approx(x), x
        assert None not in [v for r in eq["rows"] for v in r.values()], (x, eq)


def test_equal_time_says_no_overlap_when_the_render_times_do_not_meet():
    """On a loaded machine one line's renders can all take longer than the other's slowest one:
    there is no equal time (nothing is extrapolated), and the table and the summary say so."""
    from spectral_bench.batch.report import summary
    spectral = _line("llvm_ad_spectral", [4.0, 16.0, 64.0], [0.1, 0.025, 0.00625])
    rgb = _line("llvm_ad_rgb", [0.2, 0.8, 3.2], [0.12, 0.05, 0.04])
    eq = sweep.equal_time_and_error([spectral, rgb])
    assert eq["time_overlap"] is False and eq["time_s"] is None
    assert all(r["rmse_at_equal_time"] is None for r in eq["rows"])
    assert eq["time_note"].startswith("no overlap") and "4-64 s" in eq["time_note"] and "0.2-3.2 s" in eq["time_note"]
    assert eq["error_overlap"] is True and "error_note" not in eq  # equal error is still defined
    assert [r["time_at_equal_error"] for r in eq["rows"]] == pytest.approx([0.1 * 4.0 / 0.04, 3.2])
    for l in (spectral, rgb):
        l["equal"] = eq
    rows = [r for r in summary.sweeps_table([spectral, rgb]).splitlines() if r.startswith("| s |")]
    assert len(rows) == 2 and all(r.split("|")[-3].strip() == "no overlap" for r in rows), rows
    assert all(r.split("|")[-2].strip() not in ("", "no overlap") for r in rows), rows
    # and errors that do not meet (a biased line above an unbiased one)
    far = sweep.equal_time_and_error([_line("a", [1, 2], [0.5, 0.4]), _line("b", [1, 2], [0.2, 0.1])])
    assert far["error_overlap"] is False and far["rmse"] is None and far["error_note"].startswith("no overlap")
    assert all(r["time_at_equal_error"] is None for r in far["rows"])
    assert sweep.equal_time_and_error([_line("a", [1], [0.5])]) is None  # one point is no line


@pytest.mark.slow
def test_sweep_writes_charts_and_tables(sweep_run):
    """Structure of a real sweep's tables; whether its lines' measured times overlap depends on
    the machine, so the test checks the table that follows from its own points either way."""
    _, out, data = sweep_run
    assert (out / "sweeps" / "macbeth_chart_D65.png").stat().st_size > 1000
    assert "<svg" in (out / "sweeps" / "macbeth_chart_D65.svg").read_text()
    lines = data["sweeps"]
    eq = lines[0]["equal"]
    assert all(l["equal"] == eq for l in lines) and len(eq["rows"]) == 2
    text = (out / "summary.md").read_text()
    assert "## Speed against accuracy" in text and "NO: does not converge" in text
    for key, column, overlap, common in (("time_s", "rmse_at_equal_time", "time_overlap", "time_s"),
                                         ("rmse", "time_at_equal_error", "error_overlap", "rmse")):
        ranges = [(min(p[key] for p in l["points"]), max(p[key] for p in l["points"])) for l in lines]
        meet = max(r[0] for r in ranges) <= min(r[1] for r in ranges)
        assert eq[overlap] is meet, (key, ranges)
        if meet:
            assert eq[common] > 0 and all(r[column] is not None and r[column] > 0 for r in eq["rows"]), eq
        else:
            assert eq[common] is None and all(r[column] is None for r in eq["rows"]), eq
            assert "no overlap" in text
