"""EXR files through the OpenEXR package: float32 RGB(A) images and named extra channels.

Every reader here checks the file's header before any pixel is read (``check_header``): an EXR
from outside (a baseline's render, a reference, a declared renderer's output, compare_runs'
inputs) can claim a data window of any size whose pixels compress to almost nothing (a
decompression bomb: 20000 x 20000 of a constant is a few MB on disk and 9.5 GB in memory). The
header is parsed here from its first MAX_HEADER_BYTES, without the OpenEXR library, and refused
(EXRLimitError, naming the file and the field) when the data window exceeds the job's expected
resolution (where the caller knows it) or the caps below, when it has more than MAX_CHANNELS
channels, subsampled channels or a pixel type other than UINT/HALF/FLOAT, or when it is a
multi-part or deep file (nothing this project reads writes those).
"""
import struct
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
    return _write_file(path, head, channels)


def _write_file(path, head, channels):
    """Write through OpenEXR; its RuntimeError for a failed write (a full disk: "No space left on
    device") becomes an OSError naming the file, as any other write error."""
    try:
        with OpenEXR.File(head, channels) as f:
            f.write(str(path))
    except RuntimeError as exc:
        raise OSError(f"{path}: cannot be written: {exc}") from exc
    return path


NO_COMPRESSION = OpenEXR.NO_COMPRESSION


def replace_file(path, write):
    """Make ``path`` by ``write(temporary path)`` in the same folder, then renaming it over the name
    with the umask's permissions: a reader (or another job writing the same file) never sees half a
    file, and a link planted at ``path`` (a run folder from someone else) is replaced, never
    written through. Returns ``path``."""
    import os
    import tempfile
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=path.suffix)
    os.close(fd)
    try:
        write(tmp)
        umask = os.umask(0o022)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return path


