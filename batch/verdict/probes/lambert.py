"""Lambertian patches under a uniform environment of radiance L, nothing above their planes: the
outgoing radiance is exactly rho(l) * L(l) at every point and in every direction.

Each patch is judged on the render's own noise: its region's pixels are independent draws, so the
mean of the residuals (rendered minus expected linear sRGB, per channel) is compared with its
standard error (Student's t, n - 1 degrees of freedom). A chart of patches adds one more test: the
luminance scale that best maps the expected patches onto the rendered ones (weighted least
squares), against 1. That test pools every patch, so it sees a radiometric scale error an order of
magnitude smaller than one patch does (a 1 % brighter illuminant, or a renderer's normalisation).
All tests of a scene share the family-wise false-alarm rate stats.ALPHA (Sidak).

CIEDE2000 is reported beside each patch as information, with the dE00 that the test resolves at
this noise (the colour difference of a shift of z_crit standard errors in the measured direction),
so a reader sees both how far a colour is off and how far it could be off unnoticed.
"""
import numpy as np

from ....exporters import colorimetry, spectra
from .. import raycast, stats
from .common import MIN_PIXELS, probe as _probe

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


def _patches(scene):
    """Indices of the Lambertian rectangles facing the camera with nothing above their planes."""
    cam, objs = scene["camera"], scene["objects"]
    cam_pos = np.asarray(cam["to_world"], dtype=np.float64)[:3, 3]
    for i, obj in enumerate(objs):
        b = obj.get("bsdf") or {}
        if b.get("type") != "diffuse" or b.get("fluorescence") or obj["shape"]["type"] != "rectangle" \
                or obj.get("emitter"):
            continue
        center, normal, hx, hy = raycast.rectangle_frame(obj["shape"])
        if (cam_pos - center) @ normal <= 0:
            continue  # seen from behind
        eps = 1e-6 * max(hx, hy)  # numerical only: even a patch 1 mm above shades its surroundings
        heights = [_max_height_above(o, center, normal) for j, o in enumerate(objs) if j != i]
        if any(hgt is None or hgt > eps for hgt in heights):
            continue  # something above the patch's plane: no closed form
        yield i


def _expected(obj, radiance, obs):
    return colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(
        obj["bsdf"]["reflectance"], lambda wl: spectra.evaluate(radiance, wl), obs))


def _scale_test(rows, y_row, tests):
    """Weighted least-squares luminance scale of measured over expected patches, against 1."""
    ym = np.array([r[0] @ y_row for r in rows])
    ye = np.array([r[1] @ y_row for r in rows])
    sy = np.array([r[2] for r in rows])
    wts = 1.0 / sy**2
    s = float(np.sum(wts * ym * ye) / np.sum(wts * ye**2))
    return s, stats.compare_means(s, 1.0, float(1.0 / np.sqrt(np.sum(wts * ye**2))), tests=tests)


def patches(m):
    scene, image = m.scene, m.image
    env = scene.get("environment")
    if not env:
        return []
    cam, objs = scene["camera"], scene["objects"]
    h, w = image.shape[:2]
    radiance = env["radiance"]
    white = colorimetry.spectrum_xyz(radiance)
    y_row = colorimetry.srgb_to_xyz(np.eye(3))[:, 1]  # Y of each sRGB primary
    observers = [o for o in m.observers if o != colorimetry.GROUND_TRUTH]
    chosen = list(_patches(scene))
    if not chosen:  # no ray cast for a scene without patches (16 of the default suite's 18 with a sky: issue 45 item 1)
        return []
    hits = raycast.corner_hits(cam, w, h, objs)  # one cast for every patch
    found = [(objs[i], raycast.pixels_inside(cam, w, h, objs, i, margin=0.7, hits=hits)) for i in chosen]
    measurable = sum(1 for _, mk in found if mk.sum() >= MIN_PIXELS)
    tests = 3 * measurable + (1 if measurable > 1 else 0)
    z_crit = stats.z_critical(stats.sidak_threshold(stats.ALPHA, tests))
    out, rows = [], {o: [] for o in [colorimetry.GROUND_TRUTH] + observers}
    for obj, mask in found:
        label = f"lambert {obj['name']}"
        expected = _expected(obj, radiance, colorimetry.GROUND_TRUTH)
        if mask.sum() < MIN_PIXELS:
            out.append(_probe(label, expected, None, None, "dE00", None, pixels=int(mask.sum())))
            continue
        px = image[mask][:, :3].astype(np.float64)
        n = px.shape[0]
        measured = px.mean(axis=0)
        se = px.std(axis=0, ddof=1) / np.sqrt(n)
        se_y = float((px @ y_row).std(ddof=1) / np.sqrt(n))
        stat = stats.compare_means(measured, expected, se, dof=n - 1, tests=tests)
        alternatives = {}
        for o in rows:
            e_o = expected if o == colorimetry.GROUND_TRUTH else _expected(obj, radiance, o)
            rows[o].append((measured, e_o, se_y))
            if o != colorimetry.GROUND_TRUTH:
                alternatives[o] = stats.compare_means(measured, e_o, se, dof=n - 1, tests=tests)
        lab_e = colorimetry.lab(colorimetry.srgb_to_xyz(expected), white)
        de = colorimetry.delta_e_2000(colorimetry.lab(colorimetry.srgb_to_xyz(measured), white), lab_e)
        shifted = expected + z_crit * se * np.sign(measured - expected)
        de_noise = colorimetry.delta_e_2000(colorimetry.lab(colorimetry.srgb_to_xyz(shifted), white), lab_e)
        out.append(_probe(label, expected, measured, de, "dE00", stat["pass"], pixels=n, z=stat["z"],
                          resolvable_dE00=de_noise, stat=stat, alternatives=alternatives))
    if measurable > 1:
        s, stat = _scale_test(rows[colorimetry.GROUND_TRUTH], y_row, tests)
        alternatives = {o: _scale_test(rows[o], y_row, tests)[1] for o in observers}
        out.append(_probe("lambert chart luminance scale", 1.0, s, s - 1.0, "relative", stat["pass"],
                          patches=measurable, z=stat["z"], stat=stat, alternatives=alternatives))
    return out
