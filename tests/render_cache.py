"""A disk memo of the test renderers' own renders (issue 45: no two tests rendering the same thing).

The declared test renderers (tests/plant_renderer.py, tests/toy_cached.py around the example
renderer) plant their errors on the output of one Mitsuba render: the planted renderers of one
batch render the same scene with the same seeds (pass k: seed + k * 1000, whatever the renderer),
so their base renders are the same image, bit for bit (Mitsuba is deterministic for a seed:
benchmarks/TESTS.md, "Determinism, measured"). With ``SPECTRAL_BENCH_TEST_RENDER_CACHE=DIR`` in
the environment (a test sets it for its own runs), a base render is kept in DIR under a key of
everything it depends on: the scene file's bytes and those of every file in its folder (spectra,
meshes, plugins, camera filter; hidden files, the runner's own, left out), and the caller's
``parts`` (format, film, samples per pixel, seed, variant kind). A second renderer asking for the
same key reads it back instead of rendering (and so never imports Mitsuba). Unset: every call
renders, as a user's run does.

Arrays are stored as float32 where that is exact (Mitsuba's film is float32: the renders are)
and read back as the float64 the renderer returned, so a cached render is the same array.
"""
import hashlib
import os
import pickle
from pathlib import Path

import numpy as np

ENV = "SPECTRAL_BENCH_TEST_RENDER_CACHE"


def key(scene_xml, parts):
    """A hex digest of the scene file, the files of its folder and ``parts``."""
    scene_xml = Path(scene_xml)
    folder = scene_xml.resolve().parent
    h = hashlib.sha256(scene_xml.read_bytes())
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if p.is_file() and not any(part.startswith(".") for part in rel.parts):
            h.update(str(rel).encode() + b"\0" + p.read_bytes() + b"\0")
    h.update(repr(tuple(parts)).encode())
    return h.hexdigest()[:40]


def _pack(x):
    if isinstance(x, np.ndarray) and x.dtype == np.float64:
        small = x.astype(np.float32)
        if np.array_equal(small, x, equal_nan=True):
            return ("f32", small)
        return ("f64", x)
    if isinstance(x, (tuple, list)):
        return (type(x).__name__, [_pack(v) for v in x])
    return ("raw", x)


def _unpack(x):
    kind, value = x
    if kind == "f32":
        return value.astype(np.float64)
    if kind in ("tuple", "list"):
        items = [_unpack(v) for v in value]
        return tuple(items) if kind == "tuple" else items
    return value


def memo(render, scene_xml, *parts):
    """``render()``, or what it returned for the same key before (with the cache switched on)."""
    folder = os.environ.get(ENV)
    if not folder:
        return render()
    path = Path(folder) / f"{key(scene_xml, parts)}.pickle"
    if path.is_file():
        with path.open("rb") as f:
            return _unpack(pickle.load(f))
    result = render()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}")
    with tmp.open("wb") as f:
        pickle.dump(_pack(result), f, protocol=5)
    os.replace(tmp, path)  # whole or not at all: a reader never sees half a file
    return result
