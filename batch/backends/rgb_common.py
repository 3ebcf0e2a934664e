"""What the RGB backends (Cycles, LuxCore) share: deciding the mode from what the scene needs
(rgb_scene.problems), exporting the reduced scene, and writing independent passes as a mean and
its standard error (as mitsuba/worker.py does). Their renders run in warm workers
(batch/backends/warm.py).

Modes: ``rgb`` (spectra reduced to RGB by exporters/rgb_reduction.py's rule: always, that is what
these backends measure) and ``rgb-approx`` (``--approximate``: something the renderer cannot
express was rendered as the stated approximation; the job's record lists it under
``approximated``). Without ``--approximate`` such a scene is ``unsupported`` with every object
and field named.
"""
import json
import math
from pathlib import Path

import numpy as np

from ...exporters import rgb_scene
from .. import exr

MODE = "rgb"
APPROX_MODE = "rgb-approx"


class RgbBackend:
    """Shared half of an RGB backend; a subclass sets name, label, distributions and implements
    availability, write(rgb scene, out_dir) -> path and render."""
    name = label = ""
    distributions = frozenset()
    light_types = frozenset()  # the IR's delta light types (point, spot, directional) it renders
    environment_maps = False  # renders an IR environment map (docs/scene-format.md 7.1)
    textures = False  # renders an IR image texture (docs/scene-format.md 6.7)

    def __init__(self, executable=None, approximate=False):
        self.executable = executable
        self.approximate = approximate
        self.options = {"executable": executable, "approximate": approximate}  # what rebuilds this backend

    @property
    def formats(self):
        return (self.name,)

    def mode_for(self, scene):
        found = rgb_scene.problems(scene, self.distributions, self.light_types, self.environment_maps, self.textures)
        blocking = [p for p in found if not self.approximate or p[3] is None]
        if blocking:
            hint = any(p[3] for p in blocking)
            return None, (f"{self.label} cannot express: " + "; ".join(f"{o}.{f}: {m}" for o, f, m, _ in blocking)
                          + (" (--approximate renders an explicitly labelled approximation)" if hint else ""))
        return (APPROX_MODE if found else MODE), None

    def export(self, scene, out_dir):
        """Reduce ``scene`` to RGB and write it in this renderer's format into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        rgb = rgb_scene.build(scene, self.distributions, approximate=self.approximate, light_types=self.light_types,
                              out_dir=out, env_maps=self.environment_maps, textures=self.textures)
        return self.write(rgb, out)


def reduction_of(export_path):
    """reduction.json of an exported folder (what was reduced and approximated)."""
    path = Path(export_path).parent / "reduction.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def expand(image, film_scale=1.0, stokes=False):
    """(names, H x W x C) of one pass's H x W x 3 linear sRGB image: ``film_scale`` multiplies it
    (an approximated polariser); ``stokes`` adds S0 = RGB and S1 = S2 = S3 = 0 (an approximated
    Stokes output)."""
    img = np.asarray(image, dtype=np.float64)[..., :3] * film_scale
    names = ["R", "G", "B"]
    if stokes:
        zeros = np.zeros_like(img)
        img = np.concatenate([img, img, zeros, zeros, zeros], axis=-1)
        names += [f"S{k}.{c}" for k in range(4) for c in "RGB"]
    return names, img


def write_passes(out_exr, images, film_scale=1.0, stokes=False):
    """Write the mean of pass images (each H x W x 3, linear sRGB, through ``expand``) and, with
    two or more, the standard error of that mean per pixel. Returns the channel names."""
    expanded = [expand(i, film_scale, stokes) for i in images]
    names = expanded[0][0]
    stack = np.stack([img for _, img in expanded])
    extra = {}
    if len(images) > 1:
        stderr = stack.std(axis=0, ddof=1) / math.sqrt(len(images))
        extra = {f"stderr.{n}": stderr[..., i].astype(np.float32) for i, n in enumerate(names)}
    exr.write_image(out_exr, names, stack.mean(axis=0), extra)
    return names


def split_spp(spp, passes):
    """Samples per pass (the same in every pass, rounded up as mitsuba/worker.py does)."""
    return math.ceil(spp / max(1, passes))
