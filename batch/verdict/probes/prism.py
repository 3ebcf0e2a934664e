"""A collimated beam through a dispersive dielectric onto a diffuse screen (the dispersion case):
where each wavelength lands follows from Snell's law with the scene's own n(lambda), and how much
of the beam arrives from the Fresnel equations. Plain numpy, from the IR alone.

Ground truth. The beam is the IR's collimated rectangle (irradiance E(l) across it, area A). Its
four corner rays are traced per wavelength (1 nm, 360-830 nm) through the dielectric's faces by
Snell's law (Hecht, Optics, eq. 4.4) to the first opaque surface, which must be a diffuse
rectangle (the screen), all four on it. The beam stays a parallel beam through plane faces, so
each wavelength lights a parallelogram of area A_s(l) on the screen with irradiance
E(l) T(l) A / A_s(l), where T(l) is the transmittance of the path: Fresnel's Ts and Tp at each
interface (Hecht, eq. 4.42-4.43), with unpolarised light Ts and Tp are carried separately through
the interfaces (T = (Ts1 Ts2 + Tp1 Tp2) / 2 when the planes of incidence coincide, as in a
prism's principal section; an unpolarised renderer multiplies the two means instead: ``T_unpolarised``
records that value). The screen (reflectance rho) shows radiance rho/pi times that irradiance, so
the expected image is, per pixel and sRGB channel c,
    I_c(px) = sum_l dl w_c(l) rho/pi E(l) T(l) A / A_s(l) * coverage(px, quad(l)),
with w_c the CIE 1931 CMFs turned to linear sRGB (as colorimetry.py, Y of a flat 1 is 1) and
coverage the exact fraction of the pixel (box filter) covered by the parallelogram's image, a quad
(a pinhole camera maps lines to lines): pixel squares clipped by the quad's four edges. The beam's
width and the pixel footprint are thus integrated exactly, not evaluated at pixel centres.

Two probes, judged on the render's own noise (per-pixel standard error from independent passes;
without passes, the squared residual against the expected image, unbiased under the hypothesis):
- positions: the rendered colours run in the right order across the screen (the channels'
  centroids along the direction of increasing deviation are ordered as expected) and each
  channel's band is where Snell's law puts it: the centroid of channel c along that direction,
  sum s I_c / sum I_c, against the same statistic of the expected image. The test statistic is
  the linear sum_px (s - s_expected) I_c(px), zero in expectation, with variance
  sum_px (s - s_expected)^2 sigma_px^2. Its tolerance follows from the beam width and the pixel
  size through that variance: a band w pixels wide and h tall whose pixels have relative noise
  r gives a centroid standard error of about r * sqrt((w^2 / 12 + spread^2) / (w h)) pixels
  (spread: the fan's own extent); with the beam width and the pixel footprint integrated exactly
  (above), nothing but noise remains to tolerate (benchmarks/CALIBRATION.md, "Dispersion").
- energy: the flux on the screen, (pi/rho) sum_px I_c(px) a_px over the pixels that see the
  screen (a_px: the pixel's footprint on the screen plane), equals sum_l dl w_c(l) E(l) A T(l):
  the beam's flux times the prism's Fresnel transmittance. The footprint sum's own error (the
  image-to-screen Jacobian varies inside a pixel) is computed on the expected image and added to
  the tolerance (``model_error``).
Both use the Sidak-corrected p-value of stats.py over the three channels, from Student's t with
the Welch-Satterthwaite degrees of freedom of the estimated variance (each pixel's variance
counted with one degree of freedom, as from two passes: conservative with more).
"""
import math

import numpy as np

from ....exporters import colorimetry, dispersion, mesh_io, spectra
from .. import raycast, stats
from ..optics import fresnel_dielectric
from .common import MIN_PIXELS, probe as _probe

STEP_NM = 1.0
MAX_EVENTS = 8  # interfaces a beam corner may cross before reaching the screen


def _triangles(shape, base_dir=None):
    v, f = mesh_io.load_mesh(shape, base_dir)
    v = np.asarray(v, dtype=np.float64)
    if "to_world" in shape:
        m = np.asarray(shape["to_world"], dtype=np.float64)
        v = v @ m[:3, :3].T + m[:3, 3]
    return v[np.asarray(f, dtype=np.int64)]  # (T, 3, 3)


