"""Noise error models: the render's standard error misreported (the block z too wide or too
narrow with no bias), e.g. passes that are not independent or a variance of the samples given
for the variance of the mean."""
import numpy as np

from . import Fit, Model

FAMILY = "noise"


def _stderr_scale(ev):
    """s^2 = chi2 / N (the maximum-likelihood factor of every block's variance); -2 log L is then
    N log s^2 + N, against chi2 for the render's own variances (s = 1)."""
    if not ev.has_reference:
        return None
    chi2_none = ev.chi2_none()
    n = ev.ztest.diff.size
    s2 = chi2_none / n
    se = float(np.sqrt(s2) / np.sqrt(2 * n))  # se of s from the chi-square's variance 2N
    # no bias: the pooled scale test passes on the render's own variances, and the block test on s^2 times them
    unbiased = ev.ztest.scale is None or bool(ev.ztest.scale["pass"])
    return Fit([float(np.sqrt(s2))], [se], float(n), chi2_none, n, 1,
               unbiased and ev.passes_noise_test(ev.ref_mean, var_factor=s2), minus2logl=float(n * np.log(s2) + n))


MODELS = [
    Model("standard error misreported", FAMILY, ("factor",), "reference",
          "the differences are noise, but the render's standard error is this factor too small (or large)",
          _stderr_scale),
]
