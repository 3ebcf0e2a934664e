"""Lambertian patch under a uniform environment of radiance L, nothing above its plane: the
outgoing radiance is exactly rho(l) * L(l). Reported as CIEDE2000 between the rendered and the
expected colour (white: the perfect diffuser under L); and for a constant reflector under CIE D65
the chroma C*ab, which must be ~0 (neutral, since sRGB's white is D65)."""
import numpy as np

from ....exporters import colorimetry, spectra
from .. import raycast
from .common import MIN_PIXELS, probe as _probe

PATCH_DE_MAX = 1.0      # CIEDE2000 per Lambertian patch (set from measurement, see tests)
CHART_DE_MEAN_MAX = 0.5
NEUTRAL_CHROMA_MAX = 0.5


def _max_height_above(obj, center, normal):
    """Largest signed distance of an object's points above a plane (None if unknown)."""
    s = obj["shape"]
    if s["type"] == "rectangle":
        m = np.asarray(s["to_world"], dtype=np.float64)
        corners = np.array([[x, y, 0, 1] for x in (-1, 1) for y in (-1, 1)]) @ m.T
        return float(np.max((corners[:, :3] - center) @ normal))
    if s["type"] == "sphere":
        return float((np.asarray(s["center"]) - center) @ normal + s["radius"])
    return None


def patches(m):
    scene, names, image = m.scene, m.names, m.image
    env = scene.get("environment")
    if not env:
        return []
    cam, objs = scene["camera"], scene["objects"]
    h, w = image.shape[:2]
    radiance = env["radiance"]
    white = colorimetry.spectrum_xyz(radiance)
    cam_pos = np.asarray(cam["to_world"], dtype=np.float64)[:3, 3]
    out, des = [], []
    for i, obj in enumerate(objs):
        b = obj.get("bsdf") or {}
        if b.get("type") != "diffuse" or obj["shape"]["type"] != "rectangle" or obj.get("emitter"):
            continue
        center, normal, hx, hy = raycast.rectangle_frame(obj["shape"])
        if (cam_pos - center) @ normal <= 0:
            continue  # seen from behind
        eps = 0.01 * min(hx, hy)
        heights = [_max_height_above(o, center, normal) for j, o in enumerate(objs) if j != i]
        if any(hgt is None or hgt > eps for hgt in heights):
            continue  # something above the patch's plane: no closed form
        expected_xyz = colorimetry.spectrum_xyz(b["reflectance"], lambda wl: spectra.evaluate(radiance, wl))
        expected = colorimetry.xyz_to_srgb(expected_xyz)
        mask = raycast.pixels_inside(cam, w, h, objs, i, margin=0.7)
        name = f"lambert {obj['name']}"
        if mask.sum() < MIN_PIXELS:
            out.append(_probe(name, expected, None, None, "dE00", None, pixels=int(mask.sum())))
            continue
        measured = image[mask][:, :3].mean(axis=0)
        lab_m = colorimetry.lab(colorimetry.srgb_to_xyz(measured), white)
        de = colorimetry.delta_e_2000(lab_m, colorimetry.lab(expected_xyz, white))
        des.append(de)
        out.append(_probe(name, expected, measured, de, "dE00", de <= PATCH_DE_MAX, pixels=int(mask.sum())))
        if (b["reflectance"]["type"] == "constant" and radiance.get("type") == "named"
                and radiance.get("name") == "cie_d65"):
            chroma = float(np.hypot(lab_m[1], lab_m[2]))
            out.append(_probe(f"neutral {obj['name']} under D65", 0.0, chroma, chroma, "C*ab",
                              chroma <= NEUTRAL_CHROMA_MAX))
    if len(des) > 1:
        out.append(_probe("lambert mean dE00", 0.0, float(np.mean(des)), float(np.mean(des)), "dE00",
                          float(np.mean(des)) <= CHART_DE_MEAN_MAX))
        out.append(_probe("lambert max dE00", 0.0, float(np.max(des)), float(np.max(des)), "dE00",
                          float(np.max(des)) <= PATCH_DE_MAX))
    return out
