"""The statistics every verdict uses: two-sided p-values (normal, or Student's t where a variance
is estimated from few degrees of freedom), the Sidak correction, and the test of a region's mean
residual against its own standard error.

Pixels are independent (box filter, independent sampling: see exporters/ir.py), so the residuals
of a region's pixels (rendered minus expected) are independent draws: their mean's standard error
is their sample standard deviation over sqrt(n), with n - 1 degrees of freedom. Nothing here is a
tolerance: a probe passes when its residual is compatible with the render's own noise.
"""
import math

import numpy as np
from scipy import stats as _st

ALPHA = 0.01  # family-wise false-alarm rate of one probe: its tests share it (Sidak)


def sidak_threshold(alpha, tests):
    """Per-test p threshold so that ``tests`` independent tests together false-alarm at ``alpha``."""
    return 1.0 - (1.0 - alpha) ** (1.0 / max(int(tests), 1))


def two_sided_p(z, dof=None):
    """P(|Z| >= |z|) for a standard normal Z, or Student's t with ``dof`` degrees of freedom."""
    z = np.abs(np.asarray(z, dtype=np.float64))
    if dof is None or np.all(np.asarray(dof) > 1e6):
        return np.vectorize(lambda x: math.erfc(x / math.sqrt(2)))(z) if z.ndim else math.erfc(float(z) / math.sqrt(2))
    return 2.0 * _st.t.sf(z, np.asarray(dof, dtype=np.float64))


def satterthwaite_dof(variances, dofs):
    """Welch-Satterthwaite degrees of freedom of a sum of independent variance estimates."""
    v = np.asarray(variances, dtype=np.float64)
    d = np.asarray(dofs, dtype=np.float64)
    num = np.sum(v, axis=0) ** 2
    den = np.sum(np.where(d > 0, v**2 / np.maximum(d, 1e-300), 0.0), axis=0)
    return np.where(den > 0, num / np.maximum(den, 1e-300), np.inf)


def region_mean_test(residuals, alpha=ALPHA, tests=1):
    """Test that a region's residuals (n pixels x c channels, rendered minus expected) average to
    zero, each channel against its own standard error with n - 1 degrees of freedom; ``tests`` is
    how many such tests (channels included) the probe makes in all, for the Sidak correction.

    Returns {z (worst channel), p, threshold, se (per channel), mean (per channel), n, pass}."""
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
