"""Comparison of a render with a reference, judged against the reference's noise.

Both images use a box pixel filter and independent sampling (the IR's convention), so pixels
are independent and a reference of H x W downsamples exactly to h x w when H/h = W/w is an
integer: a big pixel is the mean of its f x f small ones.

The reference stores its mean and the standard error of that mean per pixel (from
independent passes). Its per-sample variance sigma^2 = stderr^2 * N_ref predicts the variance
of a render at s spp. The verdict is a two-sided Z-test per block of b x b test pixels and
channel, with a Sidak correction over all blocks (the approach of Mitsuba 3's
src/render/tests/test_renders.py). It assumes the render's per-sample variance is the
reference's, which holds for the same backend and is approximate across renderers.

Why blocks, and how big: path-traced pixel estimates are heavy-tailed (a rare caustic path,
such as floor -> copper plate -> light, puts one bright sample into a dark pixel), so the mean
of a few thousand samples is far from Gaussian in the 5-sigma tail that a Sidak correction over
~10^4 tests looks at. Measured on ggx_copper_50 at 512x512, 64 spp: 4x4 blocks (1024 samples)
gave |z| = 8.9 for an unbiased render. The block is therefore sized so that each one pools at
least MIN_SAMPLES samples (a firefly's z shrinks like 1/sqrt(samples per block)); measured false
alarms per block size are in benchmarks/CALIBRATION.md (16384 still gave 2 of 20 at 512x512).
"""
import math
from dataclasses import dataclass, field

import numpy as np

REL_EPS = 0.01  # regulariser of the relative metrics (as in Mitsuba's and Blender's tests)
MIN_SAMPLES = 65536  # samples pooled per block of the noise test (see above)


def block_size(spp, shape, min_samples=MIN_SAMPLES):
    """Smallest power-of-two block side b with b^2 * spp >= min_samples, within the image."""
    b = 1
    while b * b * spp < min_samples and b * 2 <= min(shape[0], shape[1]):
        b *= 2
    return b


def downsample(img, f):
    if f == 1:
        return img
    h, w = img.shape[0] // f, img.shape[1] // f
    return img[:h * f, :w * f].reshape(h, f, w, f, -1).mean(axis=(1, 3))


def reference_at(ref_mean, ref_stderr, ref_spp, shape):
    """Reference mean, variance of that mean, and per-sample variance at the test resolution."""
    H, W = ref_mean.shape[:2]
    h, w = shape[:2]
    if H % h or W % w or H // h != W // w:
        raise ValueError(f"test resolution {w}x{h} is not the reference's {W}x{H} divided by an integer")
    f = H // h
    var_mean = ref_stderr.astype(np.float64) ** 2
    mean = downsample(ref_mean.astype(np.float64), f)
    var_of_mean = downsample(var_mean, f) / (f * f)
    sigma2 = downsample(var_mean * ref_spp, f)
    if f > 1:
        # the radiance varies inside a big pixel: that variation is sampling variance too.
        # Its estimate from the noisy small-pixel means is biased up by (1 - 1/f^2) * E[stderr^2].
        spread = downsample(ref_mean.astype(np.float64) ** 2, f) - mean ** 2
        spread -= (1 - 1 / f**2) * downsample(var_mean, f)
        sigma2 += np.maximum(spread, 0.0)
    return mean, var_of_mean, sigma2


def metrics(test, ref):
    d = test.astype(np.float64) - ref
    return {
        "rmse": float(np.sqrt(np.mean(d**2))),
        "relmse": float(np.mean(d**2 / (ref**2 + REL_EPS))),
        "mape": float(np.mean(np.abs(d) / (np.abs(ref) + REL_EPS))),
    }


def _block_sum(img, b):
    h, w = img.shape[0] // b * b, img.shape[1] // b * b
    return img[:h, :w].reshape(h // b, b, w // b, b, -1).sum(axis=(1, 3))


@dataclass
class ZTest:
    alpha: float
    block: int
    blocks: int
    p_min: float
    threshold: float
    z_max: float
    frac_over_3: float
    passed: bool
    samples_per_block: int = 0
    zmap: np.ndarray = field(repr=False, default=None)

    def as_dict(self):
        return {"name": "block Z-test, Sidak-corrected", "alpha": self.alpha, "block": self.block,
                "samples_per_block": self.samples_per_block,
                "tests": self.blocks, "p_min": self.p_min, "threshold": self.threshold,
                "z_max": self.z_max, "fraction_abs_z_over_3": self.frac_over_3, "pass": self.passed}


def z_test(test, ref_mean, ref_var_of_mean, sigma2, spp, alpha=0.01, block=None, min_samples=MIN_SAMPLES,
           test_var_of_mean=None):
    """Block Z-test of ``test`` (s = spp samples per pixel) against the reference at the same
    resolution; ``block`` None sizes blocks by ``min_samples``. The render's variance is the
    reference's per-sample variance over s, unless the render brings its own (per-pixel variance
    of its mean from independent passes: another renderer's noise is its own). A variance floor
    (1e-4 of the image's mean level, squared) keeps exactly black regions from dividing by zero:
    any visible light where the reference has none fails."""
    block = block or block_size(spp, test.shape, min_samples)
    block = max(1, min(block, test.shape[0], test.shape[1]))
    n = block * block
    d = _block_sum(test.astype(np.float64) - ref_mean, block) / n
    own = _block_sum(test_var_of_mean, block) if test_var_of_mean is not None else _block_sum(sigma2, block) / spp
    var = (own + _block_sum(ref_var_of_mean, block)) / n**2
    floor = (1e-4 * max(float(np.mean(np.abs(ref_mean))), 1e-12)) ** 2
    z = d / np.sqrt(var + floor)
    p = np.vectorize(lambda x: math.erfc(abs(x) / math.sqrt(2)))(z) if z.size else np.ones(0)
    m = z.size
    threshold = 1 - (1 - alpha) ** (1 / m)
    p_min = float(p.min())
    return ZTest(alpha=alpha, block=block, blocks=m, p_min=p_min, threshold=threshold,
                 z_max=float(np.abs(z).max()), frac_over_3=float(np.mean(np.abs(z) > 3)),
                 passed=bool(p_min >= threshold and np.all(np.isfinite(test))), zmap=z,
                 samples_per_block=int(n * spp))


def image_sanity(img):
    """Counts of NaN, Inf and negative values (negative RGB can be legitimate out-of-gamut
    colour; NaN and Inf never are)."""
    return {"nan": int(np.isnan(img).sum()), "inf": int(np.isinf(img).sum()),
            "negative": int((img < 0).sum())}
