"""Cycles backend (``-r cycles``): the IR reduced to RGB (exporters/rgb_reduction.py), written as
a .blend and rendered on CPU from that .blend, one pass per request, by a warm bpy worker
(batch/backends/cycles/worker.py ``serve``: every Cycles setting and how it is verified is listed
there) kept across jobs (batch/backends/warm.py: issue 23, bpy imported once per run, not three
times per job; a worker that fails, dies or overruns is killed and fails only its pass or job).
Each request starts from a clean Blender state (a build from factory settings, a render by
opening its .blend); tests/backends/test_warm_rgb.py checks that a warm worker renders what fresh children
render. The ``build`` and ``render`` subcommands re-run one step by hand.

Cycles is an RGB renderer: it has no spectra, polarisation, fluorescence or dispersion, and its
thin film is not mapped yet; what a scene needs beyond RGB is reported per object and field
(exporters/rgb_scene.py) or, with ``--approximate``, rendered as a labelled approximation.
"""
import importlib.util
import json
import os
import sys
from pathlib import Path

from ....exporters import rgb_scene
from ... import exr
from .. import passes as passes_mod
from .. import warm
from ..rgb_common import RgbBackend, reduction_of

WORKER = Path(__file__).resolve().parent / "worker.py"
EXPORT_TIMEOUT = 600
SERVE = [sys.executable, str(WORKER), "serve"]


def ask(request, timeout, log_path, what):
    """One request to the warm Cycles worker (batch/backends/warm.py), noted in ``log_path``."""
    with open(log_path, "a", encoding="utf-8") as log:
        log.write(f"# warm Cycles worker ({' '.join(SERVE)}): {json.dumps(request)}\n")
    return warm.call("cycles", SERVE, "Cycles", dict(request, log=str(log_path)), timeout, what)["result"]


class CyclesBackend(RgbBackend):
    name = "cycles"
    label = "Cycles"
    distributions = frozenset({"ggx", "beckmann"})
    light_types = frozenset({"point", "spot", "directional"})
    environment_maps = True  # an Environment Texture node (worker.py)
    textures = True  # an Image Texture node on the mesh's UV map (worker.py)

    def availability(self):
        if self.executable:
            return False, "Cycles renders through the bpy module; it takes no executable (-e cycles=...)"
        if importlib.util.find_spec("bpy") is None:
            return False, "the bpy module is not installed (pip install bpy==5.0.1)"
        return True, ""

    def write(self, rgb, out):
        (out / "scene_rgb.json").write_text(json.dumps(rgb))
        rgb_scene.write_reduction(rgb, out)
        blend = out / "scene.blend"
        (out / "export.log").write_text("")  # this export's log; the worker appends to it
        try:
            ask({"build": {"scene": str(out / "scene_rgb.json"), "blend": str(blend)}}, EXPORT_TIMEOUT,
                out / "export.log", "the Cycles export (bpy)")
        except passes_mod.PassTimeout as exc:
            raise passes_mod.BackendFailure(f"Cycles export (bpy) timed out: {exc}") from exc
        (out / "scene_rgb.json").unlink()
        return blend

    def render(self, blend, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render in independent passes (batch/backends/passes.py); returns the render record."""
        return passes_mod.render(self, blend, mode, spp, out_exr, passes, seed, timeout, log_path)

    def session(self, blend, mode, log):
        """One request to the warm bpy worker per pass (it opens the .blend and renders one seed)."""
        return passes_mod.OneProcessPerPass(
            lambda spp, seed, out, timeout, log: self._pass(blend, mode, spp, seed, out, timeout, log),
            log, {"approximated": reduction_of(blend).get("approximated", [])})

    def _pass(self, blend, mode, spp, seed, out, timeout, log):
        result = Path(out).with_suffix(".result.json")
        log.flush()
        name = getattr(log, "name", None)
        info = ask({"render": {"blend": str(blend), "mode": mode, "spp": spp, "passes": 1, "seed": seed,
                               "out": str(out), "result": str(result)}},
                   timeout, name if isinstance(name, str) else os.devnull, f"rendering {spp} spp with seed {seed}")
        names, img = exr.read_image(out)
        return {"names": names, "image": img, "time_s": info["time_s"],
                "info": {k: info[k] for k in ("settings", "versions") if k in info}}
