"""LuxCoreRender backend (``-r luxcore``): the IR reduced to RGB (exporters/rgb_reduction.py),
written as LuxCore SDL (exporters/luxcore_writer.py: scene.scn, render.cfg, meshes/*.ply; every
setting is listed there) and rendered on CPU by pyluxcore 2.11.2 in a child process
(batch/backends/luxcore_worker.py), which polls the session and stops it at the time limit.

LuxCore is an RGB renderer (its wavelength sampling serves only glass dispersion, not mapped yet);
it has no Beckmann distribution and no polarisation. What a scene needs beyond that is reported
per object and field (exporters/rgb_scene.py) or, with ``--approximate``, rendered as a labelled
approximation.
"""
import importlib.util
import json
import sys
import time
from pathlib import Path

import numpy as np

from ...exporters import luxcore_writer
from .rgb_common import RgbBackend, reduction_of, run_child, write_passes

WORKER = Path(__file__).resolve().parent / "luxcore_worker.py"
GRACE_S = 30  # the worker stops itself at the time limit; it is killed this much later


class LuxCoreBackend(RgbBackend):
    name = "luxcore"
    label = "LuxCore"
    distributions = frozenset({"ggx"})

    def availability(self):
        if self.executable:
            return False, "LuxCore renders through pyluxcore; it takes no executable (-e luxcore=...)"
        if importlib.util.find_spec("pyluxcore") is None:
            return False, "pyluxcore is not installed (pip install pyluxcore==2.11.2)"
        return True, ""

    def write(self, rgb, out):
        return luxcore_writer.write(rgb, out)

    def render(self, cfg, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        result = Path(out_exr).with_suffix(".result.json")
        stack = Path(out_exr).with_suffix(".passes.npy")
        cmd = [sys.executable, str(WORKER), "--cfg", str(cfg), "--mode", mode, "--spp", str(spp),
               "--passes", str(passes), "--seed", str(seed), "--timeout", str(timeout),
               "--out", str(stack), "--result", str(result)]
        t0 = time.perf_counter()
        run_child(cmd, timeout + GRACE_S, log_path, "LuxCore render")
        info = json.loads(result.read_text())
        meta = reduction_of(cfg)
        info["channels"] = write_passes(out_exr, list(np.load(stack)), meta.get("film_scale", 1.0), meta.get("stokes", False))
        stack.unlink()
        info["approximated"] = meta.get("approximated", [])
        info["wall_s"] = time.perf_counter() - t0
        return info
