"""HDR-FLIP (Andersson et al. 2021, flip-evaluator), run in a child process.

flip_evaluator calls sys.exit on bad arguments; a child process keeps that from ever closing
the batch runner or Blender. Inputs are checked first: finite, and negative values (out-of-gamut
linear RGB) clamped to 0, since FLIP requires non-negative input.

    python batch/verdict/flip_isolated.py reference.exr test.exr flipmap.exr   -> prints {"flip": mean}
"""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np


def prepare(img):
    img = np.asarray(img, dtype=np.float32)[..., :3]
    if not np.all(np.isfinite(img)):
        raise ValueError("image has NaN or Inf values; FLIP is not defined for it")
    return np.ascontiguousarray(np.maximum(img, 0.0))


def hdr_flip(ref_path, test_path, map_path, timeout=600):
    """Mean HDR-FLIP of test against reference, computed in a child process; map written to
    ``map_path``. Returns (mean or None, error message or None)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), str(ref_path), str(test_path), str(map_path)]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, f"FLIP timed out after {timeout} s"
    if proc.returncode != 0:
        return None, f"FLIP failed (exit {proc.returncode}): {(proc.stderr or proc.stdout).strip()[-500:]}"
    try:
        return json.loads(proc.stdout.strip().splitlines()[-1])["flip"], None
    except (ValueError, IndexError, KeyError):
        return None, f"FLIP printed no result: {proc.stdout[-300:]}"


def _main(ref_path, test_path, map_path):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch import exr
    import flip_evaluator
    ref, test = prepare(exr.read_rgb(ref_path)), prepare(exr.read_rgb(test_path))
    if ref.shape != test.shape:
        raise ValueError(f"shapes differ: {ref.shape} vs {test.shape}")
    fmap, mean, _params = flip_evaluator.evaluate(ref, test, "HDR", inputsRGB=False, applyMagma=False,
                                                  computeMeanError=True)
    fmap = np.asarray(fmap, dtype=np.float32).reshape(ref.shape[0], ref.shape[1], -1)[..., 0]
    exr.write(map_path, np.repeat(fmap[..., None], 3, axis=-1))
    print(json.dumps({"flip": float(mean)}))


if __name__ == "__main__":
    _main(*sys.argv[1:4])
