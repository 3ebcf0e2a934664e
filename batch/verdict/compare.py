"""Comparison of a render with a reference, judged against noise: the render's own and the
reference's.

Both images use a box pixel filter and independent sampling (the IR's convention), so pixels
are independent and a reference of H x W downsamples exactly to h x w whenever H/h = fy and
W/w = fx are integers (the two factors may differ: 620x420 at 1/5 x 1/5 is 124x84, at 1/10 x
1/10 62x42): a big pixel is the mean of its fy x fx small ones, the variance of that mean the
sum of theirs over (fy fx)^2.

The reference stores its mean and the standard error of that mean per pixel (from P_ref
independent passes). The render brings its own per-pixel standard error when it was rendered in
two or more independent passes: every backend is judged on its own noise. Only a render by the
reference's own backend and mode may instead borrow the reference's per-sample variance
sigma^2 = stderr^2 * N_ref, scaled to its sample count (the same estimator has the same variance);
a render of another backend without passes is not judged by this test.

The verdict is a two-sided test per block of test pixels and channel, with a Sidak correction over
all blocks (the approach of Mitsuba 3's src/render/tests/test_renders.py). The blocks tile the
whole image: each axis is cut into floor(n / b) nearly equal runs of b to 2b - 1 pixels, so every
pixel is tested. A block's variance is the sum of its pixels' variance estimates; where those come
from few passes, the statistic is Student's t with Welch-Satterthwaite degrees of freedom
(batch/verdict/stats.py), not a normal z.

Why blocks, and how big: path-traced pixel estimates are heavy-tailed (a rare caustic path,
such as floor -> copper plate -> light, puts one bright sample into a dark pixel), so the mean
of a few thousand samples is far from Gaussian in the 5-sigma tail that a Sidak correction over
~10^4 tests looks at. Measured on ggx_copper_50 at 512x512, 64 spp: 4x4 blocks (1024 samples)
gave |z| = 8.9 for an unbiased render. The block is therefore sized so that each one pools at
least MIN_SAMPLES samples (a firefly's z shrinks like 1/sqrt(samples per block)); measured false
alarms per block size are in benchmarks/CALIBRATION.md.

The scale test: the block test with Sidak over thousands of blocks is weak against an error spread
over the whole image (a light 1 % too bright moves every block by 1 % of its mean, far below a
Sidak threshold of |z| ~ 4.5). So the noise test is two tests at a Bonferroni split of alpha
(ALPHA_SPLIT: alpha/2 each, so together they false-alarm at most at alpha): the block test, and per
channel the weighted estimate of a uniform scale s of the render against the reference,
s_hat - 1 = sum_b w_b D_b / sum_b w_b M_b (D_b: block difference, M_b: the reference's block mean,
w_b = M_b / V_b with V_b the block's variance as the reference predicts it, sigma^2 / spp plus the
reference's own: weights independent of the render's noise, so they cannot bias it), and
z = sum_b w_b D_b / sqrt(sum_b w_b^2 Vhat_b) with Vhat_b the block variance the block test uses
(the render's own noise), Student's t with Welch-Satterthwaite degrees of freedom over blocks
(Satterthwaite 1946), Sidak over channels. Inverse-variance weighting of independent block means
is the minimum-variance linear estimate (Gauss-Markov); the statistic is self-normalising, so one
heavy-tailed sample moves numerator and variance together and cannot make it large on its own
(measured on the rough glass spheres: benchmarks/CALIBRATION.md).

Power (``detectable``): the smallest relative uniform scale error eps detected with 90 % power.
A planted eps shifts block b's z by eps M_b / sqrt(V_b) and channel c's scale z by
eps sqrt(sum_b w_b M_b)^2 / sum_b w_b^2 V_b (closed form). The power of each channel's scale test
is P(|T + delta| > t*) with T Student's t, and of its block test 1 - prod_b P(|T_b + delta_b| < t*_b)
(independent blocks); the detection probability of the whole noise test is at least the largest
of these (it fails when any one fails), so eps solved for 90 % on the best channel and test (by
bisection: power grows with eps) is an upper bound on what 90 % power needs; exact when one
test dominates and channels are fully correlated (as a path tracer's R, G, B are).
"""
from dataclasses import dataclass, field

import numpy as np

from ..previews import REL_EPS  # noqa: F401 - the regulariser of the relative metrics, shared with the previews
from . import stats

