"""The images a verdict leaves beside a render, kept small: the report (batch/report/html.py)
draws every view from floats, so no 8-bit previews are written for it, and what only a reader
looks at is stored as half floats (11 significant bits: 4.9e-4 relative rounding, far below the
noise of any render judged here):

- ``zscore.exr``: the noise test's z per block and colour channel (half);
- ``block_stderr.exr`` (``BLOCK_STDERR``): the standard error of each block's difference that z
  divides by (the render's noise, the reference's, and the floor: batch/verdict/compare.py
  ``z_test``), per block and colour channel (half): what the page shows under the cursor as the
  standard error (a pixel's own, from a few passes, is itself too noisy to read; it stays in
  render.exr);
- ``flip.exr``: the HDR-FLIP map (one channel Y, half, 5 significant bits: ``FLIP_BITS``);
- ``probe_residual.exr``: for a scene with a GGX/Beckmann plate probe, what that probe's
  residual map needs (half, NaN off the plates: batch/verdict/probes/ggx.py ``residual_map``):
  ``expected.R/G/B`` per plate pixel (the residual is render.exr minus these; the page and tev
  users subtract) and ``z.R/G/B``, the z of the pixel's block in the probe's test;
- ``<scene>/results/reference_<W>x<H>.exr``: the scene's reference at the render's resolution,
  once per scene and resolution, shared by every backend of the scene (half, or float32 where a
  value does not fit in half; no bits below a quarter of its standard error);
- differences are not stored: the page computes them from the render and the reference, and
  the Blender panel writes ``diff_abs.exr`` / ``diff_rel.exr`` when its buttons are pressed
  (``differences``).

PNG writers stay for charts and strips that are pictures (stability)."""
import contextlib
from pathlib import Path

import numpy as np
from PIL import Image

from . import exr

REL_EPS = 0.01  # regulariser of the relative metrics (as in Mitsuba's and Blender's tests); batch/verdict/compare.py uses it

HALF_MAX = 65504.0  # largest finite IEEE 754 binary16


def srgb_encode(x):
    """IEC 61966-2-1 sRGB transfer function of linear values clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def save_linear(path, img, exposure=1.0):
    Image.fromarray((srgb_encode(img[..., :3] * exposure) * 255 + 0.5).astype(np.uint8)).save(path)


def save_signed(path, values, scale):
    """Diverging map: blue negative, red positive, white zero; |value| = scale is saturated."""
    v = np.clip(np.asarray(values, dtype=np.float64) / max(scale, 1e-30), -1, 1)
    rgb = np.stack([1 - np.maximum(-v, 0), 1 - np.abs(v), 1 - np.maximum(v, 0)], axis=-1)
    Image.fromarray((rgb * 255 + 0.5).astype(np.uint8)).save(path)


def save_gray(path, values, scale=1.0):
    v = np.clip(np.asarray(values, dtype=np.float64) / max(scale, 1e-30), 0, 1)
    Image.fromarray((v * 255 + 0.5).astype(np.uint8)).save(path)


def fits_half(values):
    values = np.asarray(values)
    return bool(np.all(np.isfinite(values)) and float(np.max(np.abs(values), initial=0.0)) < HALF_MAX)


def write_half(path, rgb, channels="RGB"):
    """An HxWx3 image as R, G, B half floats (float32 if a value would not fit), written to a
    temporary name and renamed: a reader, or another job writing the same file, never sees half
    a file. ``channels="Y"``: an HxW (or HxWx1) grey image as one channel Y (tev and Blender show
    it grey; batch/exr.py ``read_rgb`` reads it as three equal channels)."""
    rgb = np.asarray(rgb)
    if channels == "Y" and rgb.ndim == 2:
        rgb = rgb[..., None]
    dtype = np.float16 if fits_half(rgb) else np.float32
    return _replace(path, {c: rgb[..., i].astype(dtype) for i, c in enumerate(channels)})


def _replace(path, channels):
    """Write {channel: HxW array} to ``path`` through a temporary name and a rename (a reader, or
    another job writing the same file, never sees half a file); the umask's permissions."""
    return exr.replace_file(path, lambda tmp: exr.write_channels(tmp, channels))


PROBE_RESIDUAL = "probe_residual.exr"
PROBE_RESIDUAL_CHANNELS = ("expected.R", "expected.G", "expected.B", "z.R", "z.G", "z.B")


def write_probe_residual(res_dir, maps):
    """``res_dir``/probe_residual.exr from the probes' residual maps ({record name: H x W x 6},
    NaN off each probe's region; the regions of a scene's plates do not overlap) as half floats
    (NaN kept, finite values clipped to the largest half); a file left from an earlier verdict
    is removed when no probe hands a map over. Returns the path or None."""
    path = Path(res_dir) / PROBE_RESIDUAL
    if not maps:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        return None
    merged = None
    for values in maps.values():
        values = np.asarray(values, dtype=np.float32)
        merged = values.copy() if merged is None else np.where(np.isnan(merged), values, merged)
    merged = np.where(np.isfinite(merged), np.clip(merged, -HALF_MAX, HALF_MAX), merged)
    return _replace(path, {c: merged[..., i].astype(np.float16) for i, c in enumerate(PROBE_RESIDUAL_CHANNELS)})


def shared_reference_name(shape):
    return f"reference_{int(shape[1])}x{int(shape[0])}.exr"


def shared_reference(res_dir, mean, stderr=None):
    """Write the reference at the render's resolution once per scene: ``res_dir`` is
    <scene>/results/<backend>; returns the file's path (<scene>/results/reference_WxH.exr).
    With its ``stderr``, no bits below a quarter of it are kept (batch/exr.py ``noise_rounded``:
    a copy for the eye, the verdict reads the reference itself)."""
    path = Path(res_dir).parent / shared_reference_name(np.shape(mean))
    rgb = mean[..., :3] if stderr is None else exr.noise_rounded(mean[..., :3], stderr[..., :3])
    return write_half(path, rgb)


BLOCK_STDERR = "block_stderr.exr"
FLIP_BITS = 4  # mantissa bits kept of the FLIP map's halves (5 significant: 1.6 % at most)


def write_flip(path, fmap, keep_bits=FLIP_BITS):
    """The FLIP map (HxW) as one half-float channel Y, rounded to the nearest value with
    ``keep_bits`` mantissa bits: FLIP is a perceptual index in [0, 1] read to two digits, and the
    bits below carry nothing (its mean, the metric, is taken before)."""
    grey = np.asarray(fmap, dtype=np.float32)
    if keep_bits < 10 and fits_half(grey):
        drop = 10 - keep_bits
        u = grey.astype(np.float16).view(np.uint16).astype(np.uint32)
        grey = (((u + (1 << (drop - 1))) >> drop) << drop).astype(np.uint16).view(np.float16)
    return write_half(path, grey, channels="Y")



def differences(render, reference):
    """(|render - reference|, |render - reference| / (|reference| + REL_EPS)) of the RGB channels:
    what the Blender panel's difference buttons show, computed when asked for."""
    d = np.abs(render[..., :3].astype(np.float64) - reference[..., :3])
    return d, d / (np.abs(reference[..., :3]) + REL_EPS)