def write_channels(path, channels, compression=OpenEXR.ZIP_COMPRESSION):
    """Write {channel name: HxW array} as they are (float32 unless float16), e.g. a renderer's raw
    film channels or a pass that is read back at once (``NO_COMPRESSION``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {n: np.ascontiguousarray(a if a.dtype == np.float16 else a.astype(np.float32)) for n, a in channels.items()}
    return _write_file(path, {"compression": compression, "type": OpenEXR.scanlineimage}, data)


# -- the header, checked before any pixel is read ------------------------------------------------------
MAX_SIDE = 16384              # px per side of the data window (a 16K render)
MAX_PIXELS = 1 << 26          # 67 Mpx (8192 x 8192)
MAX_CHANNELS = 1024           # a polarised spectral image at 4 x 128 wavelengths with its noise channels
MAX_DECODED_BYTES = 2 << 30   # width x height x channels x 4 (the float32 arrays the readers return)
MAX_HEADER_BYTES = 1 << 20    # the header itself
PIXEL_TYPES = {0: "UINT", 1: "HALF", 2: "FLOAT"}
_MAGIC = 20000630
_TILED, _LONG_NAMES, _NON_IMAGE, _MULTIPART = 0x200, 0x400, 0x800, 0x1000


class EXRLimitError(ValueError):
    """An EXR refused from its header; the message names the file and the field."""


def _cstring(buf, pos, path, what):
    end = buf.find(b"\0", pos)
    if end < 0:
        raise EXRLimitError(f"{path}: header: {what} runs past the first {MAX_HEADER_BYTES} bytes (truncated or not an EXR)")
    return buf[pos:end].decode("latin-1"), end + 1


def _chlist(value, path):
    channels, pos = [], 0
    while pos < len(value) and value[pos] != 0:
        name, pos = _cstring(value, pos, path, "a channel name")
        if pos + 16 > len(value):
            raise EXRLimitError(f"{path}: header: channels: the entry of {name!r} is truncated")
        ptype, _linear, xs, ys = struct.unpack_from("<iB3xii", value, pos)
        pos += 16
        channels.append((name, ptype, xs, ys))
        if len(channels) > MAX_CHANNELS:
            raise EXRLimitError(f"{path}: header: channels: more than {MAX_CHANNELS} (the cap of batch/exr.py)")
    return channels


def header_info(path):
    """{"width", "height", "channels": [(name, pixel type, xSampling, ySampling)], "tiled"} from the
    header of the EXR at ``path``, parsed from its first MAX_HEADER_BYTES (no pixel is read).
    Raises EXRLimitError for what is not a single-part, flat OpenEXR image, naming the field."""
    with open(path, "rb") as f:
        buf = f.read(MAX_HEADER_BYTES)
    if len(buf) < 8 or struct.unpack_from("<i", buf, 0)[0] != _MAGIC:
        raise EXRLimitError(f"{path}: not a readable OpenEXR file (no magic number)")
    flags = struct.unpack_from("<I", buf, 4)[0]
    if flags & _MULTIPART or flags & _NON_IMAGE:
        raise EXRLimitError(f"{path}: header: version flags: a {'multi-part' if flags & _MULTIPART else 'deep'} "
                            "file (this reader takes single-part flat images)")
    pos, attrs = 8, {}
    while True:
        if pos >= len(buf):
            raise EXRLimitError(f"{path}: header: longer than {MAX_HEADER_BYTES} bytes or truncated")
        if buf[pos] == 0:
            break
        name, pos = _cstring(buf, pos, path, "an attribute name")
        kind, pos = _cstring(buf, pos, path, f"the type of attribute {name!r}")
        if pos + 4 > len(buf):
            raise EXRLimitError(f"{path}: header: attribute {name!r} is truncated")
        size = struct.unpack_from("<i", buf, pos)[0]
        pos += 4
        if size < 0 or pos + size > len(buf):
            raise EXRLimitError(f"{path}: header: attribute {name!r}: size {size} runs past the header "
                                f"(truncated, or more than {MAX_HEADER_BYTES} bytes)")
        attrs[name] = (kind, buf[pos:pos + size])
        pos += size
    for needed, kind in (("channels", "chlist"), ("dataWindow", "box2i")):
        if attrs.get(needed, (None,))[0] != kind:
            raise EXRLimitError(f"{path}: header: no {needed} attribute of type {kind}")
    if len(attrs["dataWindow"][1]) != 16:
        raise EXRLimitError(f"{path}: header: dataWindow: {len(attrs['dataWindow'][1])} bytes, a box2i has 16")
    x0, y0, x1, y1 = struct.unpack("<iiii", attrs["dataWindow"][1])
    return {"width": x1 - x0 + 1, "height": y1 - y0 + 1, "channels": _chlist(attrs["channels"][1], path),
            "tiled": bool(flags & _TILED)}


def _expected(expect):
    """(width, height) from ``expect`` when it is two positive ints, else None."""
    if isinstance(expect, (list, tuple)) and len(expect) == 2 and all(
            isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in expect):
        return int(expect[0]), int(expect[1])
    return None


def check_header(path, expect=None, max_channels=MAX_CHANNELS):
    """``header_info`` of ``path`` if its pixels are safe to read: a data window of ``expect``
    (width, height) where the caller knows the job's resolution, else within MAX_SIDE per side,
    MAX_PIXELS and MAX_DECODED_BYTES; at most ``max_channels`` full-resolution channels of UINT,
    HALF or FLOAT. Raises EXRLimitError naming the file and the field."""
    info = header_info(path)
    w, h, channels = info["width"], info["height"], info["channels"]
    want = _expected(expect)
    if w < 1 or h < 1:
        raise EXRLimitError(f"{path}: header: dataWindow: {w}x{h} is empty or inverted")
    if want is not None and (w, h) != want:
        raise EXRLimitError(f"{path}: header: dataWindow: {w}x{h}, expected {want[0]}x{want[1]} (the resolution the job or record gives)")
    if w > MAX_SIDE or h > MAX_SIDE or w * h > MAX_PIXELS:
        raise EXRLimitError(f"{path}: header: dataWindow: {w}x{h} exceeds the cap of batch/exr.py ({MAX_SIDE} px "
                            f"per side, {MAX_PIXELS} pixels)")
    if not channels:
        raise EXRLimitError(f"{path}: header: channels: none")
    if len(channels) > max_channels:
        raise EXRLimitError(f"{path}: header: channels: {len(channels)}, more than {max_channels}")
    for name, ptype, xs, ys in channels:
        if ptype not in PIXEL_TYPES:
            raise EXRLimitError(f"{path}: header: channel {name!r}: pixel type {ptype} is not UINT, HALF or FLOAT")
        if (xs, ys) != (1, 1):
            raise EXRLimitError(f"{path}: header: channel {name!r}: subsampled {xs}x{ys} (full resolution expected)")
    if w * h * len(channels) * 4 > MAX_DECODED_BYTES:
        raise EXRLimitError(f"{path}: header: {w}x{h} x {len(channels)} channels: more than "
                            f"{MAX_DECODED_BYTES >> 20} MiB as float32 (the cap of batch/exr.py)")
    return info


def read(path, expect=None):
    """{channel name: HxW float32 array}; an RGB(A) group is split into R, G, B(, A). The header is
    checked first (``check_header``, with the expected (width, height) where known)."""
    check_header(path, expect)
    out = {}
    with OpenEXR.File(str(path), separate_channels=True) as f:
        for name, ch in f.channels().items():
            out[name] = np.asarray(ch.pixels, dtype=np.float32)
    return out


def read_rgb(path, prefix="", expect=None):
    """HxWx3 float32 from channels <prefix>R, G, B (also Mitsuba's 'RGB' group names); a grey
    image of one channel <prefix>Y (the FLIP map) as three equal channels."""
    ch = read(path, expect)
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


def read_image(path, skip_prefix="stderr.", expect=None):
    """(channel names, HxWxC float32) of every channel except those starting ``skip_prefix``."""
    names, img, _ = read_image_and_stderr(path, expect)
    return names, img


def read_image_and_stderr(path, expect=None):
    """(names, HxWxC image, HxWxC standard error or None) from one read: the stderr.<name>
    channels that independent passes write beside the mean."""
    ch = read(path, expect)
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


def stored_render(mean, stderr, seed, step_se=None):
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
    binary16, the mean stays float32 (and the standard error float32 or None). ``step_se``: the
    standard error that sets the step instead of ``stderr`` (an observer layer is rounded below the
    noise of the reference it corrects, not below its own, much smaller one: batch/verdict/
    observer_layers.py); the rounding variance still joins ``stderr``."""
    mean = np.asarray(mean, dtype=np.float64)
    if stderr is None:
        return mean.astype(np.float32), None
    se = np.asarray(stderr, dtype=np.float64)
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(se))):
        return mean.astype(np.float32), se.astype(np.float32)
    step = half_ulp(mean)
    ss = se if step_se is None else np.broadcast_to(np.asarray(step_se, dtype=np.float64), se.shape)
    coarse = 2.0 ** np.floor(np.log2(np.where(ss > 0, ss / NOISE_STEPS, 1.0)))
    step = np.where(ss > 0, np.maximum(step, coarse), step)
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
