"""Speed against accuracy: render each scene over a ladder of sample counts per backend mode,
measure wall time and error against the reference, and chart error against time (log-log).

Convergence verdict: every rung is rendered in two independent passes and judged by the noise test
against the reference on its own noise (batch/verdict/compare.py, the calibrated test of the main
run); a line converges when its top rung passes. A bias shows there first: the test's power grows
like sqrt(spp) while an unbiased method's error falls like spp^-1/2. Measured: Mitsuba's RGB mode
on the ColorChecker (spectra reduced to RGB) is flagged; the spectral mode is not.

Reported beside it, as information: each line's fit RMSE^2 = V/s + c (its own per-sample variance V
and an error floor c), the log-log slope (-0.5 for noise alone), and the noise-only prediction
from the reference's own per-sample variance (equal to the measurement for the reference's
backend; another renderer has its own variance).
"""
import math

import numpy as np


DEFAULT_LADDER = (4, 16, 64, 256)


def predicted_rmse(sigma2, var_of_mean, spp):
    return float(np.sqrt(np.mean(sigma2) / spp + np.mean(var_of_mean)))


def fit_slope(spps, errors):
    x, y = np.log(np.asarray(spps, float)), np.log(np.maximum(np.asarray(errors, float), 1e-30))
    return float(np.polyfit(x, y, 1)[0]) if len(x) > 1 else float("nan")


def fit_noise_model(spps, rmses):
    """(V, c) of RMSE^2 = V/s + c, least squares weighted by 1/RMSE^2 (relative), c >= 0."""
    x = 1.0 / np.asarray(spps, float)
    y = np.asarray(rmses, float) ** 2
    w = 1.0 / y
    a = np.stack([x * w, w], axis=1)
    v, c = np.linalg.lstsq(a, y * w, rcond=None)[0]
    if c < 0:
        v, c = float(np.sum(x * y * w * w) / np.sum(x * x * w * w)), 0.0
    return float(max(v, 0.0)), float(c)


def analyse(points, sigma2=None, var_of_mean=None):
    """The slope, the fitted noise model and the convergence verdict (the top rung's noise test,
    points[-1]["test"]) of one line's points; each point's noise-only prediction comes with it
    (batch/verdict/judge.py: sweep_point) or is computed here from the reference's variances."""
    if sigma2 is not None:
        for p in points:
            p["predicted_rmse"] = predicted_rmse(sigma2, var_of_mean, p["spp"])
            p["noise_floor_rmse"] = float(np.sqrt(np.mean(var_of_mean)))
    floor2 = float(points[-1].get("noise_floor_rmse", 0.0)) ** 2
    spps = [p["spp"] for p in points]
    top = points[-1]
    v, c = fit_noise_model(spps, [p["rmse"] for p in points]) if len(points) > 1 else (0.0, 0.0)
    excess = max(c - floor2, 0.0)
    tail = points[-2:]
    test = top.get("test") or {}
    converges = test.get("pass")
    flag = ""
    if converges is False and test.get("known"):  # differs exactly as a recorded deviation (known_deviations.toml)
        converges = True
        flag = (f"converges to the reference as its recorded deviation says ({', '.join(test['known'])}): at "
                f"{top['spp']} spp it differs plainly (max |z| {test.get('z_max', float('nan')):.1f}) and not under that model")
    elif converges is False:
        flag = (f"does not converge to the reference: at {top['spp']} spp it differs beyond noise "
                f"(max |z| {test.get('z_max', float('nan')):.1f}, p {test.get('p_min', float('nan')):.2g} "
                f"< {test.get('threshold', float('nan')):.2g}); fitted error floor {np.sqrt(excess):.3g} RMSE")
    elif converges is None:
        flag = "not judged: " + (test.get("reason") or "no noise test at the top rung")
    return {"slope": fit_slope(spps, [p["rmse"] for p in points]),
            "tail_slope": fit_slope([p["spp"] for p in tail], [p["rmse"] for p in tail]),
            "noise_floor_rmse": float(np.sqrt(floor2)), "own_variance": v, "error_floor_rmse": float(np.sqrt(excess)),
            "top_ratio_to_reference_noise": (top["rmse"] / top["predicted_rmse"]) ** 2,
            "converges": converges, "flag": flag}


