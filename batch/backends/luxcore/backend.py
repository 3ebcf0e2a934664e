"""LuxCoreRender backend (``-r luxcore``): the IR reduced to RGB (exporters/rgb_reduction.py),
written as LuxCore SDL (exporters/luxcore_writer.py: scene.scn, render.cfg, meshes/*.ply; every
setting is listed there) and rendered on CPU by pyluxcore 2.11.2 in a warm child process kept
across jobs (batch/backends/luxcore/worker.py ``serve``, batch/backends/warm.py: issue 23, one
pyluxcore import per run instead of one per pass), one pass per request; it parses each request's
scene anew, polls the session and stops it at the time limit. A worker that fails, dies or
overruns is killed and fails only its pass; the next pass or job gets a fresh one.

LuxCore is an RGB renderer (its wavelength sampling serves only glass dispersion, not mapped yet);
it has no Beckmann distribution and no polarisation. What a scene needs beyond that is reported
per object and field (exporters/rgb_scene.py) or, with ``--approximate``, rendered as a labelled
approximation.
"""
import importlib.util
import json
import os
import sys
from pathlib import Path

import numpy as np

from ....exporters import luxcore_writer
from .. import passes as passes_mod
from .. import warm
from ..rgb_common import RgbBackend, expand, reduction_of

WORKER = Path(__file__).resolve().parent / "worker.py"
GRACE_S = 30  # the worker stops itself at the time limit; it is killed this much later
SERVE = [sys.executable, str(WORKER), "serve"]


class LuxCoreBackend(RgbBackend):
    name = "luxcore"
    label = "LuxCore"
    distributions = frozenset({"ggx"})
    light_types = frozenset({"point", "spot", "directional"})
    textures = True  # an imagemap on the mesh's uvs (exporters/luxcore_writer.py)
    environment_maps = True  # an infinite light (exporters/luxcore_writer.py)

    def availability(self):
        if self.executable:
            return False, "LuxCore renders through pyluxcore; it takes no executable (-e luxcore=...)"
        if importlib.util.find_spec("pyluxcore") is None:
            return False, "pyluxcore is not installed (pip install pyluxcore==2.11.2)"
        return True, ""

    def write(self, rgb, out):
        return luxcore_writer.write(rgb, out)

    def render(self, cfg, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render in independent passes (batch/backends/passes.py); returns the render record."""
        return passes_mod.render(self, cfg, mode, spp, out_exr, passes, seed, timeout, log_path)

    def session(self, cfg, mode, log):
        """One request to the warm pyluxcore worker per pass."""
        meta = reduction_of(cfg)
        return passes_mod.OneProcessPerPass(
            lambda spp, seed, out, timeout, log: self._pass(cfg, mode, spp, seed, out, timeout, log, meta),
            log, {"approximated": meta.get("approximated", [])})

    def _pass(self, cfg, mode, spp, seed, out, timeout, log, meta):
        result = Path(out).with_suffix(".result.json")
        stack = Path(out).with_suffix(".npy")
        request = {"cfg": str(cfg), "mode": mode, "spp": spp, "passes": 1, "seed": seed, "timeout": timeout,
                   "out": str(stack), "result": str(result)}
        log.write(f"# warm LuxCore worker ({' '.join(SERVE)}): {json.dumps(request)}\n")
        log.flush()
        name = getattr(log, "name", None)
        info = warm.call("luxcore", SERVE, "LuxCore", {"render": request, "log": name if isinstance(name, str) else os.devnull},
                         timeout + GRACE_S, f"rendering {spp} spp with seed {seed}")["result"]
        names, img = expand(np.load(stack)[0], meta.get("film_scale", 1.0), meta.get("stokes", False))
        stack.unlink()
        # LuxCore stops between polls: the samples actually taken are the pass's spp (luxcore/worker.py)
        return {"names": names, "image": img, "time_s": info["time_s"], "spp": info["spp"],
                "info": {"versions": info.get("versions", {})}}
