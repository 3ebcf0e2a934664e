"""A smooth dielectric plane reflecting an area light (unpolarised) into the camera.

Through an ideal linear polariser the reflected radiance is L (Rs cos^2 phi + Rp sin^2 phi) / 2,
phi being the angle between the reflection's s direction and the polariser's transmission axis
across the ray (Fresnel equations, Hecht, Optics, 5th ed., eq. 4.42-4.43; Malus' law). The IR's
polariser is ideal and defined as seen from the camera: its axis is at theta in every ray's Stokes
frame (below), so applying it to Stokes output gives the same image. At Brewster's angle Rp = 0,
so a crossed polariser extinguishes the reflection.

Without a polariser and with Stokes output, the reflection's Stokes vector is
L/2 (Rs + Rp, (Rs - Rp) cos 2chi, (Rs - Rp) sin 2chi, 0), chi being the angle of the s direction
in the camera's Stokes frame of each ray (x = ray x camera up, counter-clockwise as seen from the
camera: the IR's convention, exporters/ir.py). The degree of polarisation (Rs - Rp)/(Rs + Rp) is
reported beside it.

The expected value of each pixel is the mean over its footprint (Gauss-Legendre points: the
incidence angle changes across a pixel), so nothing but noise separates a correct render from the
expected image; each channel's mean residual over the region is judged against its own standard
error (batch/verdict/stats.py), the tests of one probe sharing stats.ALPHA.
"""
import numpy as np

from ....exporters import colorimetry, dispersion
from .. import raycast, stats
from ..optics import fresnel_dielectric
from .common import MIN_PIXELS, probe as _probe, remembered

FOOTPRINT = 3  # Gauss-Legendre points per pixel axis


def _reflection(scene, di, li, w, h, points):
    """Per ray through ``points``: valid (reflects off object di straight into light li, nothing
    in the way, the refracted ray escapes), cos_i, eta, the unit s direction and the ray."""
    cam, objs = scene["camera"], scene["objects"]
    m = np.asarray(cam["to_world"], dtype=np.float64)
    origin, dirs = raycast.camera_rays(cam, w, h, points)
    who, t = raycast.nearest(objs, origin, dirs)
    center, n, _, _ = raycast.rectangle_frame(objs[di]["shape"])
    n = n if (m[:3, 3] - center) @ n > 0 else -n
    p = origin + np.where(np.isfinite(t), t, 0)[..., None] * dirs
    cos_i = -(dirs @ n)
    r = dirs + 2 * cos_i[..., None] * n
    eps = 1e-6 * max(1.0, float(np.max(np.abs(center))))
    who_r, _ = raycast.nearest(objs, p + eps * n, r)
    _, ln, _, _ = raycast.rectangle_frame(objs[li]["shape"])
    inner = np.isfinite(raycast.hit_rectangle(objs[li]["shape"], p + eps * n, r, margin=0.8))
    faces = (-r) @ ln > 0  # the light emits along its +Z only
    eta = objs[di]["bsdf"]["int_ior"] / objs[di]["bsdf"].get("ext_ior", 1.000277)
    sin_t = np.sqrt(np.clip(1 - cos_i**2, 0, 1)) / eta
    cos_t = np.sqrt(np.clip(1 - sin_t**2, 0, 1))
    refr = dirs / eta + (cos_i / eta - cos_t)[..., None] * n
    who_t, _ = raycast.nearest(objs, p - eps * n, refr)
    valid = (who == di) & (who_r == li) & inner & faces & (who_t == -1) & (cos_i > 0)
    s = np.cross(dirs, n)
    s /= np.maximum(np.linalg.norm(s, axis=-1, keepdims=True), 1e-12)
    return valid, cos_i, eta, s, dirs


def _stokes_chi(s, dirs, up):
    """Angle of s in each ray's Stokes frame: x = ray x up, y = x x ray (counter-clockwise from
    image right as seen from the camera)."""
    bx = np.cross(dirs, up)
    bx /= np.maximum(np.linalg.norm(bx, axis=-1, keepdims=True), 1e-12)
    by = np.cross(bx, dirs)
    return np.arctan2(np.sum(s * by, axis=-1), np.sum(s * bx, axis=-1))


@remembered(size=1)
def _footprints(camera, objects, di, li, w, h):
    """Per footprint point (FOOTPRINT^2 of them, in footprint_offsets' order): whether the ray is
    valid, Rs, Rp and chi (stacked); the pixels whose corners are all valid; cos_i at the pixel
    centres; eta. What ``_expected`` needs but the polariser: polarizing_plane_0 and _90 differ
    only in their polariser's angle, and the second takes these from the first (issue 45 item 1:
    1.7 s of its 2.5 s of CPU). ``camera``: the camera's fields that raycast reads (its name and
    polariser are not)."""
    scene = {"camera": camera, "objects": objects}
    up = np.asarray(camera["to_world"], dtype=np.float64)[:3, 1]
    up = up / np.linalg.norm(up)
    valid, rs, rp, chi = [], [], [], []
    for offset, _weight in raycast.footprint_offsets(FOOTPRINT):
        ok, cos_i, eta, s, dirs = _reflection(scene, di, li, w, h, offset)
        r_s, r_p = fresnel_dielectric(cos_i, eta)
        valid.append(ok), rs.append(r_s), rp.append(r_p), chi.append(_stokes_chi(s, dirs, up))
    corners, *_ = _reflection(scene, di, li, w, h, "corners")
    corners = corners[:-1, :-1] & corners[1:, :-1] & corners[:-1, 1:] & corners[1:, 1:]
    cos_centre = _reflection(scene, di, li, w, h, "centers")[1]
    return np.stack(valid), np.stack(rs), np.stack(rp), np.stack(chi), corners, cos_centre, eta