@np.errstate(divide="ignore", invalid="ignore")
def _hit_triangles(tris, origin, dirs):
    """(t, unit face normal) of the nearest triangle hit per ray (Moller-Trumbore); t = inf if none."""
    o = np.broadcast_to(origin, dirs.shape)
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = np.cross(dirs[:, None, :], e2[None])
    det = np.sum(e1[None] * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o[:, None, :] - tris[None, :, 0]
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1[None])
        v = np.sum(dirs[:, None, :] * q, axis=-1) * inv
        t = np.sum(e2[None] * q, axis=-1) * inv
    ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
    t = np.where(ok, t, np.inf)
    k = np.argmin(t, axis=1)
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return t[np.arange(len(k)), k], n[k]


def _nearest(objs, base_dir, origin, dirs, skip=None):
    """(object index or -1, t, unit geometric normal) per ray, meshes included; object ``skip``
    (the beam's own rectangle) is transparent."""
    ts, ns = [], []
    for k, obj in enumerate(objs):
        s = obj["shape"]
        if k == skip:
            t, n = np.full(dirs.shape[0], np.inf), np.zeros_like(dirs)
        elif s["type"] == "mesh":
            t, n = _hit_triangles(_triangles(s, base_dir), origin, dirs)
        else:
            t = raycast.hit(s, origin, dirs)
            if s["type"] == "rectangle":
                n = np.broadcast_to(raycast.rectangle_frame(s)[1], dirs.shape)
            else:
                p = origin + np.where(np.isfinite(t), t, 0)[:, None] * dirs
                n = (p - np.asarray(s["center"], dtype=np.float64)) / s["radius"]
        ts.append(t)
        ns.append(n)
    ts = np.stack(ts)
    idx = np.argmin(ts, axis=0)
    t = ts[idx, np.arange(dirs.shape[0])]
    n = np.stack(ns)[idx, np.arange(dirs.shape[0])]
    return np.where(np.isfinite(t), idx, -1), t, n


def fresnel_ts_tp(cos_i, eta):
    """(Ts, Tp, cos_t) for light from the side of cos_i > 0 into relative index eta (n_t / n_i)."""
    rs, rp = fresnel_dielectric(cos_i, eta)  # both 1 under total internal reflection
    cos_t = np.sqrt(np.clip(1 - (1 - cos_i ** 2) / eta ** 2, 0, 1))
    return 1 - rs, 1 - rp, cos_t


