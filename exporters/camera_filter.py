"""The IR's ideal linear polariser in front of the lens, applied to a render's Stokes channels.

Mitsuba 3 has no camera-side filter; a polariser sheet in the scene is a surface whose axis turns
for oblique rays (docs/findings.md, "Findings"). The Mitsuba writer therefore renders the Stokes vector and
writes the filter beside scene.xml (POSTPROCESS); the worker applies it to every pass before
the passes are averaged, so the per-pixel noise is the filtered image's own. The ideal polariser
with its axis at theta (IR frame: counter-clockwise from image right, S1 > 0 horizontal) has the
Mueller matrix (Collett, "Field Guide to Polarization", 2005, eq. for a rotated linear polariser)

    M = 1/2 [[1, c, s, 0], [c, c^2, c s, 0], [s, c s, s^2, 0], [0, 0, 0, 0]],  c = cos 2 theta, s = sin 2 theta.
"""
import json
from pathlib import Path

import numpy as np

POSTPROCESS = "camera_filter.json"


def mueller(angle_deg):
    c, s = np.cos(2 * np.radians(angle_deg)), np.sin(2 * np.radians(angle_deg))
    return 0.5 * np.array([[1, c, s, 0], [c, c * c, c * s, 0], [s, c * s, s * s, 0], [0, 0, 0, 0]])


def write(folder, angle_deg, keep_stokes):
    (Path(folder) / POSTPROCESS).write_text(json.dumps(
        {"ideal_linear_polarizer_deg": float(angle_deg), "keep_stokes": bool(keep_stokes)}, indent=1) + "\n")


def read(folder):
    path = Path(folder) / POSTPROCESS
    return json.loads(path.read_text()) if path.is_file() else None


def apply(spec, names, image):
    """Filter the channels ``names`` of an H x W x C (or N x H x W x C) image holding S0..S3 per
    colour channel: returns (names, image) with R, G, B the transmitted intensity and, with
    keep_stokes, the transmitted S0..S3."""
    colours = [n.split(".", 1)[1] for n in names if n.startswith("S0.")]
    stokes = np.stack([np.stack([image[..., names.index(f"S{k}.{c}")] for k in range(4)], axis=-1)
                       for c in colours], axis=-2)  # ... x colours x 4
    out = np.einsum("kj,...cj->...ck", mueller(spec["ideal_linear_polarizer_deg"]), stokes)
    new_names = list(colours)
    planes = [out[..., i, 0] for i in range(len(colours))]
    if spec.get("keep_stokes"):
        for k in range(4):
            new_names += [f"S{k}.{c}" for c in colours]
            planes += [out[..., i, k] for i in range(len(colours))]
    return new_names, np.stack(planes, axis=-1)