def _interp_loglog(xs, ys, x):
    """y at x along the points (xs, ys), linear in log-log; None when x lies outside [min xs, max xs]
    (compared as numbers, so a range's own end is inside it)."""
    xs, ys = np.asarray(xs, float), np.asarray(ys, float)
    if not xs.min() <= x <= xs.max():
        return None
    order = np.argsort(xs)
    lx, ly = np.log(xs[order]), np.log(ys[order])
    return float(np.exp(np.interp(np.clip(math.log(x), lx[0], lx[-1]), lx, ly)))


def _common(ranges):
    """(low, high) of the interval every (low, high) range covers, or None when they do not overlap."""
    low, high = max(r[0] for r in ranges), min(r[1] for r in ranges)
    return (low, high) if low <= high else None


def _ranges_text(usable, key, unit):
    return ", ".join(f"{l['backend']} {l['mode']} {min(p[key] for p in l['points']):.3g}-"
                     f"{max(p[key] for p in l['points']):.3g}{unit}" for l in usable)


NO_OVERLAP = "no overlap"


def equal_time_and_error(lines):
    """Equal-time table (error each line reaches at the longest time every line covers) and
    equal-error table (time each line needs for the smallest error every line reaches).

    Both are read off each line's own points (log-log interpolation, never extrapolated), so they
    exist only where the lines' ranges overlap. Render times are measured, so whether the time
    ranges overlap depends on the machine (a loaded machine slows one line's renders more than
    the other's): when they do not, ``time_s`` and every ``rmse_at_equal_time`` are None, the
    table says so (``time_overlap`` False, ``time_note`` naming each line's range) and the
    summary prints "no overlap". Likewise for errors (``error_overlap``, ``error_note``).
    None when no line has two points."""
    usable = [l for l in lines if len(l["points"]) > 1]
    if len(usable) < 1:
        return None
    times = _common([(min(p["time_s"] for p in l["points"]), max(p["time_s"] for p in l["points"])) for l in usable])
    errors = _common([(min(p["rmse"] for p in l["points"]), max(p["rmse"] for p in l["points"])) for l in usable])
    t_common = times[1] if times else None
    e_common = errors[0] if errors else None
    rows = []
    for l in usable:
        ts, es = [p["time_s"] for p in l["points"]], [p["rmse"] for p in l["points"]]
        # error falls with time: interpolate along the line's own (time, error) points
        rows.append({"backend": l["backend"], "mode": l["mode"],
                     "rmse_at_equal_time": None if times is None else _interp_loglog(ts, es, t_common),
                     "time_at_equal_error": None if errors is None else _interp_loglog(es, ts, e_common)})
    table = {"time_s": t_common, "rmse": e_common, "time_overlap": times is not None,
             "error_overlap": errors is not None, "rows": rows}
    if times is None:
        table["time_note"] = f"{NO_OVERLAP}: the lines' render times do not overlap ({_ranges_text(usable, 'time_s', ' s')})"
    if errors is None:
        table["error_note"] = f"{NO_OVERLAP}: the lines' errors do not overlap ({_ranges_text(usable, 'rmse', '')})"
    return table


def chart(path_stem, scene, lines, floor=None, ylabel="RMSE against the reference"):
    """error against time, log-log, one line per backend/mode; PNG and SVG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for l in lines:
        ts = [p["time_s"] for p in l["points"]]
        es = [p["rmse"] for p in l["points"]]
        label = f"{l['backend']} {l['mode']} (slope {l['slope']:.2f}{', NOT CONVERGING' if l['converges'] is False else ''})"
        ax.loglog(ts, es, "o-", label=label)
        for p in l["points"]:
            ax.annotate(str(p["spp"]), (p["time_s"], p["rmse"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    if floor:
        ax.axhline(floor, color="grey", ls="--", lw=1, label="reference noise floor")
    ax.set_xlabel("render time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(scene)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(f"{path_stem}.png", dpi=110)
    fig.savefig(f"{path_stem}.svg")
    plt.close(fig)


def sweep_modes(backend, scene, requested=None):
    """The modes a sweep compares for one backend: the chosen one and, for Mitsuba's LLVM
    (or CUDA) variants, the scalar variant of the same kind (unless ``requested`` lists them)."""
    mode, why = backend.mode_for(scene)
    if mode is None:
        return [], why
    if backend.name in ("cycles", "luxcore"):
        return [mode], None  # an RGB backend has one mode (--sweep-modes names Mitsuba variants)
    if requested:
        return list(requested), None
    modes = [mode]
    if "_ad_" in mode and "fluorescence" not in scene.get("needs", []):
        # (fluorescent scenes render through a Python integrator, which needs a JIT variant)
        from ..backends.mitsuba.backend import scalar_twin
        modes.append(scalar_twin(mode))
    return modes, None