def trace_beam(scene, wavelengths, points):
    """Trace rays of the collimated beam, one per (wavelength, point of its rectangle in local
    [-1, 1]^2 coordinates), always refracting at dielectrics. Returns a dict with the beam's
    object index, direction, area, irradiance spectrum, and per ray the landing object, point,
    the transmittances T (unpolarised input, s/p carried separately) and T_unpolarised
    (product of per-interface means), and the number of interfaces crossed."""
    objs = scene["objects"]
    beams = [i for i, o in enumerate(objs) if (o.get("emitter") or {}).get("type") == "collimated"]
    if len(beams) != 1:
        return None
    bi = beams[0]
    m = np.asarray(objs[bi]["shape"]["to_world"], dtype=np.float64)
    direction = raycast.rectangle_frame(objs[bi]["shape"])[1]
    area = 4.0 * np.linalg.norm(np.cross(m[:3, 0], m[:3, 1]))
    pts = np.array([m[:3, :3] @ [x, y, 0.0] + m[:3, 3] for x, y in points])
    wl = np.asarray(wavelengths, dtype=np.float64)
    nl, npt = len(wl), len(pts)
    origin = np.repeat(pts[None], nl, axis=0).reshape(-1, 3) + 1e-7 * direction
    d = np.tile(direction, (nl * npt, 1))
    lam = np.repeat(wl, npt)
    alive = np.ones(len(d), dtype=bool)
    i_s, i_p = np.full(len(d), 0.5), np.full(len(d), 0.5)
    t_unpol = np.ones(len(d))
    s_axis = np.zeros((len(d), 3))
    events = np.zeros(len(d), dtype=int)
    landing = np.full(len(d), -1)
    point = np.full((len(d), 3), np.nan)
    base = scene.get("_base_dir")
    for _ in range(MAX_EVENTS + 1):
        todo = np.flatnonzero(alive)
        if not len(todo):
            break
        who, t, n = _nearest(objs, base, origin[todo], d[todo], skip=bi)
        p = origin[todo] + np.where(np.isfinite(t), t, 0)[:, None] * d[todo]
        for k in np.unique(who):
            sel = who == k
            rays = todo[sel]
            if k < 0:
                alive[rays] = False  # left the scene
                continue
            b = objs[k].get("bsdf") or {}
            if b.get("type") != "dielectric":
                alive[rays] = False
                landing[rays], point[rays] = k, p[sel]
                continue
            nn = n[sel]
            cos = -np.sum(d[rays] * nn, axis=-1)
            entering = cos > 0
            nn = np.where(entering[:, None], nn, -nn)
            cos = np.abs(cos)
            n_in = dispersion.ior(b["int_ior"], lam[rays]) / b.get("ext_ior", 1.000277)
            eta = np.where(entering, n_in, 1.0 / n_in)
            ts, tp, cos_t = fresnel_ts_tp(cos, eta)
            # s is across the plane of incidence; the light's s/p intensities turn into the new frame
            s_new = np.cross(d[rays], nn)
            norm = np.linalg.norm(s_new, axis=-1, keepdims=True)
            s_new = np.where(norm > 1e-12, s_new / np.maximum(norm, 1e-300), s_axis[rays])
            c2 = np.where(np.linalg.norm(s_axis[rays], axis=-1) > 0, np.sum(s_axis[rays] * s_new, axis=-1) ** 2, 1.0)
            a_s = i_s[rays] * c2 + i_p[rays] * (1 - c2)
            a_p = i_s[rays] * (1 - c2) + i_p[rays] * c2
            i_s[rays], i_p[rays] = a_s * ts, a_p * tp
            t_unpol[rays] *= (ts + tp) / 2
            s_axis[rays] = s_new
            d_new = d[rays] / eta[:, None] + (cos / eta - cos_t)[:, None] * nn
            d[rays] = d_new / np.linalg.norm(d_new, axis=-1, keepdims=True)
            origin[rays] = p[sel] + 1e-7 * d[rays]
            events[rays] += 1
            alive[rays] &= (ts + tp) > 0  # total internal reflection: this path carries nothing
    shape = (nl, npt)
    return {"beam": bi, "direction": direction, "area": area, "irradiance": objs[bi]["emitter"]["irradiance"],
            "landing": landing.reshape(shape), "point": point.reshape(shape + (3,)),
            "T": (i_s + i_p).reshape(shape), "T_unpolarised": t_unpol.reshape(shape),
            "events": events.reshape(shape)}


def project(camera, width, height, points):
    """Image coordinates (x right, y down, in pixels; pixel (0, 0) spans [0, 1]^2) of world points."""
    m = np.asarray(camera["to_world"], dtype=np.float64)
    inv = np.linalg.inv(m)
    local = points @ inv[:3, :3].T + inv[:3, 3]
    t = math.tan(math.radians(camera["fov"]) / 2)
    tx, ty = (t, t * height / width) if camera.get("fov_axis", "x") == "x" else (t * width / height, t)
    xn, yn = local[..., 0] / (-local[..., 2] * tx), local[..., 1] / (-local[..., 2] * ty)
    return np.stack([(xn + 1) / 2 * width, (1 - yn) / 2 * height], axis=-1)


