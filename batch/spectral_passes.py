"""What a spectral render leaves beside its RGB image (issue 33): its S0 bands, the mean over its
passes and the standard error of that mean, for the band checks (batch/verdict/probes/bands.py),
and a small preview for the report's wavelength slider.

- ``spectral_bands.npz``: wavelengths (nm), the band model (batch/spectral_exr.py BAND_MODELS) and
  its width, ``mean`` and ``stderr`` (H x W x N float32; no stderr from one pass) at the render's
  resolution. The verdict reads it once and removes it (``read(..., remove=True)``): a 512 x 512
  render of 94 bands is about 200 MB, which a run folder should not keep for every job.
- ``spectral_preview.exr``: the mean in the spectral OpenEXR layout of Fichet et al. 2021
  (batch/spectral_exr.py), half floats, box-filtered by an integer factor so that its longer side
  is at most PREVIEW_MAX_PX; kept.
"""
import json
import math
from pathlib import Path

import numpy as np

from . import spectral_exr

BANDS_FILE = "spectral_bands.npz"
PREVIEW_FILE = "spectral_preview.exr"
PREVIEW_MAX_PX = 256


def _box(img, f):
    if f == 1:
        return img
    h, w = img.shape[0] // f, img.shape[1] // f
    return img[:h * f, :w * f].reshape(h, f, w, f, -1).mean(axis=(1, 3))


def write(folder, meta, mean, var_of_mean=None):
    """Write the bands and the preview into ``folder``; returns the render record's ``spectral``:
    ``meta`` (wavelengths_nm, bands, band_width_nm) with the two file names."""
    folder = Path(folder)
    wl = np.asarray(meta["wavelengths_nm"], dtype=np.float64)
    arrays = {"wavelengths_nm": wl, "mean": mean.astype(np.float32),
              "meta": np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8)}
    if var_of_mean is not None:
        arrays["stderr"] = np.sqrt(var_of_mean).astype(np.float32)
    with open(folder / BANDS_FILE, "wb") as f:
        np.savez(f, **arrays)
    f = max(1, math.ceil(max(mean.shape[:2]) / PREVIEW_MAX_PX))
    preview = np.clip(_box(mean, f), -65504.0, 65504.0)
    spectral_exr.write(folder / PREVIEW_FILE, wl, preview.astype(np.float16), rgb_preview=True, dtype=np.float16)
    return dict(meta, file=BANDS_FILE, preview=PREVIEW_FILE, preview_factor=f)


def read(folder, record, remove=False):
    """(wavelengths, mean, stderr or None, meta) of a render's bands (``record``: its ``spectral``),
    or None when the file is not there; ``remove``: delete the file once read."""
    path = Path(folder) / BANDS_FILE
    if record is None or record.get("file") != BANDS_FILE or not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as z:
        wl = z["wavelengths_nm"].astype(np.float64)
        mean = z["mean"].astype(np.float64)
        stderr = z["stderr"].astype(np.float64) if "stderr" in z.files else None
        meta = json.loads(bytes(z["meta"]).decode())
    if remove:
        path.unlink(missing_ok=True)
    return wl, mean, stderr, meta
