"""Analytic probes: image regions whose expected value follows from the scene's own spectra by
a closed form, independently of any renderer (plain numpy; colour-science for CIELAB/CIEDE2000).

- Lambertian patch under a uniform environment of radiance L, nothing above its plane: the
  outgoing radiance is exactly rho(l) * L(l). Reported as CIEDE2000 between the rendered and
  the expected colour (white: the perfect diffuser under L); and for a constant reflector under
  CIE D65 the chroma C*ab, which must be ~0 (neutral, since sRGB's white is D65).
- Smooth dielectric reflecting an area light (unpolarised) into the camera: the reflected
  radiance is L * (Rs cos^2 phi + Rp sin^2 phi) / 2 through an ideal linear polariser, where phi
  is the angle between the reflection's s direction and the polariser's transmission axis in the
  plane across the ray (Fresnel equations, Hecht, Optics, eq. 4.42-4.43). The polariser is a sheet
  across the lens: its axis, at theta from image right in the sheet, is projected across each
  ray (an oblique ray sees it slightly turned: measured, this is what Mitsuba's sheet polariser
  does, and at 512x512 it is visible against the region's standard error). At Brewster's angle
  Rp = 0, so a crossed polariser extinguishes the reflection.
  Without a polariser and with Stokes output, the degree of polarisation is (Rs - Rp)/(Rs + Rp).
- Stokes output: S0 >= sqrt(S1^2 + S2^2 + S3^2) at every pixel, up to noise.

Each probe is a dict {name, expected, measured, error, unit, pass}; ``pass`` is None when the
probe cannot be measured at the render's resolution (fewer than MIN_PIXELS whole pixels).
"""
import numpy as np

from ..exporters import spectra
from . import colorimetry, compare, raycast

MIN_PIXELS = 4
PATCH_DE_MAX = 1.0      # CIEDE2000 per Lambertian patch (set from measurement, see tests)
CHART_DE_MEAN_MAX = 0.5
NEUTRAL_CHROMA_MAX = 0.5
Z_MAX = 4.0             # probe means are judged against their own standard error
REL_SLACK = 0.005       # ... with 0.5 % for evaluating Fresnel at pixel centres


def _probe(name, expected, measured, error, unit, passed, **extra):
    as_list = lambda v: None if v is None else (np.asarray(v, dtype=float).round(8).tolist() if np.ndim(v) else float(v))
    out = {"name": name, "expected": as_list(expected), "measured": as_list(measured),
           "error": None if error is None else float(error), "unit": unit,
           "pass": None if passed is None else bool(passed)}
    out.update(extra)
    return out


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


def lambert_patches(scene, names, image):
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


def fresnel_dielectric(cos_i, eta):
    """(Rs, Rp) for unpolarised light from outside (eta = n_inside / n_outside)."""
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin_t2 = (1 - cos_i**2) / eta**2
    cos_t = np.sqrt(np.clip(1 - sin_t2, 0.0, 1.0))
    rs = ((cos_i - eta * cos_t) / (cos_i + eta * cos_t)) ** 2
    rp = ((eta * cos_i - cos_t) / (eta * cos_i + cos_t)) ** 2
    return np.where(sin_t2 >= 1, 1.0, rs), np.where(sin_t2 >= 1, 1.0, rp)


def _reflection_geometry(scene, di, li, w, h, points):
    """Per ray: (valid mask, cos_i, psi(theta), eta) for camera rays reflecting off object di into
    light li; psi(theta) is the angle between s and a sheet polariser's axis at theta."""
    cam, objs = scene["camera"], scene["objects"]
    m = np.asarray(cam["to_world"], dtype=np.float64)
    origin, dirs = raycast.camera_rays(cam, w, h, points)
    who, t = raycast.nearest(objs, origin, dirs)
    on = who == di
    center, n, _, _ = raycast.rectangle_frame(objs[di]["shape"])
    n = n if (m[:3, 3] - center) @ n > 0 else -n
    p = origin + np.where(np.isfinite(t), t, 0)[..., None] * dirs
    cos_i = -(dirs @ n)
    r = dirs + 2 * cos_i[..., None] * n
    eps = 1e-6 * max(1.0, float(np.max(np.abs(center))))
    who_r, _ = raycast.nearest(objs, p + eps * n, r)
    lc, ln, _, _ = raycast.rectangle_frame(objs[li]["shape"])
    inner = np.isfinite(raycast.hit_rectangle(objs[li]["shape"], p + eps * n, r, margin=0.8))
    faces = (-r) @ ln > 0  # the light emits along its +Z only
    eta = objs[di]["bsdf"]["int_ior"] / objs[di]["bsdf"].get("ext_ior", 1.000277)
    sin_t = np.sqrt(np.clip(1 - cos_i**2, 0, 1)) / eta
    cos_t = np.sqrt(np.clip(1 - sin_t**2, 0, 1))
    refr = dirs / eta + (cos_i / eta - cos_t)[..., None] * n
    who_t, _ = raycast.nearest(objs, p - eps * n, refr)
    valid = on & (who_r == li) & inner & faces & (who_t == -1) & (cos_i > 0)
    s = np.cross(dirs, n)
    s /= np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-12)
    right, up = m[:3, 0] / np.linalg.norm(m[:3, 0]), m[:3, 1] / np.linalg.norm(m[:3, 1])

    def psi(theta):
        axis = np.cos(theta) * right + np.sin(theta) * up
        across = axis - (dirs @ axis)[..., None] * dirs  # the axis as seen across each ray
        across /= np.maximum(np.linalg.norm(across, axis=-1, keepdims=True), 1e-12)
        return np.arccos(np.clip(np.abs(np.sum(across * s, axis=-1)), 0.0, 1.0))
    return valid, cos_i, psi, eta


