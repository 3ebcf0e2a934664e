"""What reducing spectra to RGB costs on the ColorChecker: per Lambertian patch under a uniform
environment, the rendered colour's CIEDE2000 against the spectral truth rho(l) * L(l), next to
what the reduction rule (exporters/rgb_reduction.py) predicts without any renderer, and the
pixels' residuals against the rule's own colour (to judge on the render's noise that the
renderer implements the rule). Used by tests/backends/test_rgb_backends.py,
benchmarks/calibrate_rgb_colorchecker.py and benchmarks/bench_rgb_backends.py.
"""
import numpy as np

from ...exporters import colorimetry, rgb_reduction
from ..verdict import raycast


def patch_pixels(scene, img, margin=0.7):
    """{patch object name: (pixels N x 3, reflectance spectrum)} of the chart's patches (the
    Lambertian rectangles named patch_*), whole pixels inside the inner ``margin``."""
    h, w = img.shape[:2]
    out = {}
    for i, obj in enumerate(scene["objects"]):
        if obj["name"].startswith("patch_") and (obj.get("bsdf") or {}).get("type") == "diffuse":
            mask = raycast.pixels_inside(scene["camera"], w, h, scene["objects"], i, margin=margin)
            out[obj["name"]] = (img[mask][:, :3].astype(np.float64), obj["bsdf"]["reflectance"])
    return out


def chart_errors(scene, img):
    """{patch: (measured dE00 against the truth, dE00 the rule predicts, pixels minus the rule's
    colour)} for a chart under the scene's uniform environment."""
    env = scene["environment"]["radiance"]
    white = colorimetry.spectrum_xyz(env)
    out = {}
    for name, (pix, refl) in patch_pixels(scene, img).items():
        truth, rule, predicted = rgb_reduction.predicted_error(refl, env)
        lab = colorimetry.lab(colorimetry.srgb_to_xyz(pix.mean(axis=0)), white)
        measured = colorimetry.delta_e_2000(lab, colorimetry.lab(colorimetry.srgb_to_xyz(truth), white))
        out[name] = (measured, predicted, pix - rule)
    return out