@np.errstate(divide="ignore", invalid="ignore")
def _clip_boxes(x0, y0, quad):
    """Area of each unit pixel box [x0, x0+1] x [y0, y0+1] inside the convex quad (4 x 2, either
    orientation; or one quad per box, n x 4 x 2): Sutherland-Hodgman, vectorised over boxes (each
    box's arithmetic is the same whichever boxes share the call)."""
    n = len(x0)
    px = np.stack([x0, x0 + 1, x0 + 1, x0], axis=1).astype(np.float64)
    py = np.stack([y0, y0, y0 + 1, y0 + 1], axis=1).astype(np.float64)
    count = np.full(n, 4)
    q = np.broadcast_to(np.asarray(quad, dtype=np.float64), (n, 4, 2))
    orient = np.sign(np.sum(q[..., 0] * np.roll(q[..., 1], -1, axis=-1) - np.roll(q[..., 0], -1, axis=-1) * q[..., 1],
                            axis=-1))
    rows = np.arange(n)
    for e in range(4):
        ax, ay = q[:, e, 0], q[:, e, 1]
        bx, by = q[:, (e + 1) % 4, 0], q[:, (e + 1) % 4, 1]
        k_max = px.shape[1]
        ox, oy = np.zeros((n, k_max + 1)), np.zeros((n, k_max + 1))
        oc = np.zeros(n, dtype=int)
        side = lambda x, y: orient * ((bx - ax) * (y - ay) - (by - ay) * (x - ax))  # >= 0: inside
        for k in range(k_max):
            valid = k < count
            nxt = np.where(k + 1 < count, k + 1, 0)
            cx, cy = px[:, k], py[:, k]
            nx, ny = px[rows, nxt], py[rows, nxt]
            dc, dn = side(cx, cy), side(nx, ny)
            keep = valid & (dc >= 0)
            ox[rows[keep], oc[keep]], oy[rows[keep], oc[keep]] = cx[keep], cy[keep]
            oc += keep
            cross = valid & ((dc >= 0) != (dn >= 0))
            with np.errstate(divide="ignore", invalid="ignore"):
                f = dc / (dc - dn)
            ix, iy = cx + f * (nx - cx), cy + f * (ny - cy)
            ox[rows[cross], oc[cross]], oy[rows[cross], oc[cross]] = ix[cross], iy[cross]
            oc += cross
        px, py, count = ox, oy, oc
    k = np.arange(px.shape[1])[None, :]
    nxt = np.where(k + 1 < count[:, None], k + 1, 0)
    valid = k < count[:, None]
    area = np.where(valid, px * np.take_along_axis(py, nxt, 1) - np.take_along_axis(px, nxt, 1) * py, 0.0)
    return np.abs(area.sum(axis=1)) / 2


BOXES_PER_CALL = 1 << 16  # pixel boxes clipped in one call (bounded memory: about 10 arrays of n x 8)


def _beam_coverage(quads, lit, width, height):
    """[(k, y0, y1, x0, x1, coverage of each pixel of that window by quad k)] for the wavelengths
    ``lit``, in their order: the boxes of many wavelengths clipped together (_clip_boxes), each
    exactly as on its own."""
    windows = []
    for k in lit:
        q = quads[k]
        x0, x1 = int(max(0, math.floor(q[:, 0].min()))), int(min(width, math.ceil(q[:, 0].max())))
        y0, y1 = int(max(0, math.floor(q[:, 1].min()))), int(min(height, math.ceil(q[:, 1].max())))
        if x1 > x0 and y1 > y0:
            windows.append((k, y0, y1, x0, x1))
    out, batch = [], []

    def flush():
        if not batch:
            return
        grids = [np.meshgrid(np.arange(x0, x1), np.arange(y0, y1)) for _, y0, y1, x0, x1 in batch]
        gx, gy = (np.concatenate([g[i].ravel() for g in grids]) for i in (0, 1))
        sizes = [(y1 - y0) * (x1 - x0) for _, y0, y1, x0, x1 in batch]
        per_box = np.repeat(np.stack([quads[k] for k, *_ in batch]), sizes, axis=0)
        cov = np.split(_clip_boxes(gx, gy, per_box), np.cumsum(sizes)[:-1])
        out.extend((k, y0, y1, x0, x1, c.reshape(y1 - y0, x1 - x0)) for (k, y0, y1, x0, x1), c in zip(batch, cov))
        batch.clear()
    boxes = 0
    for w in windows:
        size = (w[2] - w[1]) * (w[4] - w[3])
        if batch and boxes + size > BOXES_PER_CALL:
            flush()
            boxes = 0
        batch.append(w)
        boxes += size
    flush()
    return out