def brewster(scene, names, image):
    objs = scene["objects"]
    h, w = image.shape[:2]
    pol = scene["camera"].get("polarizer")
    stokes = "S0.G" in names
    out = []
    dielectrics = [i for i, o in enumerate(objs) if (o.get("bsdf") or {}).get("type") == "dielectric"
                   and o["shape"]["type"] == "rectangle" and not ((o["bsdf"].get("roughness") or {}).get("alpha", 0) > 0)]
    lights = [i for i, o in enumerate(objs) if o.get("emitter") and o["shape"]["type"] == "rectangle"]
    if not (pol or stokes):
        return out
    for di in dielectrics:
        for li in lights:
            corners, _, _, _ = _reflection_geometry(scene, di, li, w, h, "corners")
            valid, cos_i, psi, eta = _reflection_geometry(scene, di, li, w, h, "centers")
            mask = valid & corners[:-1, :-1] & corners[1:, :-1] & corners[:-1, 1:] & corners[1:, 1:]
            rs, rp = fresnel_dielectric(cos_i, eta)
            light_rgb = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(objs[li]["emitter"]["radiance"]))
            label = f"{objs[di]['name']} reflecting {objs[li]['name']}"
            brewster_deg = float(np.degrees(np.arctan(eta)))
            if pol:
                phi = psi(np.radians(pol["angle"]))
                factor = (rs * np.cos(phi) ** 2 + rp * np.sin(phi) ** 2) / 2
                name = f"brewster {label}, polariser {pol['angle']:g} deg"
            else:
                factor = (rs + rp) / 2
                name = f"reflection {label}"
            if mask.sum() < MIN_PIXELS:
                out.append(_probe(name, None, None, None, "sigma", None, pixels=int(mask.sum())))
                continue
            expected_px = factor[mask][:, None] * light_rgb
            measured_px = image[mask][:, :3]
            resid = measured_px - expected_px
            se = resid.std(axis=0, ddof=1) / np.sqrt(mask.sum())
            exp_mean, meas_mean = expected_px.mean(axis=0), measured_px.mean(axis=0)
            tol = np.sqrt(se**2 + (REL_SLACK * np.abs(exp_mean)) ** 2) + 1e-12
            z = np.abs(resid.mean(axis=0)) / tol
            out.append(_probe(name, exp_mean, meas_mean, float(z.max()), "sigma", bool(z.max() <= Z_MAX),
                              pixels=int(mask.sum()),
                              incidence_deg=[float(np.degrees(np.arccos(cos_i[mask].max()))),
                                             float(np.degrees(np.arccos(cos_i[mask].min())))],
                              brewster_deg=brewster_deg))
            if stokes and not pol:
                s = [image[mask][:, names.index(f"S{k}.G")] for k in range(4)]
                dop_m = float(np.sqrt(s[1].mean() ** 2 + s[2].mean() ** 2 + s[3].mean() ** 2) / s[0].mean())
                dop_e = float(((rs - rp) * 0.5)[mask].mean() / factor[mask].mean())
                out.append(_probe(f"degree of polarisation, {label}", dop_e, dop_m, abs(dop_m - dop_e), "",
                                  abs(dop_m - dop_e) <= 0.02, pixels=int(mask.sum())))
    return out


def stokes_validity(scene, names, image, reference):
    if "S0.G" not in names:
        return []
    name = "Stokes S0 >= |(S1, S2, S3)|"
    if reference is None or reference.names != names:
        return [_probe(name, 0.0, None, None, "fraction", None, note="needs the reference's noise")]
    spp = scene["render"]["spp"]
    try:
        mean, var_of_mean, sigma2 = compare.reference_at(reference.mean, reference.stderr, reference.spp, image.shape)
    except ValueError:
        return [_probe(name, 0.0, None, None, "fraction", None, note="resolution not comparable")]
    worst = 0.0
    for c in "RGB":
        idx = [names.index(f"S{k}.{c}") for k in range(4)]
        s = image[..., idx].astype(np.float64)
        sd = np.sqrt(np.sum(sigma2[..., idx] / spp + var_of_mean[..., idx], axis=-1))
        excess = np.linalg.norm(s[..., 1:], axis=-1) - s[..., 0]
        floor = 1e-6 * max(float(np.abs(s[..., 0]).mean()), 1e-12)
        worst = max(worst, float(np.mean(excess > Z_MAX * sd + floor)))
    return [_probe(name, 0.0, worst, worst, "fraction of pixels beyond 4 sigma", worst <= 1e-3)]


def evaluate(scene, names, image, reference=None):
    """Every probe that applies to ``scene``, measured on ``image`` (channels ``names``)."""
    return (lambert_patches(scene, names, image) + brewster(scene, names, image)
            + stokes_validity(scene, names, image, reference))