MIN_SAMPLES = 65536  # samples pooled per block of the noise test (see above)
# Scenes whose noise test pools more samples per block than --min-samples asks (never fewer): the
# rough glass spheres' caustic paths are so skewed at 65536 samples per block that a block missing
# them has its mean and its variance estimate both low, and the block test false-alarmed in 3 of 40
# full-resolution renders of ggx_glass (worst block's z negative in 33 of 40); at 262144 samples
# (32 px blocks at their 256 spp) in 0 of 40 (benchmarks/CALIBRATION.md, issue 20).
SCENE_MIN_SAMPLES = {"ggx_glass": 262144, "beckmann_glass": 262144}
ALPHA_SPLIT = {"block": 0.5, "scale": 0.5}  # Bonferroni shares of alpha of the noise test's two tests
POWER = 0.9  # the power at which ``detectable`` is stated


def min_samples_for(scene_name, requested=MIN_SAMPLES):
    """Samples per block of the noise test for ``scene_name``: ``requested`` (--min-samples), or
    the scene's own larger figure (SCENE_MIN_SAMPLES)."""
    return max(int(requested or MIN_SAMPLES), SCENE_MIN_SAMPLES.get(scene_name, 0))


def block_size(spp, shape, min_samples=MIN_SAMPLES):
    """Smallest power-of-two block side b with b^2 * spp >= min_samples, within the image."""
    b = 1
    while b * b * spp < min_samples and b * 2 <= min(shape[0], shape[1]):
        b *= 2
    return b


