"""What every probe shares: what it measures (a Measurement), its record, and the smallest
region it can be measured on."""
import functools
import json
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

MIN_PIXELS = 4


def remembered(size=32):
    """Decorator: keep the last ``size`` results of a function of JSON-like arguments (scene
    parts: a BSDF, a spectrum, an observer's name), keyed by their JSON text, so that scenes
    which share a material and a light (ggx_copper_50 ... 80 and their isolated twins) or one
    scene judged on several backends compute its spectral tables once per process (issue 23).
    The result's arrays are made read-only: every caller gets the same objects."""
    def wrap(fn):
        cache, lock = OrderedDict(), threading.Lock()

        @functools.wraps(fn)
        def cached(*args):
            key = json.dumps(args, sort_keys=True, default=repr)
            with lock:
                if key in cache:
                    cache.move_to_end(key)
                    return cache[key]
            value = fn(*args)
            for a in (value if isinstance(value, tuple) else (value,)):
                if isinstance(a, np.ndarray):
                    a.flags.writeable = False
            with lock:
                cache[key] = value
                while len(cache) > size:
                    cache.popitem(last=False)
            return value
        cached.cache = cache
        return cached
    return wrap


@dataclass
class Measurement:
    """One render to probe: the IR scene as rendered (resolution and spp applied), the image's
    channel names and H x W x C values, the per-pixel standard error of the image from the
    render's own independent passes (None with one pass) and their number, the scene's usable
    reference (or None), and the observers (exporters/colorimetry.py) besides the ground truth for
    which probes that integrate spectra also report their verdict (``alternatives``), so that a
    known deviation of a renderer's film can be re-judged."""
    scene: dict
    names: list
    image: np.ndarray
    stderr: np.ndarray = None
    reference: object = None
    passes: int = 1
    observers: tuple = ()
    # a spectral render's S0 bands (batch/spectral_passes.py): {"wavelengths_nm", "mean": H x W x N,
    # "stderr", "bands": the band model, "band_width_nm"}, or None (probes/bands.py)
    spectral: dict = None


def probe(name, expected, measured, error, unit, passed, **extra):
    as_list = lambda v: None if v is None else (np.asarray(v, dtype=float).round(8).tolist() if np.ndim(v) else float(v))
    out = {"name": name, "expected": as_list(expected), "measured": as_list(measured),
           "error": None if error is None else float(error), "unit": unit,
           "pass": None if passed is None else bool(passed)}
    out.update(extra)
    return out


def lerp(table, i, f):
    """table[i] + f * (table[i + 1] - table[i]) per index ``i`` (any shape) into the rows of
    ``table`` (K x C), with ``f`` of i's shape: the same numbers, bit for bit, as the fancy-indexed
    ``table[i] + f[..., None] * (table[1:] - table[:-1])[i]`` (IEEE addition and multiplication
    commute), gathered with np.take into one array computed in place: measured 4x faster on
    8192 x 256 indices (issue 45 item 1; tests/probes/test_probe_speedups.py pins it to the
    fancy-indexed form)."""
    out = np.take(table[1:] - table[:-1], i, axis=0)
    out *= f[..., None]
    out += np.take(table, i, axis=0)
    return out