def _channel_weights(wl, obs=colorimetry.GROUND_TRUTH):
    """w_c(l) dl: linear sRGB of the observer's CMFs over its normalisation (Y of a flat 1 is 1),
    times the trapezoid rule's weights on the grid ``wl`` (as colorimetry.xyz)."""
    cwl, xb, yb, zb, norm = colorimetry.observer(obs)
    cmf = np.stack([np.interp(wl, cwl, c) for c in (xb, yb, zb)], axis=-1)
    rgb = colorimetry.xyz_to_srgb(cmf) / norm
    trap = np.zeros(len(wl))
    trap[1:] += np.diff(wl) / 2
    trap[:-1] += np.diff(wl) / 2
    return rgb * trap[:, None]


def screen_pixels(scene, width, height, screen):
    """Mask of pixels whose four corners see the screen first (meshes included) and the area of
    each pixel's footprint on the screen plane."""
    cam, objs = scene["camera"], scene["objects"]
    origin, dirs = raycast.camera_rays(cam, width, height, "corners")
    flat = dirs.reshape(-1, 3)
    who, t, _ = _nearest(objs, scene.get("_base_dir"), origin, flat)
    ok = (who == screen).reshape(height + 1, width + 1)
    mask = ok[:-1, :-1] & ok[1:, :-1] & ok[:-1, 1:] & ok[1:, 1:]
    c, nrm, _, _ = raycast.rectangle_frame(objs[screen]["shape"])
    tp = ((c - origin) @ nrm) / (flat @ nrm)
    p = (origin + tp[:, None] * flat).reshape(height + 1, width + 1, 3)
    d1, d2 = p[1:, 1:] - p[:-1, :-1], p[:-1, 1:] - p[1:, :-1]
    area = 0.5 * np.linalg.norm(np.cross(d1, d2), axis=-1)
    return mask, area


def expected(scene, width, height, step_nm=STEP_NM):
    """The ground truth of a prism scene at ``width`` x ``height`` or None if it does not apply:
    dict with the expected image (H x W x 3), the screen mask and footprints, the per-wavelength
    band centres (image coordinates), the flux per channel and the transmittance."""
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    wl = np.arange(spectra.LAMBDA_MIN, spectra.LAMBDA_MAX + 0.5 * step_nm, step_nm)
    tr = trace_beam(scene, wl, corners + [(0, 0)])
    if tr is None:
        return None
    objs = scene["objects"]
    screens = set(tr["landing"][:, :4].ravel().tolist())
    lit = tr["T"][:, 4] > 0
    if len(screens) != 1 or -1 in screens or not lit.any():
        return {"error": "the beam does not land whole on one opaque surface at every wavelength"}
    screen = screens.pop()
    sb = objs[screen].get("bsdf") or {}
    if objs[screen]["shape"]["type"] != "rectangle" or sb.get("type") != "diffuse":
        return {"error": f"the beam lands on {objs[screen]['name']}, which is not a diffuse rectangle"}
    if (tr["events"][:, :4] != tr["events"][:, :1]).any():
        return {"error": "the beam's corners cross different faces (the beam is clipped by an edge)"}
    rho = spectra.evaluate(sb["reflectance"], wl)
    e = spectra.evaluate(tr["irradiance"], wl)
    cam = scene["camera"]
    quads = project(cam, width, height, tr["point"][:, :4])  # (L, 4, 2)
    pts = tr["point"][:, :4]
    area_s = 0.5 * np.linalg.norm(np.cross(pts[:, 2] - pts[:, 0], pts[:, 3] - pts[:, 1]), axis=-1)
    # flux per nm, T of the central ray (every ray of a parallel beam through plane faces has it)
    t = tr["T"][:, 4]
    radiance = rho / math.pi * e * t * tr["area"] / area_s
    w = _channel_weights(wl)
    img = np.zeros((height, width, 3))
    for k, y0, y1, x0, x1, cov in _beam_coverage(quads, np.flatnonzero(t > 0), width, height):
        img[y0:y1, x0:x1] += cov[..., None] * (radiance[k] * w[k])[None, None, :]
    mask, footprint = screen_pixels(scene, width, height, screen)
    inside = np.ones(len(wl), dtype=bool)
    for k in range(len(wl)):
        q = quads[k]
        ix = np.clip(np.floor(q[:, 0]).astype(int), 0, width - 1)
        iy = np.clip(np.floor(q[:, 1]).astype(int), 0, height - 1)
        inside[k] = (q[:, 0] > 0).all() and (q[:, 0] < width).all() and (q[:, 1] > 0).all() \
            and (q[:, 1] < height).all() and mask[iy, ix].all()
    flux = np.sum((e * tr["area"] * t)[:, None] * w, axis=0)
    flux_unpol = np.sum((e * tr["area"] * tr["T_unpolarised"][:, 4])[:, None] * w, axis=0)
    # the same flux as films with other observers integrate it (known deviations re-judge with these)
    flux_by_observer = {o: np.sum((e * tr["area"] * t)[:, None] * _channel_weights(wl, o), axis=0)
                        for o in colorimetry.OBSERVERS}
    centres = quads.mean(axis=1)
    fan = centres[np.argmin(np.abs(wl - 420))] - centres[np.argmin(np.abs(wl - 680))]
    spread = float(np.linalg.norm(fan))
    u = fan / spread if spread > 1e-6 else np.array([1.0, 0.0])
    along = (quads - centres[:, None, :]) @ u
    across = (quads - centres[:, None, :]) @ np.array([-u[1], u[0]])
    return {"fan_direction": u, "fan_spread_px": spread, "beam_width_px": float(np.median(np.ptp(along, axis=1))),
            "band_height_px": float(np.median(np.ptp(across, axis=1))),
            "image": img, "mask": mask, "footprint": footprint, "screen": screen, "rho": rho,
            "wavelengths": wl, "centres": centres, "T": t, "flux": flux, "flux_unpolarised": flux_unpol,
            "flux_by_observer": flux_by_observer,
            "inside": bool(inside.all()), "beam": objs[tr["beam"]]["name"], "screen_name": objs[screen]["name"]}