def block_edges(n, b):
    """Cut [0, n) into max(1, n // b) runs of nearly equal length (b to 2b - 1 pixels): every
    pixel belongs to exactly one block."""
    k = max(1, n // max(b, 1))
    return np.linspace(0, n, k + 1).round().astype(int)


def block_sums(img, edges_y, edges_x):
    """Sums of ``img`` (H x W x C) over the blocks given by their edges."""
    s = np.add.reduceat(img, edges_y[:-1], axis=0)
    return np.add.reduceat(s, edges_x[:-1], axis=1)


def expand_blocks(values, edges_y, edges_x):
    """Per-block values (h x w x C) back to a per-pixel map."""
    return np.repeat(np.repeat(values, np.diff(edges_y), axis=0), np.diff(edges_x), axis=1)


def downsample(img, f, fx=None):
    """Box filter of an H x W x C image by integer factors ``f`` (rows) and ``fx`` (columns,
    default ``f``): each output pixel is the mean of an f x fx tile (float64)."""
    fy, fx = int(f), int(f if fx is None else fx)
    if fy == 1 and fx == 1:
        return img
    h, w = img.shape[0] // fy, img.shape[1] // fx
    # one axis at a time, in float64: 2-5x faster than a mean over both axes of the 5-D view
    tiles = img[:h * fy, :w * fx].reshape(h, fy, w, fx, -1)
    return tiles.sum(axis=1, dtype=np.float64).sum(axis=2) / (fy * fx)


def factors(ref_shape, shape):
    """(fy, fx): the integer factors by which a reference of ``ref_shape`` (H, W, ...) box-filters
    to ``shape`` (h, w, ...), or None when either axis does not divide."""
    (H, W), (h, w) = ref_shape[:2], shape[:2]
    if h <= 0 or w <= 0 or H % h or W % w:
        return None
    return H // h, W // w


@dataclass
class ReferenceAt:
    """The reference at the test resolution: mean, variance of that mean, per-sample variance,
    and the degrees of freedom of each pixel's variance estimate."""
    mean: np.ndarray
    var_of_mean: np.ndarray
    sigma2: np.ndarray
    dof: float
    # {observer: (difference, its variance)}: the reference as that observer's film would have seen
    # it, minus the reference (batch/verdict/observer_layers.py), at this resolution; scalars 0.0
    # for the reference's own observer
    offsets: dict = field(default_factory=dict)

    def channels(self, sl):
        return ReferenceAt(self.mean[..., sl], self.var_of_mean[..., sl], self.sigma2[..., sl], self.dof,
                           {k: tuple(x if np.isscalar(x) else x[..., sl] for x in v) for k, v in self.offsets.items()})


def reference_at(ref_mean, ref_stderr, ref_spp, shape, ref_passes=8, offsets=None):
    """The reference box-filtered to the test resolution: integer factors fy = H/h and fx = W/w
    of its own (independent per axis; n = fy fx small pixels per big one). ``offsets``: its
    observer layers ({observer: (difference, variance)}, observer_layers.offsets), carried along."""
    H, W = ref_mean.shape[:2]
    h, w = shape[:2]
    f = factors(ref_mean.shape, shape)
    if f is None:
        raise ValueError(f"test resolution {w}x{h} is not the reference's {W}x{H} divided by an integer in each axis")
    fy, fx = f
    n = fy * fx
    var_mean = ref_stderr.astype(np.float64) ** 2
    mean = downsample(ref_mean.astype(np.float64), fy, fx)
    var_of_mean = downsample(var_mean, fy, fx) / n
    sigma2 = downsample(var_mean * ref_spp, fy, fx)
    if n > 1:
        # the radiance varies inside a big pixel: that variation is sampling variance too.
        # Its estimate from the noisy small-pixel means is biased up by (1 - 1/n) * E[stderr^2].
        spread = downsample(ref_mean.astype(np.float64) ** 2, fy, fx) - mean ** 2
        spread -= (1 - 1 / n) * downsample(var_mean, fy, fx)
        sigma2 += np.maximum(spread, 0.0)
    at_offsets = {k: (d if np.isscalar(d) else downsample(d, fy, fx), v if np.isscalar(v) else downsample(v, fy, fx) / n)
                  for k, (d, v) in (offsets or {}).items()}
    return ReferenceAt(mean, var_of_mean, sigma2, float(n * max(ref_passes - 1, 1)), at_offsets)


def metrics(test, ref):
    d = test.astype(np.float64) - ref
    return {
        "rmse": float(np.sqrt(np.mean(d**2))),
        "relmse": float(np.mean(d**2 / (ref**2 + REL_EPS))),
        "mape": float(np.mean(np.abs(d) / (np.abs(ref) + REL_EPS))),
    }


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
    noise: str = "own"
    dof_min: float = float("inf")
    zmap: np.ndarray = field(repr=False, default=None)
    semap: np.ndarray = field(repr=False, default=None)  # per pixel: its block difference's standard error (z's divisor)
    # per block and channel, kept to re-judge against a recorded deviation (batch/verdict/known.py)
    diff: np.ndarray = field(repr=False, default=None)
    ref_block_mean: np.ndarray = field(repr=False, default=None)
    var: np.ndarray = field(repr=False, default=None)
    dof: np.ndarray = field(repr=False, default=None)
    # the scale test (module docstring): per-block weights, its threshold and result
    weight: np.ndarray = field(repr=False, default=None)
    var_model: np.ndarray = field(repr=False, default=None)  # the block variance the reference predicts (the weights' V_b)
    var_ref: np.ndarray = field(repr=False, default=None)    # the reference's own share of ``var``
    scale: dict = None
    block_passed: bool = True
    finite: bool = True
    # {observer: (block mean of the difference, its variance)} (ReferenceAt.offsets per block)
    offsets: dict = field(repr=False, default_factory=dict)

    def as_dict(self):
        out = {"name": "block test, Sidak-corrected",
               "alpha": self.alpha, "block": self.block,
               "samples_per_block": self.samples_per_block, "noise": self.noise,
               "tests": self.blocks, "p_min": self.p_min, "threshold": self.threshold,
               "z_max": self.z_max, "dof_min": self.dof_min if np.isfinite(self.dof_min) else None,
               "fraction_abs_z_over_3": self.frac_over_3, "block_pass": self.block_passed, "pass": self.passed}
        if self.scale is not None:
            out["scale_test"] = dict(self.scale)
        return out

    def _judge(self, d, var, ref_block_mean=None):
        """(block test passed, scale test record) for block differences ``d`` with variances ``var``."""
        p = stats.two_sided_p(d / np.sqrt(var), self.dof) if d.size else np.ones(0)
        block_ok = bool(np.min(p) >= self.threshold) if p.size else True
        m = self.ref_block_mean if ref_block_mean is None else ref_block_mean
        return block_ok, (scale_stats(d, var, self.dof, self.weight, m, self.alpha)
                          if self.weight is not None else None)

    def rejudge(self, scale, scale_se=0.0, observer=None):
        """Would the render pass if the reference were ``scale`` (+- scale_se) times brighter, seen
        by ``observer``'s film (the reference plus that observer's layer, whose own variance joins
        the test's)? None when the reference has no layer for ``observer``: cannot tell."""
        off, var_off = 0.0, 0.0
        if observer is not None:
            if observer not in self.offsets:
                return None
            off, var_off = self.offsets[observer]
        m = self.ref_block_mean + off
        d = self.diff - off - (scale - 1.0) * m
        block_ok, sc = self._judge(d, self.var + var_off + (scale_se * m) ** 2, m)
        return block_ok and (sc is None or sc["pass"])

    def detectable(self, power=POWER):
        """The smallest relative uniform scale error detected with ``power`` (module docstring),
        or None when not even a 100 % error would be: {"scale", "alpha", "power", "method", "by":
        which test, "tests": each test's own figure}. Closed-form power per channel and test,
        bisection on eps (batch/verdict/stats.py smallest_detectable)."""
        if self.diff is None or not self.diff.size:
            return None
        c = self.diff.shape[-1]
        shift = (self.ref_block_mean / np.sqrt(self.var)).reshape(-1, c)
        dof = np.broadcast_to(np.asarray(self.dof, dtype=np.float64), self.diff.shape).reshape(-1, c)

        block_curve = stats.power_curve(self.threshold, dof, shift.shape)  # critical values once per bisection

        def block_power(eps):
            miss = np.clip(1.0 - block_curve(eps * shift), 1e-300, 1.0)
            return float(np.max(1.0 - np.exp(np.sum(np.log(miss), axis=0))))
        tests = {"block test": block_power}
        if self.scale is not None:
            sens = np.asarray([x or 0.0 for x in self.scale["sensitivity"]], dtype=np.float64)
            sdof = np.asarray([np.inf if x is None else x for x in self.scale["dof"]], dtype=np.float64)
            scale_curve = stats.power_curve(self.scale["threshold"], sdof, sens.shape)
            tests["scale test"] = lambda eps: float(np.max(scale_curve(eps * sens)))
        found = {k: e for k, fn in tests.items() if (e := stats.smallest_detectable(fn, power)) is not None}
        if not found:
            return None
        by = min(found, key=found.get)
        return {"scale": float(found[by]), "alpha": self.alpha, "power": power, "by": by,
                "method": ("closed form: the noise test's block and scale tests at their shares of alpha, Student t "
                           "shifted by a planted uniform scale error, best channel and test (a lower bound on the power)"),
                "tests": {k: float(v) for k, v in found.items()}}


def scale_stats(d, var, dof, weight, ref_block_mean, alpha):
    """The scale test (module docstring) per channel from block differences ``d``, their variances
    ``var`` and degrees of freedom ``dof``, fixed ``weight``s and the reference's block means: a
    record {s, se, z, dof, p_min, threshold, sensitivity, z_max, pass}."""
    c = d.shape[-1]
    w = weight.reshape(-1, c)
    dd, vv, mm = d.reshape(-1, c), var.reshape(-1, c), ref_block_mean.reshape(-1, c)
    df = np.broadcast_to(np.asarray(dof, dtype=np.float64), d.shape).reshape(-1, c)
    num = np.sum(w * dd, axis=0)
    wv = w**2 * vv
    den2 = np.sum(wv, axis=0)
    wm = np.sum(w * mm, axis=0)
    usable = (den2 > 0) & (np.abs(wm) > 0)
    z = np.where(usable, num / np.sqrt(np.where(usable, den2, 1.0)), 0.0)
    tdof = stats.satterthwaite_dof(wv, df)
    p = np.where(usable, stats.two_sided_p(z, tdof), 1.0)
    threshold = stats.sidak_threshold(alpha * ALPHA_SPLIT["scale"], int(usable.sum()) or 1)
    se = np.where(usable, np.sqrt(den2) / np.where(usable, np.abs(wm), 1.0), np.inf)
    s_hat = np.where(usable, 1.0 + num / np.where(usable, wm, 1.0), np.nan)
    sens = np.where(usable, np.abs(wm) / np.sqrt(np.where(usable, den2, 1.0)), 0.0)
    clean = lambda a: [float(x) if np.isfinite(x) else None for x in np.asarray(a, dtype=np.float64)]  # noqa: E731
    return {"name": "scale test, Sidak over channels", "s": clean(s_hat), "se": clean(se), "z": clean(z),
            "dof": clean(tdof), "p_min": float(np.min(p)), "threshold": threshold, "sensitivity": clean(sens),
            "z_max": float(np.max(np.abs(z))), "pass": bool(np.min(p) >= threshold)}


def z_test(test, ref, spp, own_var_of_mean=None, own_passes=None, alpha=0.01, block=None,
           min_samples=MIN_SAMPLES, scale_test=True):
    """Block test of ``test`` (spp samples per pixel) against ``ref`` (a ReferenceAt at the same
    resolution). ``own_var_of_mean``: the render's per-pixel variance of its mean from
    ``own_passes`` independent passes (its own noise); without it the reference's per-sample
    variance over spp is used (only valid for the reference's own backend and mode: the caller
    decides). A variance floor (1e-4 of the image's mean level, squared) only keeps blocks where
    both images are exactly black from dividing zero by zero: visible light where the reference
    and its noise are exactly zero fails. ``scale_test``: also the scale test (module docstring),
    the two at a Bonferroni split of ``alpha``; without it the block test alone at ``alpha``."""
    block = block or block_size(spp, test.shape, min_samples)
    block = max(1, min(block, test.shape[0], test.shape[1]))
    ey, ex = block_edges(test.shape[0], block), block_edges(test.shape[1], block)
    n = block_sums(np.ones(test.shape[:2] + (1,)), ey, ex)
    finite = np.isfinite(test)
    d = block_sums(np.where(finite, test.astype(np.float64), 0.0) - ref.mean, ey, ex) / n
    ref_block_mean = block_sums(ref.mean, ey, ex) / n
    v_ref = block_sums(ref.var_of_mean, ey, ex) / n**2
    # per-block Satterthwaite over pixels: (sum v)^2 / sum(v^2 / dof)
    dof_ref = block_sums(ref.var_of_mean, ey, ex) ** 2 / np.maximum(block_sums(ref.var_of_mean**2, ey, ex) / ref.dof, 1e-300)
    if own_var_of_mean is not None:
        own = np.where(np.isfinite(own_var_of_mean), own_var_of_mean, 0.0).astype(np.float64)
        own_dof = max(int(own_passes or 2) - 1, 1)
        v_own = block_sums(own, ey, ex) / n**2
        dof_own = block_sums(own, ey, ex) ** 2 / np.maximum(block_sums(own**2, ey, ex) / own_dof, 1e-300)
        noise = "own"
    else:
        v_own = block_sums(ref.sigma2, ey, ex) / spp / n**2
        dof_own = dof_ref
        noise = "reference"
    floor = (1e-4 * max(float(np.mean(np.abs(ref.mean))), 1e-12)) ** 2
    var = v_own + v_ref + floor
    dof = stats.satterthwaite_dof(np.stack([v_own, v_ref]), np.stack([dof_own, dof_ref]))
    z = d / np.sqrt(var)
    p = stats.two_sided_p(z, dof) if z.size else np.ones(0)
    m = z.size
    block_alpha = alpha * (ALPHA_SPLIT["block"] if scale_test else 1.0)
    threshold = stats.sidak_threshold(block_alpha, m)
    p_min = float(np.min(p)) if m else 1.0
    zmap = expand_blocks(z, ey, ex)
    weight = scale = v_model = None
    if scale_test:
        # weights from the reference alone (its per-sample variance over spp, plus its own noise)
        v_model = block_sums(ref.sigma2, ey, ex) / max(spp, 1) / n**2 + v_ref + floor
        weight = ref_block_mean / v_model
        scale = scale_stats(d, var, dof, weight, ref_block_mean, alpha)
    all_finite = bool(np.all(finite))
    block_ok = bool(p_min >= threshold)
    offsets = {k: (dd if np.isscalar(dd) else block_sums(dd, ey, ex) / n, vv if np.isscalar(vv) else block_sums(vv, ey, ex) / n**2)
               for k, (dd, vv) in ref.offsets.items()}
    return ZTest(alpha=alpha, block=block, blocks=m, p_min=p_min, threshold=threshold,
                 z_max=float(np.abs(z).max()), frac_over_3=float(np.mean(np.abs(z) > 3)),
                 passed=bool(block_ok and (scale is None or scale["pass"]) and all_finite), zmap=zmap,
                 semap=expand_blocks(np.sqrt(var), ey, ex),
                 samples_per_block=int(block * block * spp), noise=noise, dof_min=float(np.min(dof)),
                 diff=d, ref_block_mean=ref_block_mean, var=var, dof=dof, weight=weight, var_model=v_model,
                 var_ref=v_ref, scale=scale,
                 block_passed=block_ok, finite=all_finite, offsets=offsets)


def image_sanity(img):
    """Counts of NaN, Inf and negative values (negative RGB can be legitimate out-of-gamut
    colour; NaN and Inf never are)."""
    return {"nan": int(np.isnan(img).sum()), "inf": int(np.isinf(img).sum()),
            "negative": int((img < 0).sum())}
