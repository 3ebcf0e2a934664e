"""The statistics every verdict uses: two-sided p-values (normal, or Student's t where a variance
is estimated from few degrees of freedom), the Sidak correction, and the test of a region's mean
residual against its own standard error.

Pixels are independent (box filter, independent sampling: see exporters/ir.py), so the residuals
of a region's pixels (rendered minus expected) are independent draws: their mean's standard error
is their sample standard deviation over sqrt(n), with n - 1 degrees of freedom. Nothing here is a
tolerance: a probe passes when its residual is compatible with the render's own noise.
"""
import math
import os

import numpy as np
from scipy import special as _sc, stats as _st

# The family-wise false-alarm rate of one probe (its tests share it, Sidak): 0.01. The environment
# variable SPECTRAL_BENCH_PROBE_ALPHA, read once at import, sets another: the test suite sets it for
# runs of a renderer whose renders are not the same from run to run (ART, LuxCore), so that the
# suite's statistical tests together false-alarm less than once in 1000 runs (tests/conftest.py
# SUITE_ALPHA, benchmarks/TESTS.md). The runner's --alpha sets the noise test's alpha, not this.
PROBE_ALPHA_ENV = "SPECTRAL_BENCH_PROBE_ALPHA"


def _alpha_from_env(default=0.01):
    text = os.environ.get(PROBE_ALPHA_ENV, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.0 < value < 1.0:
        raise ValueError(f"{PROBE_ALPHA_ENV}={text!r}: the probes' alpha must be a number with 0 < alpha < 1")
    return value


ALPHA = _alpha_from_env()


def sidak_threshold(alpha, tests):
    """Per-test p threshold so that ``tests`` independent tests together false-alarm at ``alpha``."""
    return 1.0 - (1.0 - alpha) ** (1.0 / max(int(tests), 1))


def two_sided_p(z, dof=None):
    """P(|Z| >= |z|) for a standard normal Z, or Student's t with ``dof`` degrees of freedom."""
    z = np.abs(np.asarray(z, dtype=np.float64))
    normal = _st.norm.sf(z) * 2.0
    if dof is None:
        return normal if z.ndim else float(normal)
    dof = np.broadcast_to(np.asarray(dof, dtype=np.float64), z.shape)
    student = 2.0 * _st.t.sf(z, np.where(np.isfinite(dof) & (dof < 1e7), np.maximum(dof, 1.0), 1e7))
    out = np.where(np.isfinite(dof) & (dof < 1e7), student, normal)
    return out if z.ndim else float(out)


def one_sided_p(z, dof=None):
    """P(T >= z) for a standard normal, or Student's t with ``dof`` degrees of freedom."""
    z = np.asarray(z, dtype=np.float64)
    if dof is None:
        return _st.norm.sf(z)
    dof = np.broadcast_to(np.asarray(dof, dtype=np.float64), z.shape)
    small = np.isfinite(dof) & (dof < 1e7)
    return np.where(small, _st.t.sf(z, np.where(small, np.maximum(dof, 1.0), 1e7)), _st.norm.sf(z))


def z_critical(p_threshold):
    """|z| at which a two-sided normal test reaches ``p_threshold``."""
    return float(_st.norm.isf(p_threshold / 2.0))


def satterthwaite_dof(variances, dofs):
    """Welch-Satterthwaite degrees of freedom of a sum of independent variance estimates."""
    v = np.asarray(variances, dtype=np.float64)
    d = np.asarray(dofs, dtype=np.float64)
    num = np.sum(v, axis=0) ** 2
    den = np.sum(np.where(d > 0, v**2 / np.maximum(d, 1e-300), 0.0), axis=0)
    return np.where(den > 0, num / np.maximum(den, 1e-300), np.inf)


def region_mean_test(residuals, alpha=None, tests=1):
    """Test that a region's residuals (n pixels x c channels, rendered minus expected) average to
    zero, each channel against its own standard error with n - 1 degrees of freedom; ``tests`` is
    how many such tests (channels included) the probe makes in all, for the Sidak correction;
    ``alpha``: the family's false-alarm rate (None: ALPHA, read when called).

    Returns {z (worst channel), p, threshold, se (per channel), mean (per channel), n, pass}."""
    alpha = ALPHA if alpha is None else alpha
    r = np.asarray(residuals, dtype=np.float64)
    r = r.reshape(r.shape[0], -1)
    n = r.shape[0]
    if n < 2:
        return {"z": None, "p": None, "threshold": None, "se": None, "mean": None, "n": n, "pass": None}
    mean = r.mean(axis=0)
    se = r.std(axis=0, ddof=1) / math.sqrt(n)
    z = np.abs(mean) / np.maximum(se, 1e-300)
    p = two_sided_p(z, n - 1)
    threshold = sidak_threshold(alpha, tests)
    worst = int(np.argmax(z))
    return {"z": float(z[worst]), "p": float(np.min(p)), "threshold": threshold,
            "se": se.tolist(), "mean": mean.tolist(), "n": n, "pass": bool(np.min(p) >= threshold)}


def compare_means(measured, expected, se, dof=None, alpha=None, tests=None, judged=None):
    """Two-sided tests of measured means against expected values, each with its standard error
    (arrays of one shape; dof: degrees of freedom of each se, None for normal). ``tests`` is the
    number of tests the family makes in all (default: this many), for the Sidak correction;
    ``alpha``: the family's false-alarm rate (None: ALPHA, read when called).
    ``judged``: a boolean mask of the means that are tested (default: all); the others (too few
    samples for their standard error to mean anything: probes/bands.py ``enough_samples``) are
    kept in the arrays, never tested (p 1, z 0), and ``pass`` is None when none is tested.

    Returns a dict that also keeps the arrays, so the verdict can be re-judged against a recorded
    deviation (rejudge)."""
    alpha = ALPHA if alpha is None else alpha
    m = np.atleast_1d(np.asarray(measured, dtype=np.float64))
    e = np.atleast_1d(np.asarray(expected, dtype=np.float64))
    s = np.atleast_1d(np.asarray(se, dtype=np.float64))
    j = np.ones(m.shape, dtype=bool) if judged is None else np.broadcast_to(np.asarray(judged, dtype=bool), m.shape)
    z = np.where(j, (m - e) / np.maximum(s, 1e-300), 0.0)
    p = np.where(j, np.atleast_1d(two_sided_p(z, dof)), 1.0)
    threshold = sidak_threshold(alpha, tests or m.size)
    passed = bool(np.all(p >= threshold) and np.all(np.isfinite(m[j]))) if j.any() else None
    out = {"z": float(np.max(np.abs(z))) if z.size else 0.0, "p": float(np.min(p)) if p.size else 1.0,
           "threshold": threshold, "pass": passed,
           "measured": m.tolist(), "expected": e.tolist(), "se": s.tolist()}
    if dof is not None:
        out["dof"] = np.broadcast_to(np.asarray(dof, dtype=np.float64), m.shape).tolist()
    if judged is not None:
        out["judged"] = j.tolist()
    return out


def rejudge(stat, scale=1.0, scale_se=0.0):
    """Would a compare_means result pass if the expected values were ``scale`` times larger
    (with that factor's own standard error)? The model of a recorded deviation. Only the means it
    tested (``judged``) are tested again."""
    m, e, s = (np.asarray(stat[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    se = np.sqrt(s**2 + (scale_se * e) ** 2)
    p = np.atleast_1d(two_sided_p((m - scale * e) / np.maximum(se, 1e-300), stat.get("dof")))
    if stat.get("judged") is not None:
        p = p[np.broadcast_to(np.asarray(stat["judged"], dtype=bool), p.shape)]
    return bool(np.all(p >= stat["threshold"]))


def rejudge_interval(stat, scale=1.0, scale_se=0.0):
    """Would an interval probe's one-sided tests (probes/rough_film.py: per group, the mean
    ``measured`` against the mean ``lo`` and ``hi`` with standard error ``se``) pass if the bounds
    were ``scale`` times larger (with that factor's own standard error)? The model of a recorded
    deviation, as ``rejudge`` is for compare_means results."""
    g = stat["groups"]
    m, lo, hi, s = (np.asarray(g[k], dtype=np.float64) for k in ("measured", "lo", "hi", "se"))
    dof = np.asarray(g["dof"], dtype=np.float64)[:, None]
    z_hi = (m - scale * hi) / np.maximum(np.sqrt(s**2 + (scale_se * hi) ** 2), 1e-300)
    z_lo = (scale * lo - m) / np.maximum(np.sqrt(s**2 + (scale_se * lo) ** 2), 1e-300)
    p = np.minimum(one_sided_p(z_hi, dof), one_sided_p(z_lo, dof))
    return bool(np.all(p >= stat["threshold"]) and np.all(np.isfinite(m)))


def shifted_power(shift, threshold, dof=None):
    """Power of the two-sided test at per-test p ``threshold`` when the statistic (Student's t with
    ``dof``, normal where None or infinite) is shifted by ``shift`` standard errors:
    P(|T + shift| > t*) = 1 - F(t* - shift) + F(-t* - shift) (the location-shift approximation of
    the noncentral t; exact for the normal)."""
    shift = np.asarray(shift, dtype=np.float64)
    return power_curve(threshold, dof, shift.shape)(shift)


def power_curve(threshold, dof=None, shape=()):
    """``shifted_power`` as a function of the shift alone, for shifts of ``shape``: the critical
    values t* are computed once, and F is scipy.special's stdtr (Student's t) and ndtr (normal),
    the functions scipy.stats' t.cdf and norm.cdf evaluate (same values, without their argument
    handling: a bisection calls this some twenty times per test, issue 23)."""
    d = np.broadcast_to(np.asarray(np.inf if dof is None else dof, dtype=np.float64), shape)
    small = np.isfinite(d) & (d < 1e7)
    dd = np.where(small, np.maximum(d, 1.0), 1e7)
    q = threshold / 2.0
    if 0.0 < q < 1.0:  # scipy.stats' isf is -stdtrit(df, q) (t) and -ndtri(q) (normal) inside (0, 1)
        tcrit = np.where(small, -_sc.stdtrit(dd, q), -_sc.ndtri(q))
    else:
        tcrit = np.where(small, _st.t.isf(q, dd), _st.norm.isf(q))

    def cdf(x):
        return np.where(small, _sc.stdtr(dd, x), _sc.ndtr(x))

    def power(shift):
        return 1.0 - cdf(tcrit - shift) + cdf(-tcrit - shift)
    return power


def smallest_detectable(power_of, power=0.9, hi=1.0, rtol=1e-4):
    """The smallest eps in (0, hi] with power_of(eps) >= power (power_of grows with eps), by
    bisection to a relative width ``rtol`` (the figure is shown to three digits; the power it
    rests on is itself a location-shift approximation), returning the upper end: power_of of
    the result is >= power. None when even ``hi`` is not detected with that power. About 20
    evaluations for a figure of 1 %, instead of a fixed 50 (issue 23: each evaluates the cdf of
    every block of the image)."""
    if power_of(hi) < power:
        return None
    lo = 0.0
    for _ in range(64):  # at most 2^-64 when every eps is detected (no noise)
        if hi - lo <= rtol * hi:
            break
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if power_of(mid) >= power else (mid, hi)
    return hi


def detectable_scale(stat, power=0.9):
    """The smallest relative change eps of a compare_means family's expected values (expected x
    (1 + eps)) that its best single test detects with ``power``: a lower bound on the family's
    power, as it fails when any test does. None when not even eps = 1 would be."""
    e = np.atleast_1d(np.asarray(stat["expected"], dtype=np.float64))
    s = np.atleast_1d(np.asarray(stat["se"], dtype=np.float64))
    e, s = np.broadcast_arrays(e, s)
    dof = stat.get("dof")
    sens = np.abs(e) / np.maximum(s, 1e-300)
    if stat.get("judged") is not None:  # a mean that is not tested detects nothing
        sens = np.where(np.broadcast_to(np.asarray(stat["judged"], dtype=bool), sens.shape), sens, 0.0)
    if not sens.size or not np.isfinite(sens).any():
        return None
    curve = power_curve(stat["threshold"], dof, sens.shape)
    return smallest_detectable(lambda eps: float(np.max(curve(eps * sens))), power)