def _expected(scene, di, li, w, h, pol):
    """Footprint means of (I through the polariser or (S0, S1, S2)) / L, and the mask of pixels
    valid over their whole footprint."""
    camera = raycast.camera_fields(scene["camera"])  # what raycast reads
    valid_all, rs_all, rp_all, chi_all, corners, cos_centre, eta = _footprints(camera, scene["objects"], di, li, w, h)
    mask, acc = None, None
    for k, (offset, weight) in enumerate(raycast.footprint_offsets(FOOTPRINT)):
        valid, rs, rp, chi = valid_all[k], rs_all[k], rp_all[k], chi_all[k]
        if pol:
            phi = chi - np.radians(pol["angle"])
            values = np.stack([(rs * np.cos(phi) ** 2 + rp * np.sin(phi) ** 2) / 2], axis=-1)
        else:
            values = np.stack([(rs + rp) / 2, (rs - rp) / 2 * np.cos(2 * chi), (rs - rp) / 2 * np.sin(2 * chi)], axis=-1)
        mask = valid if mask is None else mask & valid
        acc = weight * values if acc is None else acc + weight * values
    mask = mask & corners
    return mask, acc, eta, cos_centre


def brewster(m):
    scene, names, image = m.scene, m.names, m.image
    objs = scene["objects"]
    h, w = image.shape[:2]
    pol = scene["camera"].get("polarizer")
    stokes = "S0.G" in names
    if not (pol or stokes):
        return []
    dielectrics = [i for i, o in enumerate(objs) if (o.get("bsdf") or {}).get("type") == "dielectric"
                   and isinstance(o["bsdf"].get("int_ior"), (int, float))
                   and o["shape"]["type"] == "rectangle" and not ((o["bsdf"].get("roughness") or {}).get("alpha", 0) > 0)]
    lights = [i for i, o in enumerate(objs) if o.get("emitter") and o["shape"]["type"] == "rectangle"]
    out = []
    for i, o in enumerate(objs):
        b = o.get("bsdf") or {}
        if b.get("type") == "dielectric" and o["shape"]["type"] == "rectangle" and dispersion.is_model(b.get("int_ior")):
            # the closed form takes one IOR; a dispersive one is said so, not approximated
            out.append(_probe(f"reflection {o['name']}", None, None, None, "sigma", None,
                              reason="dispersive int_ior: the Fresnel probe needs a constant IOR"))
    for di in dielectrics:
        for li in lights:
            mask, factor, eta, cos_i = _expected(scene, di, li, w, h, pol)
            label = f"{objs[di]['name']} reflecting {objs[li]['name']}"
            extra = {"brewster_deg": float(np.degrees(np.arctan(eta))), "pixels": int(mask.sum())}
            if mask.any():
                extra["incidence_deg"] = [float(np.degrees(np.arccos(cos_i[mask].max()))),
                                          float(np.degrees(np.arccos(cos_i[mask].min())))]
            name = f"brewster {label}, polariser {pol['angle']:g} deg" if pol else f"reflection {label}"
            if mask.sum() < MIN_PIXELS:
                out.append(_probe(name, None, None, None, "relative", None, **extra))
                continue
            if pol or not stokes:
                measured_px = image[mask][:, :3].astype(np.float64)
            else:
                measured_px = image[mask][:, [names.index(f"S{k}.{c}") for k in range(3) for c in "RGB"]]
                measured_px = measured_px.astype(np.float64)

            def judged(obs):
                light = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(objs[li]["emitter"]["radiance"], obs=obs))
                expected_px = (factor[mask][:, :, None] * light[None, None, :]).reshape(measured_px.shape)
                se = (measured_px - expected_px).std(axis=0, ddof=1) / np.sqrt(len(measured_px))
                return stats.compare_means(measured_px.mean(axis=0), expected_px.mean(axis=0), se,
                                           dof=len(measured_px) - 1)
            stat = judged(colorimetry.GROUND_TRUTH)
            alternatives = {o: judged(o) for o in m.observers if o != colorimetry.GROUND_TRUTH}
            exp_mean, meas_mean = np.array(stat["expected"][:3]), np.array(stat["measured"][:3])
            rel = float(np.sum(meas_mean) / max(np.sum(exp_mean), 1e-30) - 1.0)
            out.append(_probe(name, exp_mean, meas_mean, rel, "relative", stat["pass"], z=stat["z"], stat=stat,
                              alternatives=alternatives, **extra))
            if stokes and not pol:
                s0 = image[mask][:, names.index("S0.G")].mean()
                s_vec = [image[mask][:, names.index(f"S{k}.G")].mean() for k in (1, 2, 3)]
                dop_e = float(np.hypot(factor[mask][:, 1].mean(), factor[mask][:, 2].mean()) / factor[mask][:, 0].mean())
                dop_m = float(np.linalg.norm(s_vec) / s0)
                out.append(_probe(f"degree of polarisation, {label}", dop_e, dop_m, dop_m - dop_e, "", stat["pass"],
                                  note="judged through the Stokes channels of the reflection probe", **extra))
    return out