def _variance(m, residual):
    if m.stderr is not None:
        return np.asarray(m.stderr[..., :3], dtype=np.float64) ** 2
    return residual ** 2  # one pass: the squared residual, unbiased for the variance under H0


def _linear_test(a, v):
    """(standard deviation, degrees of freedom) of sum_px a_px x_px for independent pixels whose
    variances v_px are estimated each with one degree of freedom (two passes, or one squared
    residual: the worst case, conservative with more passes): Welch-Satterthwaite."""
    terms = a ** 2 * v
    return math.sqrt(float(np.sum(terms))), float(stats.satterthwaite_dof(terms, np.ones_like(terms)))


def _positions(label, gt, s, meas, exp_img, var, threshold):
    """The band-position probe: colour order and each channel's centroid along the fan."""
    name = f"prism band positions, {label}"
    if gt["fan_spread_px"] < 0.5:
        return _probe(name, None, None, None, "sigma", None,
                      reason=f"the fan spans {gt['fan_spread_px']:.2g} px: no colour order to measure")
    exp_pos, meas_pos, se_pos, z_pos, dofs = [], [], [], [], []
    for ch in range(3):
        e_c, m_c, v_c = exp_img[:, ch], meas[:, ch], var[:, ch]
        s_exp = float(np.sum(s * e_c) / np.sum(e_c))
        total = float(np.sum(m_c))
        stat = float(np.sum((s - s_exp) * m_c))  # zero in expectation at the expected centroid
        sd, dof = _linear_test(s - s_exp, v_c)
        exp_pos.append(s_exp)
        if total <= 5 * math.sqrt(float(np.sum(v_c))):  # no light where the channel expects its band
            meas_pos.append(math.nan)
            se_pos.append(None)
            z_pos.append(math.inf)
            dofs.append(None)
            continue
        meas_pos.append(s_exp + stat / total)
        se_pos.append(sd / total)
        z_pos.append(abs(stat) / max(sd, 1e-300))
        dofs.append(dof)
    p_pos = [float(stats.two_sided_p(z, d)) if math.isfinite(z) else 0.0 for z, d in zip(z_pos, dofs)]
    order_exp = "".join("RGB"[i] for i in np.argsort(exp_pos))
    order_meas = "".join("RGB"[i] for i in np.argsort(meas_pos)) if not np.isnan(meas_pos).any() else "?"
    c, wl, u = gt["centres"], gt["wavelengths"], gt["fan_direction"]
    c550 = c[np.argmin(np.abs(wl - 550))]
    lines = {k: float((c[np.argmin(np.abs(wl - v))] - c550) @ u) for k, v in dispersion.FRAUNHOFER_NM.items()}
    return _probe(name, exp_pos, meas_pos, float(max(z_pos)), "sigma",
                  bool(order_meas == order_exp and min(p_pos) >= threshold),
                  unit_positions="px along the fan (towards more deviation) from 550 nm's band centre",
                  standard_error_px=se_pos, dof=dofs, p_min=float(min(p_pos)), threshold=threshold,
                  order_expected=order_exp, order_measured=order_meas, fraunhofer_px=lines,
                  beam_width_px=gt["beam_width_px"], fan_spread_px=gt["fan_spread_px"],
                  # where the positions lie in the image (the report marks them): position s is at
                  # origin_px + s * fan_direction (image x right, y down, pixels)
                  origin_px=[float(v) for v in c550], fan_direction=[float(v) for v in u],
                  band_height_px=gt["band_height_px"])


