"""Mitsuba 3 backend: renders the exported scene.xml in a child process.

Default route: batch/backends/mitsuba_worker.py with the mitsuba Python package (independent passes,
render time measured inside). With ``-e mitsuba=PATH`` the user's ``mitsuba`` executable
renders instead (``mitsuba -m VARIANT -Dspp=N -Dseed=S -o out.exr scene.xml``).
"""
import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from ...exporters import mitsuba_writer
from .. import exr
from . import child, llvm

WORKER = Path(__file__).resolve().parent / "mitsuba_worker.py"
NATIVE = {"spectral", "polarization"}
# phenomena this project's Python plugins add (exporters/mitsuba_plugins): they load through the
# Python API only, not through the mitsuba executable
PLUGIN_NEEDS = {"thin_film", "dispersion", "fluorescence"}  # sb_thin_film_conductor; sb_dispersive_dielectric
# (unpolarised); sb_fluorescent_diffuse + sb_fluorescent_path (unpolarised spectral variants)
INTEGRATORS = ("path", "ptracer")  # the IR's render.integrator values Mitsuba renders


class BackendFailure(RuntimeError):
    pass


def scalar_twin(variant):
    """The scalar variant that models the same as an llvm_ad_* one (Mitsuba ships no scalar_mono*:
    its spectral twin is exact for the constant spectra a mono variant is chosen for)."""
    kind = variant.split("_", 2)[-1] if variant.startswith("llvm_ad_") else variant.split("_", 1)[-1]
    return "scalar_" + kind.replace("mono", "spectral")


class MitsubaBackend:
    name = "mitsuba"
    formats = ("mitsuba",)

    def __init__(self, executable=None, force_variant=None):
        self.executable = executable
        self.force_variant = force_variant
        self.options = {"executable": executable, "force_variant": force_variant}  # what rebuilds this backend

    def availability(self):
        """(available, reason)."""
        if self.executable:
            return (Path(self.executable).exists(), f"mitsuba executable not found: {self.executable}")
        if importlib.util.find_spec("mitsuba") is None:
            return False, "the mitsuba Python package is not installed (pip install mitsuba==3.9.1)"
        return True, ""

    def llvm_message(self):
        return llvm.find()[1]

    def mode_for(self, scene):
        """(variant, None) or (None, reason the scene is unsupported)."""
        needs = set(scene.get("needs", []))
        missing = sorted(needs - NATIVE - PLUGIN_NEEDS)
        if missing:
            return None, (f"Mitsuba 3 has no native {', '.join(missing)} "
                          "(needs a plugin this backend does not have yet)")
        if self.executable and needs & PLUGIN_NEEDS:
            return None, (f"{', '.join(sorted(needs & PLUGIN_NEEDS))} needs this project's Python plugins, "
                          "which the mitsuba executable cannot load (use the Python route: no -e mitsuba=...)")
        if "dispersion" in needs and "polarization" in needs:
            return None, ("the dispersive dielectric plugin has no polarised (Mueller) form: "
                          "dispersion with polarisation is not supported")
        if scene.get("render", {}).get("integrator", "path") not in INTEGRATORS:
            return None, f"render.integrator {scene['render']['integrator']!r}: Mitsuba renders {', '.join(INTEGRATORS)}"
        if "fluorescence" in needs and "polarization" in needs:
            return None, ("fluorescence with polarisation: sb_fluorescent_path traces unpolarised spectral "
                          "radiance only")
        if self.force_variant:
            if "fluorescence" in needs and not (self.force_variant.endswith("_spectral")
                                                and not self.force_variant.startswith("scalar_")):
                return None, ("fluorescence needs an unpolarised spectral JIT variant (llvm_ad_spectral), "
                              f"not {self.force_variant}")
            return self.force_variant, None
        llvm_ok = llvm.find()[0] is not None
        if "fluorescence" in needs and not llvm_ok:
            return None, ("fluorescence: sb_fluorescent_path is a Python integrator that Mitsuba's scalar "
                          "variants would call once per sample; it needs llvm_ad_spectral: "
                          + llvm.find()[1])
        prefix = "llvm_ad_" if llvm_ok else "scalar_"
        if "polarization" in needs:
            if "spectral" in needs or not llvm_ok:  # Mitsuba ships no scalar_mono_polarized
                return prefix + "spectral_polarized", None
            return "llvm_ad_mono_polarized", None  # every spectrum is constant: one wavelength is exact
        if "spectral" in needs or "dispersion" in needs:
            return prefix + "spectral", None
        return prefix + "rgb", None

    def export(self, scene, out_dir):
        return mitsuba_writer.write(scene, out_dir)

    def render(self, xml_path, variant, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render; returns a dict with time_s, wall_s, spp, variant, versions. Raises BackendFailure."""
        if self.executable:
            return self._render_cli(xml_path, variant, spp, out_exr, seed, timeout, log_path)
        result_path = Path(out_exr).with_suffix(".result.json")
        cmd = [sys.executable, str(WORKER), "--xml", str(xml_path), "--variant", variant, "--spp", str(spp),
               "--passes", str(passes), "--seed", str(seed), "--out", str(out_exr), "--result", str(result_path)]
        self._run(cmd, timeout, log_path)
        return json.loads(result_path.read_text())

    def _run(self, cmd, timeout, log_path):
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=llvm.env(),
                                  **child.popen_kwargs())
        except subprocess.TimeoutExpired as exc:
            raise BackendFailure(f"render timed out after {timeout} s") from exc
        if log_path:
            Path(log_path).write_text(f"$ {' '.join(cmd)}\n{proc.stdout}\n{proc.stderr}")
        if proc.returncode != 0:
            tail = (proc.stderr.strip() or proc.stdout.strip()).splitlines()[-3:]
            raise BackendFailure(f"mitsuba exited with {proc.returncode}: {' | '.join(tail)[-600:]}")
        return time.perf_counter() - t0

    def _render_cli(self, xml_path, variant, spp, out_exr, seed, timeout, log_path):
        cmd = [self.executable, "-m", variant, f"-Dspp={spp}", f"-Dseed={seed}", "-o", str(out_exr), str(xml_path)]
        wall = self._run(cmd, timeout, log_path)
        names, img = exr.read_image(out_exr)  # normalise the channel layout
        if names and names[0] == "Y":
            img = np.concatenate([np.repeat(img[..., :1], 3, axis=-1), img[..., 1:]], axis=-1)
            names = ["R", "G", "B"] + names[1:]
        exr.write_image(out_exr, names, img)
        return {"variant": variant, "spp": spp, "passes": 1, "seed": seed, "time_s": wall, "wall_s": wall,
                "resolution": [img.shape[1], img.shape[0]], "versions": {"mitsuba": "executable " + self.executable}}
