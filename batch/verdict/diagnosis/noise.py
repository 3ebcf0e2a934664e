"""Noise error models: the render's standard error misreported (the block z too wide or too
narrow with no bias), e.g. passes that are not independent or a variance of the samples given
for the variance of the mean; and a too-small sample count (a render of one pass judged on the
noise the reference predicts for its declared samples per pixel, noisier than that)."""
import numpy as np

from . import NOISE_FAMILY, Fit, Model

FAMILY = NOISE_FAMILY


def _unbiased(ev):
    """No bias: the pooled scale test passes on the render's own variances."""
    return ev.ztest.scale is None or bool(ev.ztest.scale["pass"])


def _stderr_scale(ev):
    """s^2 = chi2 / N (the maximum-likelihood factor of every block's variance); -2 log L is then
    N log s^2 + N, against chi2 for the render's own variances (s = 1). Only for a render that
    reported its own noise (from its passes): one judged on the reference's prediction reported none."""
    if not ev.has_reference or ev.ztest.noise != "own":
        return None
    chi2_none = ev.chi2_none()
    n = ev.ztest.diff.size
    s2 = chi2_none / n
    se = float(np.sqrt(s2) / np.sqrt(2 * n))  # se of s from the chi-square's variance 2N
    # no bias: the pooled scale test passes on the render's own variances, and the block test on s^2 times them
    ok = _unbiased(ev) and ev.passes_noise_test(ev.ref_mean, var_factor=s2)
    return Fit([float(np.sqrt(s2))], [se], float(n), chi2_none, n, 1, ok, minus2logl=float(n * np.log(s2) + n))


def _too_few_samples(ev):
    """A render of one pass is judged on the noise the reference predicts for its declared spp
    (compare.z_test: the reference's per-sample variance over spp, plus the reference's own). If
    the renderer took fewer samples than declared, its part of each block's variance is spp /
    spp_eff times larger: the maximum-likelihood f of var_b(f) = f v_render + (var_b - v_render)
    over the blocks (-2 log L = sum log var_b(f) + d_b^2 / var_b(f), Gaussian blocks), found on a
    bounded scalar search; its standard error from the Fisher information
    I(f) = 1/2 sum (v_render / var_b(f))^2 (Cramer-Rao), carried to spp_eff = spp / f by the delta
    method. Only for renders judged on the reference's noise: where the render's own noise is
    measured (two passes or more), fewer samples show as less power, never as a failure."""
    from scipy import optimize
    if not ev.has_reference or ev.ztest.noise != "reference" or ev.ztest.var_ref is None:
        return None
    zt = ev.ztest
    d2 = zt.diff.ravel() ** 2
    var = zt.var.ravel()
    v_render = np.clip(var - zt.var_ref.ravel(), 0.0, None)
    rest = var - v_render
    if not np.any(v_render > 0):
        return None

    def m2logl(f):
        v = f * v_render + rest
        return float(np.sum(np.log(v) + d2 / v))
    r = optimize.minimize_scalar(lambda lf: m2logl(np.exp(lf)), bounds=(np.log(1e-3), np.log(1e4)), method="bounded")
    f = float(np.exp(r.x))
    v = f * v_render + rest
    info = 0.5 * float(np.sum((v_render / v) ** 2))
    se_f = 1 / np.sqrt(info) if info > 0 else np.inf
    spp = float(ev.entry.get("spp") or ev.scene["render"]["spp"])
    n = d2.size
    chi2 = float(np.sum(d2 / v))
    # the block and scale tests again on the variances the fit gives (the scale test on the
    # render's under-stated variance fails too: it is re-judged, not required)
    ok = ev.passes_noise_test(ev.ref_mean, var=v.reshape(zt.var.shape))
    return Fit([spp / f], [spp * se_f / f ** 2], chi2, ev.chi2_none(), n, 1, ok,
               note=f"declared {spp:g} spp", minus2logl=m2logl(f) - m2logl(1.0) + ev.chi2_none())


MODELS = [
    Model("standard error misreported", FAMILY, ("factor",), "reference",
          "the differences are noise, but the render's standard error is this factor too small (or large)",
          _stderr_scale),
    Model("too few samples", FAMILY, ("effective spp",), "reference",
          "the differences are noise, but more of it than the declared samples per pixel give: the renderer "
          "took fewer samples (a sample count lost on the way, or samples that are not independent)",
          _too_few_samples),
]