def _energy(label, gt, mask, meas, exp_img, var, observers):
    """The energy probe: the flux on the screen against the beam's times the transmittance, per
    channel (three tests, Sidak-corrected), with its verdict for each other observer."""
    name = f"prism energy, {label}"
    if np.ptp(gt["rho"]) > 0:
        return _probe(name, None, None, None, "sigma", None, reason="the screen's reflectance is not constant")
    scale = math.pi / float(np.mean(gt["rho"])) * gt["footprint"][mask]
    flux_m = np.sum(scale[:, None] * meas, axis=0)
    flux_e = gt["flux"]
    model = np.abs(np.sum(scale[:, None] * exp_img, axis=0) - flux_e)  # the footprint sum's own error
    se_dof = [_linear_test(scale, var[:, c]) for c in range(3)]
    se, dof = np.array([x[0] for x in se_dof]), np.array([x[1] for x in se_dof])
    se_all = np.sqrt(se ** 2 + model ** 2)

    def judged(obs):
        return stats.compare_means(flux_m, gt["flux_by_observer"][obs], se_all, dof=dof)

    stat = judged(colorimetry.GROUND_TRUTH)
    alternatives = {o: judged(o) for o in observers if o != colorimetry.GROUND_TRUTH}
    return _probe(name, flux_e, flux_m, stat["z"], "sigma", stat["pass"], stat=stat, alternatives=alternatives,
                  standard_error=se.tolist(), dof=dof.tolist(), model_error=model.tolist(),
                  relative_error=((flux_m - flux_e) / flux_e).tolist(),
                  flux_unpolarised=gt["flux_unpolarised"].tolist(), p_min=stat["p"], threshold=stat["threshold"],
                  transmittance_550nm=float(gt["T"][np.argmin(np.abs(gt["wavelengths"] - 550))]))


def probes(m):
    """The position and energy probes of a prism scene; [] for other scenes."""
    scene, image = m.scene, np.asarray(m.image, dtype=np.float64)
    if not any((o.get("emitter") or {}).get("type") == "collimated" for o in scene["objects"]):
        return []
    h, w = image.shape[:2]
    gt = expected(scene, w, h)
    if gt is None:
        return []
    if "error" in gt:
        return [_probe("prism band positions", None, None, None, "sigma", None, reason=gt["error"])]
    label = f"{gt['beam']} on {gt['screen_name']}"
    mask = gt["mask"]
    if not gt["inside"] or mask.sum() < MIN_PIXELS:
        return [_probe(f"prism band positions, {label}", None, None, None, "sigma", None,
                       reason="the fan does not lie whole inside the screen's visible pixels")]
    meas, exp_img = image[..., :3][mask], gt["image"][mask]
    var = _variance(m, image[..., :3] - gt["image"])[mask]
    ys, xs = np.nonzero(mask)
    c, wl = gt["centres"], gt["wavelengths"]
    s = (np.stack([xs + 0.5, ys + 0.5], axis=-1) - c[np.argmin(np.abs(wl - 550))]) @ gt["fan_direction"]
    threshold = stats.sidak_threshold(stats.ALPHA, 3)  # three channels per probe
    out = [_positions(label, gt, s, meas, exp_img, var, threshold),
           _energy(label, gt, mask, meas, exp_img, var, m.observers)]
    for record in out:
        record["pixels"] = int(mask.sum())
    return out
