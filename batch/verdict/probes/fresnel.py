"""Smooth dielectric reflecting an area light (unpolarised) into the camera: the reflected
radiance is L * (Rs cos^2 phi + Rp sin^2 phi) / 2 through an ideal linear polariser, where phi is
the angle between the reflection's s direction and the polariser's transmission axis in the plane
across the ray (Fresnel equations, Hecht, Optics, eq. 4.42-4.43). The polariser is a sheet across
the lens: its axis, at theta from image right in the sheet, is projected across each ray (an
oblique ray sees it slightly turned: measured, this is what Mitsuba's sheet polariser does, and
at 512x512 it is visible against the region's standard error). At Brewster's angle Rp = 0, so a
crossed polariser extinguishes the reflection. Without a polariser and with Stokes output, the
degree of polarisation is (Rs - Rp)/(Rs + Rp)."""
import numpy as np

from ....exporters import colorimetry, dispersion
from .. import raycast
from .common import MIN_PIXELS, probe as _probe

Z_MAX = 4.0             # probe means are judged against their own standard error
REL_SLACK = 0.005       # ... with 0.5 % for evaluating Fresnel at pixel centres


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


def brewster(m):
    scene, names, image = m.scene, m.names, m.image
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
    for di in [i for i in dielectrics if dispersion.is_model(objs[i]["bsdf"]["int_ior"])]:
        # the closed form takes one IOR; a dispersive one is said so, not approximated
        out.append(_probe(f"reflection {objs[di]['name']}", None, None, None, "sigma", None,
                          reason="dispersive int_ior: the Fresnel probe needs a constant IOR"))
    dielectrics = [i for i in dielectrics if not dispersion.is_model(objs[i]["bsdf"]["int_ior"])]
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
