"""EXR files through the OpenEXR package: float32 RGB(A) images and named extra channels."""
from pathlib import Path

import numpy as np
import OpenEXR


def write(path, rgb, extra=None, header=None):
    """Write an HxWx3 image as R,G,B (float32, or HALF for a float16 image) plus ``extra``
    {channel name: HxW array} (kept in its dtype: float16 arrays are stored as HALF). ZIP
    compression."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rgb = np.asarray(rgb)
    channels = {"RGB": np.ascontiguousarray(rgb[..., :3], dtype=np.float16 if rgb.dtype == np.float16 else np.float32)}
    for name, arr in (extra or {}).items():
        channels[name] = np.ascontiguousarray(arr)
    head = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    head.update(header or {})
    with OpenEXR.File(head, channels) as f:
        f.write(str(path))
    return path


NO_COMPRESSION = OpenEXR.NO_COMPRESSION


def write_channels(path, channels, compression=OpenEXR.ZIP_COMPRESSION):
    """Write {channel name: HxW array} as they are (float32 unless float16), e.g. a renderer's raw
    film channels or a pass that is read back at once (``NO_COMPRESSION``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {n: np.ascontiguousarray(a if a.dtype == np.float16 else a.astype(np.float32)) for n, a in channels.items()}
    with OpenEXR.File({"compression": compression, "type": OpenEXR.scanlineimage}, data) as f:
        f.write(str(path))
    return path


def read(path):
    """{channel name: HxW float32 array}; an RGB(A) group is split into R, G, B(, A)."""
    out = {}
    with OpenEXR.File(str(path), separate_channels=True) as f:
        for name, ch in f.channels().items():
            out[name] = np.asarray(ch.pixels, dtype=np.float32)
    return out


def read_rgb(path, prefix=""):
    """HxWx3 float32 from channels <prefix>R, G, B (also Mitsuba's 'RGB' group names); a grey
    image of one channel <prefix>Y (the FLIP map) as three equal channels."""
    ch = read(path)
    if prefix + "R" not in ch and prefix + "Y" in ch:
        return np.repeat(ch[prefix + "Y"][..., None], 3, axis=-1)
    try:
        return np.stack([ch[prefix + c] for c in "RGB"], axis=-1)
    except KeyError as exc:
        raise ValueError(f"{path}: no channels {prefix}R,G,B (has {sorted(ch)})") from exc


def _order(names):
    """R, G, B first, then the rest by prefix and colour (S0.R, S0.G, S0.B, S1.R, ...)."""
    head = [c for c in ("R", "G", "B", "Y") if c in names]
    rank = {"R": 0, "G": 1, "B": 2}

    def key(n):
        prefix, _, colour = n.rpartition(".")
        return (prefix, rank.get(colour, 3), colour) if prefix else (n, 0, "")
    return head + sorted((n for n in names if n not in head), key=key)


def read_image(path, skip_prefix="stderr."):
    """(channel names, HxWxC float32) of every channel except those starting ``skip_prefix``."""
    names, img, _ = read_image_and_stderr(path)
    return names, img


def read_image_and_stderr(path):
    """(names, HxWxC image, HxWxC standard error or None) from one read: the stderr.<name>
    channels that independent passes write beside the mean."""
    ch = read(path)
    names = _order([n for n in ch if not n.startswith("stderr.")])
    img = np.stack([ch[n] for n in names], axis=-1)
    if not all(f"stderr.{n}" in ch for n in names):
        return names, img, None
    return names, img, np.stack([ch[f"stderr.{n}"] for n in names], axis=-1)


def write_image(path, names, img, extra=None):
    """Write channels ``names`` of an HxWxC image (R, G, B as the RGB group; float32, or HALF for a
    float16 image) plus ``extra``."""
    rgb = np.stack([img[..., names.index(c)] for c in "RGB"], axis=-1)
    dtype = np.float16 if np.asarray(img).dtype == np.float16 else np.float32
    rest = {n: np.ascontiguousarray(img[..., i], dtype=dtype) for i, n in enumerate(names) if n not in "RGB"}
    rest.update(extra or {})
    return write(path, rgb, rest)


# -- how a render's mean and standard error are stored (issue 21: a run folder of reasonable size) ----
HALF_MAX = 65504.0       # largest finite IEEE 754 binary16
SE_BITS = 4              # mantissa bits kept of the standard error's halves (5 significant), rounded up
NOISE_STEPS = 4          # the mean's rounding step is at most its standard error / NOISE_STEPS


def half_ulp(x):
    """The spacing of IEEE 754 binary16 numbers at ``x`` (2^-24 in the subnormal range)."""
    a = np.abs(np.asarray(x, dtype=np.float64))
    e = np.floor(np.log2(np.where(a > 0, a, 1.0)))
    return np.where(a > 0, 2.0 ** (np.maximum(e, -14) - 10), 2.0 ** -24)


def round_up_bits(values, keep=SE_BITS):
    """Non-negative ``values`` as binary16 rounded *up* to ``keep`` mantissa bits: never smaller
    than the value (a standard error stored this way never makes a test less conservative).
    Subnormal halves (below 2^-14) keep all their bits: there the spacing is already absolute."""
    v = np.asarray(values, dtype=np.float64)
    h = v.astype(np.float16)
    h = np.where(h.astype(np.float64) < v, np.nextafter(h, np.float16(np.inf)), h).astype(np.float16)
    drop = 10 - keep
    u = h.view(np.uint16).astype(np.uint32)
    rounded = ((u + (1 << drop) - 1) >> drop) << drop
    return np.where(u >= 0x0400, rounded, u).astype(np.uint16).view(np.float16)


def stored_render(mean, stderr, seed):
    """(mean, standard error) of a render as render.exr stores them: binary16 where they fit.

    The mean is rounded *stochastically* (to the neighbour above with probability equal to the
    distance from the one below, in units of the step), which is unbiased, E[stored] = mean, with a
    rounding variance (x - lo)(hi - x) known exactly per pixel (M. Croci et al., "Stochastic
    rounding: implementation, error analysis and applications", R. Soc. Open Sci. 9, 211631,
    2022); that variance is added to the pixel's squared standard error, so every reader that
    judges the stored file (the verdict, --baseline, compare_runs, a promoted reference) sees an
    unbiased mean with its whole uncertainty: round-to-nearest would leave a bias of up to half a
    step where a region has no variance (a light seen directly), which fails the noise test. The step is the binary16 spacing, or the power of two at most 1/NOISE_STEPS of
    the pixel's standard error where that is larger (noise-aware quantisation with q = 4: W. D.
    Pence, R. L. White, R. Seaman, "Optimal compression of floating-point astronomical images
    without significant loss of information", PASP 122:1065, 2010): the bits below the noise
    carry nothing and do not compress; the standard error grows by at most sqrt(1 + 1/64) - 1 =
    0.8 %. The standard error is then rounded up to SE_BITS + 1 significant bits (at most 1/16
    larger, about 3 % on average: conservative; the detectable figures of the default run grew
    by about 2.5 %, no verdict changed: benchmarks/RUN_FOLDER.md). Random numbers from ``seed``, so a run is reproducible.

    Without a standard error (one pass), with values that are not finite, or that do not fit in
    binary16, the mean stays float32 (and the standard error float32 or None)."""
    mean = np.asarray(mean, dtype=np.float64)
    if stderr is None:
        return mean.astype(np.float32), None
    se = np.asarray(stderr, dtype=np.float64)
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(se))):
        return mean.astype(np.float32), se.astype(np.float32)
    step = half_ulp(mean)
    coarse = 2.0 ** np.floor(np.log2(np.where(se > 0, se / NOISE_STEPS, 1.0)))
    step = np.where(se > 0, np.maximum(step, coarse), step)
    lo = np.floor(mean / step) * step
    hi = lo + step
    if float(np.max(np.abs(hi), initial=0.0)) >= HALF_MAX or float(np.max(np.abs(lo), initial=0.0)) >= HALF_MAX \
            or float(np.max(se, initial=0.0)) >= HALF_MAX / 2:
        return mean.astype(np.float32), se.astype(np.float32)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x21])
    up = rng.random(mean.shape) * step < (mean - lo)
    stored = np.where(up, hi, lo).astype(np.float16)
    variance = se ** 2 + (mean - lo) * (hi - mean)
    return stored, round_up_bits(np.sqrt(variance))


def noise_rounded(values, stderr):
    """``values`` rounded to the nearest multiple of the binary16 spacing, or of the power of two at
    most 1/NOISE_STEPS of the value's standard error where that is larger, as float64 (then exact
    in binary16): a copy for the eye (the run's shared reference) carries no bits below its noise,
    which do not compress (Pence et al. 2010, as ``stored_render``); each value moves by at most
    1/8 of its standard error."""
    v = np.asarray(values, dtype=np.float64)
    se = np.asarray(stderr, dtype=np.float64)
    step = half_ulp(v)
    ok = np.isfinite(se) & (se > 0)
    step = np.where(ok, np.maximum(step, 2.0 ** np.floor(np.log2(np.where(ok, se / NOISE_STEPS, 1.0)))), step)
    return np.where(np.isfinite(v), np.round(v / step) * step, v)
