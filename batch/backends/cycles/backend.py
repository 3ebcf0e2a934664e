"""Cycles backend (``-r cycles``): the IR reduced to RGB (exporters/rgb_reduction.py), written as
a .blend by a child bpy process, rendered on CPU by another child that opens that .blend
(batch/backends/cycles/worker.py: every Cycles setting and how it is verified is listed there).

Cycles is an RGB renderer: it has no spectra, polarisation, fluorescence or dispersion, and its
thin film is not mapped yet; what a scene needs beyond RGB is reported per object and field
(exporters/rgb_scene.py) or, with ``--approximate``, rendered as a labelled approximation.
"""
import importlib.util
import json
import sys
from pathlib import Path

from ....exporters import rgb_scene
from ... import exr
from .. import passes as passes_mod
from ..rgb_common import RgbBackend, reduction_of, run_child

WORKER = Path(__file__).resolve().parent / "worker.py"
EXPORT_TIMEOUT = 600


class CyclesBackend(RgbBackend):
    name = "cycles"
    label = "Cycles"
    distributions = frozenset({"ggx", "beckmann"})

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
        run_child([sys.executable, str(WORKER), "build", "--scene", str(out / "scene_rgb.json"), "--blend", str(blend)],
                  EXPORT_TIMEOUT, out / "export.log", "Cycles export (bpy)")
        (out / "scene_rgb.json").unlink()
        return blend

    def render(self, blend, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render in independent passes (batch/backends/passes.py); returns the render record."""
        return passes_mod.render(self, blend, mode, spp, out_exr, passes, seed, timeout, log_path)

    def session(self, blend, mode, log):
        """One child bpy process per pass (it opens the .blend and renders one seed)."""
        return passes_mod.OneProcessPerPass(
            lambda spp, seed, out, timeout, log: self._pass(blend, mode, spp, seed, out, timeout, log),
            log, {"approximated": reduction_of(blend).get("approximated", [])})

    def _pass(self, blend, mode, spp, seed, out, timeout, log):
        result = Path(out).with_suffix(".result.json")
        cmd = [sys.executable, str(WORKER), "render", "--blend", str(blend), "--mode", mode, "--spp", str(spp),
               "--passes", "1", "--seed", str(seed), "--out", str(out), "--result", str(result)]
        passes_mod.run_command(cmd, timeout, log, "Cycles render")
        info = json.loads(result.read_text())
        names, img = exr.read_image(out)
        return {"names": names, "image": img, "time_s": info["time_s"],
                "info": {k: info[k] for k in ("settings", "versions") if k in info}}
