"""Rough (Beckmann) conductor spheres, with or without a thin film, under a uniform environment of
radiance L(l), beside other passive objects (iridescent_spheres_film, _height, _materials: four
spheres before a diffuse backdrop): per pixel of a sphere an interval [lo, hi] that its expected
value must lie in, the sky's share exact, the light of every other object a bounded nuisance.

The BRDF (the IR's rough conductor; the film's Airy reflectance as the microfacet Fresnel factor,
Belcour and Barla 2017, "A practical extension to microfacet theory for the modeling of varying
iridescence", ACM TOG 36(4), sec. 3):

    f_r(w_i, w_o) = F(w_o . h, l) D(h) G(w_i, w_o) / (4 cos_i cos_o)      (Walter et al. 2007, eq. 20)

with D Beckmann's distribution of width alpha (Walter et al. 2007, eq. 25), G Smith's separable
G1(w_i) G1(w_o) with Beckmann's exact Lambda (Walter et al. 2007 eq. 23 and 25-26; Heitz 2014,
"Understanding the masking-shadowing function", eq. 69; batch/verdict/optics.py) and F the film's
unpolarised Airy reflectance (R_s + R_p) / 2 (Born and Wolf, Principles of Optics, 7th ed., 1.6.4
eq. 57-58; batch/verdict/airy.py; the bare conductor's Fresnel reflectance without a film, Born and
Wolf 14.2). A sphere's point is convex: no direction of its hemisphere meets the sphere again.

Sky only. With h the half vector, the Jacobian dw_i = 4 (w_o . h) dw_h (Walter et al. 2007 eq. 14)
turns the reflected radiance under a uniform sky into

    R(theta_o, l) L(l),   R = integral F D G (w_o . h) / cos_o dw_h   (over h with w_i above the horizon)

a function of the view angle alone (the sphere is isotropic): a table over theta_o. Beckmann's
D dw_h = exp(-u) du dphi / (2 pi cos theta_h) with u = tan^2 theta_h / alpha^2 (substitute in eq. 25),
so with u = s^2

    R = integral_0^inf integral_0^2pi  exp(-s^2) 2 s  F G (w_o . h) / (cos_o cos_h)  ds dphi / (2 pi),

computed by Gauss-Legendre in s on [0, S_MAX] and the trapezoid rule in phi (periodic: spectrally
accurate); the tail s > S_MAX is bounded (below). The spectrum enters through F alone, so the
table is a matrix of geometric weights (theta_o x cos(w_o . h)) times the linear sRGB colour of
F(cos, l) L(l) (the CIE 1931 CMFs, exporters/colorimetry.py) on a fine cos grid (linear
interpolation), computed once per alpha.

The nuisance. Directions of the lobe that meet another object (the backdrop, another sphere)
bring that object's radiance instead of the sky's. Every object here is passive and not
fluorescent with albedo <= 1 (diffuse reflectance <= 1; a microfacet conductor's F <= 1, G1 <= 1),
and the environment is the only source, so no radiance in the scene exceeds L(l) at any wavelength
(a surface sends at most its albedo times the largest radiance it receives). With W the occluded
part of the lobe's geometric weight (F set to 1: F <= 1),

    W = integral over occluded h of D G (w_o . h) / cos_o dw_h,

the truth lies in R L - Y with 0 <= Y(l) <= W L(l) per wavelength (the occluded directions bring
between nothing and the sky's radiance). The tail s > S_MAX adds Z with 0 <= Z <= T L,
T = exp(-u0) [sqrt(1 + a^2 u0) + a^2 / (2 sqrt(1 + a^2 u0))] / cos_o (u0 = S_MAX^2; F, G, w_o . h
<= 1 and 1 / cos_h = sqrt(1 + alpha^2 u) bounded by its tangent at u0, integrated against e^-u).
A linear sRGB channel c has weights w_c(l) of both signs, so

    lo_c = R_c - W (w_c+ . L) + T (w_c- . L),     hi_c = R_c - W (w_c- . L) + T (w_c+ . L).

W is a quadrature over the lobe (S_OCC x PHI_OCC nodes of the same rule, each node's direction
tested against every other object by ray casting: batch/verdict/raycast.py; a node next to an
occluded one counts as occluded, so that the occluded region's edge, which the rule resolves only
to a node, is covered: measured, W so grown is at least the plain rule's W with 3 x the nodes in
each axis, and about twice it), taken at the corners
of cells of c x c pixels (c = 1 up to W_GRID pixels across, so that its cost does not grow with the
image) and the largest of a pixel's cell's four corners used (W is smooth and small where pixels
are judged; measured on iridescent_spheres_film at 800 x 256, c = 4: at 4 points inside each of
2,360 judged pixels W by a 2 x finer rule without growing is nowhere above the pixel's W, and
about 1/30 of it at the median). A point whose whole lobe (the cone of half-angle 2 atan(alpha S_MAX) about the mirror
direction: reflecting about a normal tilted by theta_h turns the reflection by at most 2 theta_h)
meets no object's bounding cone (a sphere's angular radius; a rectangle's plane) has W = 0 without
casting a ray.
R is averaged over the pixel's footprint (box filter) by a FOOTPRINT x FOOTPRINT Gauss-Legendre
rule of sub-rays.

Judged on the render's own noise, on the pixels where the bound leaves power: those whose
interval is narrow ((hi - lo) / lo <= WIDTH_MAX in every channel, chosen from the scene alone) and
whose view is not grazing (cos theta_o >= COS_MIN at every corner, where Mitsuba's rational
approximation of Beckmann's G1, < 0.35 % off the exact form, Walter et al. 2007 eq. 27, could
matter). Per sphere one record: the judged pixels' mean per channel tested one-sided against their
mean lo (too dark) and mean hi (too bright), the standard error from the pixels' residuals to lo
(Student's t, n - 1), and the same per image tile (TILE x TILE pixels, at least MIN_TILE judged:
a film's colour changes across the sphere, so a local error shows in a tile), Sidak over all the
tests (region and tiles, 3 channels, 2 sides) at stats.ALPHA. ``detectable``: how far (relative)
beyond the interval the region's mean must lie, in its best channel, for the test to fail with 90 %
power; ``width``: the interval's relative width there (a change smaller than width + detectable may
stay inside the interval); ``unjudged``: the sphere's whole pixels left out (interval too wide or
view grazing).
"""
import numpy as np

from ....exporters import colorimetry, spectra
from .. import airy, optics, raycast, stats
from .common import MIN_PIXELS, probe as _probe, remembered

S_MAX = 3.5          # the lobe's quadrature in s = tan(theta_h) / alpha up to S_MAX (tail e^-12.25 bounded)
S_NODES, PHI_NODES = 48, 96      # the table's nodes
S_OCC, PHI_OCC = 24, 48          # the occluded weight's nodes (a bound's part, smaller)
THETA_TABLE = 1025   # theta_o samples of the table on [0, pi/2]
COS_TABLE = 4097     # cos(w_o . h) samples of the Fresnel colour table on [0, 1]
FOOTPRINT = 4        # Gauss-Legendre sub-rays per pixel axis for R's footprint mean
WIDTH_MAX = 0.01     # a pixel is judged where its interval's relative width is at most this in every channel
COS_MIN = 0.3        # ... and its view is not grazing (the table's rule: 3e-5 at 70 degrees, 1.5e-4 at 75)
# tiles of 16 x 16 pixels with at least 128 judged: with 8 x 8 (>= 16) a 16 spp render failed one
# 32-pixel tile at z 5.0 where the 4096 spp reference passes (too few pixels for the t test's tail)
TILE, MIN_TILE = 16, 128
POWER = 0.9
CHUNK = 4096         # points per vectorised step of the occlusion quadrature
W_GRID = 256         # W is computed on cells of c x c pixels, c = ceil(max(width, height) / W_GRID)


def applies(scene):
    """Indices of the rough Beckmann conductor spheres (film or bare) when ``scene`` has a uniform
    environment, no other light, and only passive, non-fluorescent spheres and rectangles (diffuse
    with reflectance <= 1, or conductors), so that no radiance exceeds the sky's; else []."""
    env = scene.get("environment")
    if not env or env.get("type", "uniform") != "uniform" or scene.get("lights"):
        return []
    found = []
    for i, o in enumerate(scene["objects"]):
        b = o.get("bsdf") or {}
        if o.get("emitter") or o["shape"]["type"] not in ("sphere", "rectangle"):
            return []
        if b.get("type") == "diffuse":
            if b.get("fluorescence") is not None:
                return []
            wl = spectra.cie_1931_cmfs()[0]
            if np.max(spectra.evaluate(b["reflectance"], wl)) > 1.0:
                return []
        elif b.get("type") != "conductor":
            return []
        rough = b.get("roughness") or {}
        if (b.get("type") == "conductor" and o["shape"]["type"] == "sphere" and rough.get("alpha", 0) > 0
                and rough.get("distribution") == "beckmann"):
            found.append(i)
    cam = np.asarray(scene["camera"]["to_world"], dtype=np.float64)[:3, 3]
    return [i for i in found if np.linalg.norm(cam - np.asarray(scene["objects"][i]["shape"]["center"]))
            > scene["objects"][i]["shape"]["radius"]]


def _nodes(n_s, n_phi):
    """(s, phi, weight) of the lobe's rule: Gauss-Legendre in s on [0, S_MAX] times exp(-s^2) 2 s,
    the trapezoid rule in phi over [0, 2 pi) divided by 2 pi."""
    x, w = np.polynomial.legendre.leggauss(n_s)
    s, ws = (x + 1) * S_MAX / 2, w * S_MAX / 2
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi / n_phi)
    ss, pp = np.meshgrid(s, phi, indexing="ij")
    wt = (ws * np.exp(-s * s) * 2 * s)[:, None] * np.full(n_phi, 1.0 / n_phi)[None, :]
    return ss.ravel(), pp.ravel(), wt.ravel()


def _lobe(cos_o, alpha, n_s, n_phi):
    """For view cosines ``cos_o`` (P): the lobe's nodes in the local frame (normal z, w_o in the
    xz plane): (w_i (P x N x 3), cos(w_o . h) (P x N), geometric weight G (w_o . h) / (cos_o cos_h)
    times the rule's weight, 0 where w_i is below the horizon or w_o behind the microfacet)."""
    s, phi, wt = _nodes(n_s, n_phi)
    cos_o = np.asarray(cos_o, dtype=np.float64)[:, None]
    sin_o = np.sqrt(np.maximum(1 - cos_o * cos_o, 0.0))
    tan_h = alpha * s
    cos_h = 1 / np.sqrt(1 + tan_h * tan_h)
    sin_h = tan_h * cos_h
    h = np.stack([sin_h * np.cos(phi), sin_h * np.sin(phi), cos_h], axis=-1)[None]  # 1 x N x 3
    d = sin_o * h[..., 0] + cos_o * h[..., 2]  # w_o . h
    wi = 2 * d[..., None] * h - np.stack([sin_o, np.zeros_like(sin_o), cos_o], axis=-1)
    cos_i = wi[..., 2]
    ok = (d > 0) & (cos_i > 0)
    g = optics.shadowing("beckmann", np.where(ok, cos_i, 1.0), np.broadcast_to(cos_o, d.shape), alpha, "separable")
    geo = np.where(ok, g * d / (np.maximum(cos_o, 1e-300) * cos_h[None, :]) * wt[None, :], 0.0)
    return wi, np.clip(d, 0.0, 1.0), geo


@remembered(8)
def geometry_matrix(alpha):
    """(theta_o grid, THETA_TABLE x COS_TABLE matrix M): R(theta_o) = M @ F-colour(cos grid), the
    lobe's weights spread onto the cos grid by linear interpolation's hat functions."""
    theta = np.linspace(0.0, np.pi / 2, THETA_TABLE)
    m = np.zeros((THETA_TABLE, COS_TABLE))
    for t0 in range(0, THETA_TABLE, 64):
        t1 = min(THETA_TABLE, t0 + 64)
        _wi, d, geo = _lobe(np.cos(theta[t0:t1]), alpha, S_NODES, PHI_NODES)
        x = d * (COS_TABLE - 1)
        i = np.minimum(x.astype(np.intp), COS_TABLE - 2)
        f = x - i
        rows = np.arange(t0, t1)[:, None] - t0
        flat = (rows * COS_TABLE + i).ravel()
        block = np.bincount(flat, (geo * (1 - f)).ravel(), (t1 - t0) * COS_TABLE)
        block += np.bincount(flat + 1, (geo * f).ravel(), (t1 - t0) * COS_TABLE)
        m[t0:t1] = block.reshape(t1 - t0, COS_TABLE)
    return theta, m


def _eta_k(bsdf):
    """The base's eta and k: the IR's own spectra (a named conductor's IR carries its table too)."""
    if "eta" in bsdf and "k" in bsdf:
        return bsdf["eta"], bsdf["k"]
    return spectra.named_conductor(bsdf["material"])


@remembered(16)
def _base_side(eta, k, n1):
    """(n1 sin theta_1 on the COS_TABLE cosines (COS_TABLE x 1), the base's n3 = eta + i k (1 x the
    CMFs' wavelengths), q3 = n3 cos theta_3 (COS_TABLE x wavelengths)): the part of the Fresnel
    table that depends on the base and the exterior alone, computed as airy.py's functions do
    (reference_code/appearance.py ``_film_interfaces``, ``fresnel_amplitudes``). Spheres of one
    base share it, filmed or bare (the default suite's 12 rough spheres have 3 bases, 8 of them
    one: issue 45 item 1)."""
    wl = spectra.cie_1931_cmfs()[0]
    n3 = (spectra.evaluate(eta, wl) + 1j * spectra.evaluate(k, wl))[None, :]
    cos1 = np.clip(np.linspace(0.0, 1.0, COS_TABLE)[:, None], 0.0, 1.0)
    n1_sin1 = n1 * np.sqrt(1.0 - cos1**2)
    return n1_sin1, n3, airy.normal_cos(n3, n1_sin1)


@remembered(16)
def fresnel_table(bsdf):
    """(cos grid, wavelengths, F(cos, l)): the film's unpolarised Airy reflectance (or the bare
    conductor's Fresnel reflectance) on COS_TABLE cosines and the CMFs' 1 nm grid: the operations
    of airy.unpolarized_reflectance (bare_reflectance), the base's part taken from ``_base_side``
    (the same numbers: tests/probes/test_probe_speedups.py)."""
    wl = spectra.cie_1931_cmfs()[0]
    eta_s, k_s = _eta_k(bsdf)
    cos = np.linspace(0.0, 1.0, COS_TABLE)
    film = bsdf.get("thin_film")
    n1 = 1.0 if film is None else film.get("ext_ior", 1.0)
    n1_sin1, n3, q3 = _base_side(eta_s, k_s, n1)
    q1 = airy.normal_cos(n1, n1_sin1)
    if film is None:
        rs, rp = airy.fresnel(n1, q1, n3, q3)
    else:
        n2 = film["ior"]
        q2 = airy.normal_cos(n2, n1_sin1)
        rs, rp = airy.airy_sum((q2, airy.fresnel(n1, q1, n2, q2), airy.fresnel(n2, q2, n3, q3)), wl[None, :],
                               film["thickness"])
    return cos, wl, 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def weights(obs):
    """Linear sRGB weights (wavelengths x 3) of a spectrum on the CMF grid under observer ``obs``."""
    wl = spectra.cie_1931_cmfs()[0]
    return colorimetry.xyz_to_srgb(colorimetry.xyz_rows(np.eye(wl.size), obs))


@remembered(32)
def colour_table(bsdf, radiance, obs=colorimetry.GROUND_TRUTH):
    """(theta grid, R_rgb (THETA_TABLE x 3), L+ (3), L- (3)): the sky-only colour per view angle and
    the sky's colour against the weights' positive and negative parts (the nuisance's bounds)."""
    _cos, wl, f = fresnel_table(bsdf)
    light = spectra.evaluate(radiance, wl)
    w = weights(obs)
    theta, m = geometry_matrix(float(bsdf["roughness"]["alpha"]))
    rgb = m @ ((f * light[None, :]) @ w)
    return theta, rgb, light @ np.clip(w, 0, None), light @ np.clip(w, None, 0)


def tail_bound(cos_o, alpha):
    """T(cos_o): the lobe's weight beyond S_MAX with F, G and w_o . h set to 1 (module docstring)."""
    u0 = S_MAX * S_MAX
    q = np.sqrt(1 + alpha * alpha * u0)
    return np.exp(-u0) * (q + alpha * alpha / (2 * q)) / np.maximum(cos_o, 1e-300)


def _others(scene, index):
    return [o for j, o in enumerate(scene["objects"]) if j != index]


def _cone_free(points, mirror, others, half):
    """True where the cone of half-angle ``half`` about ``mirror`` meets none of ``others`` seen from
    ``points``: a sphere by its angular radius, a rectangle by its plane (the cone points away)."""
    free = np.ones(len(points), dtype=bool)
    for o in others:
        sh = o["shape"]
        if sh["type"] == "sphere":
            d = np.asarray(sh["center"], dtype=np.float64) - points
            dist = np.linalg.norm(d, axis=-1)
            ang = np.arccos(np.clip(np.sum(d * mirror, axis=-1) / dist, -1, 1))
            reach = np.arcsin(np.clip(sh["radius"] / dist, 0, 1))
            free &= ang > half + reach
        else:
            centre, normal, _hx, _hy = raycast.rectangle_frame(sh)
            side = np.sign((points - centre) @ normal)  # towards the plane: -side * normal
            towards = np.sum(mirror * (-side[:, None] * normal[None, :]), axis=-1)
            free &= towards < -np.sin(half)
    return free


def occluded_weight(scene, index, points, w_o, n_s=S_OCC, n_phi=PHI_OCC, grow=True):
    """W at sphere ``index``'s ``points`` (P x 3) seen along ``w_o`` (P x 3, towards the viewer):
    the lobe's geometric weight over the directions that meet another object (module docstring);
    ``grow``: count the occluded nodes' neighbours too (the probe's upper bound)."""
    obj = scene["objects"][index]
    alpha = float(obj["bsdf"]["roughness"]["alpha"])
    centre = np.asarray(obj["shape"]["center"], dtype=np.float64)
    n = (points - centre) / float(obj["shape"]["radius"])
    cos_o = np.clip(np.sum(n * w_o, axis=-1), 0.0, 1.0)
    mirror = 2 * cos_o[:, None] * n - w_o
    others = _others(scene, index)
    out = np.zeros(len(points))
    if not others:
        return out
    half = 2 * np.arctan(alpha * S_MAX)
    todo = np.nonzero(~_cone_free(points, mirror, others, half))[0]
    for c0 in range(0, len(todo), CHUNK // 4):
        k = todo[c0:c0 + CHUNK // 4]
        # the local frame: z = n, x = w_o's tangential part
        t1 = w_o[k] - cos_o[k, None] * n[k]
        norm = np.linalg.norm(t1, axis=-1)
        fallback = np.cross(n[k], np.where(np.abs(n[k, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
        t1 = np.where(norm[:, None] > 1e-9, t1 / np.maximum(norm, 1e-300)[:, None],
                      fallback / np.linalg.norm(fallback, axis=-1, keepdims=True))
        t2 = np.cross(n[k], t1)
        wi_local, _d, geo = _lobe(cos_o[k], alpha, n_s, n_phi)
        wi = wi_local[..., :1] * t1[:, None] + wi_local[..., 1:2] * t2[:, None] + wi_local[..., 2:] * n[k][:, None]
        origin = (points[k] + 1e-7 * n[k])[:, None, :]
        who, _t = raycast.nearest(others, origin, wi)
        # a node counts as occluded when it or a neighbour in s or phi is (phi wraps): the occluded
        # region's edge, which the rule resolves to a node, is then covered (an upper bound on W
        # wherever the region is wider than a node: tests/probes/test_rough_film.py)
        occ = (who >= 0).reshape(len(k), n_s, n_phi)
        grown = occ.copy()
        if grow:
            grown |= np.roll(occ, 1, axis=2) | np.roll(occ, -1, axis=2)
            grown[:, 1:] |= occ[:, :-1]
            grown[:, :-1] |= occ[:, 1:]
        out[k] = np.sum(np.where(grown.reshape(len(k), -1), geo, 0.0), axis=1)
    return out


def _footprint_cos(scene, index, ys, xs, w, h):
    """Per pixel (ys, xs) the cos theta_o of FOOTPRINT^2 Gauss-Legendre sub-rays (N x K), their
    weights (K), and whether every sub-ray meets the sphere first."""
    cam, objs = scene["camera"], scene["objects"]
    sph = objs[index]["shape"]
    centre = np.asarray(sph["center"], dtype=np.float64)
    offs = raycast.footprint_offsets(FOOTPRINT)
    cos, ok = np.zeros((len(ys), len(offs))), np.ones(len(ys), dtype=bool)
    for j, ((ox, oy), _wt) in enumerate(offs):
        origin, dirs = raycast.camera_rays_at(cam, w, h, xs + ox, ys + oy)
        who, t = raycast.nearest(objs, origin, dirs)
        ok &= who == index
        p = origin + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs
        cos[:, j] = np.clip(-np.sum(dirs * (p - centre), axis=-1) / sph["radius"], 0.0, 1.0)
    return cos, np.array([wt for _o, wt in offs]), ok


def _lookup(theta, table, cos, at=None):
    """A table over the uniform theta grid at cosines ``cos`` (any shape): linear interpolation.
    ``at``: ``_lookup_at(theta, cos)``, when several tables are looked up at the same cosines."""
    i, f = _lookup_at(theta, cos) if at is None else at
    return table[i] + f[..., None] * (table[i + 1] - table[i])


def _lookup_at(theta, cos):
    """(index, fraction) of cosines ``cos`` on the uniform theta grid: ``_lookup``'s search, the
    same for every table on that grid (the ground truth's and each observer's colour table)."""
    x = np.arccos(np.clip(cos, 0.0, 1.0)) * ((len(theta) - 1) / (np.pi / 2))
    i = np.minimum(x.astype(np.intp), len(theta) - 2)
    return i, x - i


def sphere_geometry(scene, index, w, h):
    """The scene-only part of a sphere's intervals at a w x h image: (ys, xs of the sphere's whole
    pixels, footprint cosines and weights, W and the smallest corner cosine per pixel). Costly (the
    occlusion quadrature): remembered per camera (the fields the ray casts read: not its name),
    shapes, sphere, roughness and size, so that one scene judged again (another backend, a planted
    error) pays once, and so do the default suite's iridescent_spheres_film, _height and
    _materials, which differ in their materials and camera names alone (issue 45 item 1: about
    1 s of CPU per sphere, 8 of the 12 spheres)."""
    objs = scene["objects"]
    alpha = float(objs[index]["bsdf"]["roughness"]["alpha"])
    return _geometry(raycast.camera_fields(scene["camera"]), [o["shape"] for o in objs], index, alpha, w, h)


@remembered(16)
def _geometry(cam, shapes, index, alpha, w, h):
    objs = [{"shape": sh, "bsdf": {"roughness": {"alpha": alpha}}} for sh in shapes]
    scene = {"camera": cam, "objects": objs}
    sph = objs[index]["shape"]
    centre = np.asarray(sph["center"], dtype=np.float64)
    origin, corners = raycast.camera_rays(cam, w, h, "corners")
    who, t = raycast.nearest(objs, origin, corners)
    on = who == index
    whole = on[:-1, :-1] & on[1:, :-1] & on[:-1, 1:] & on[1:, 1:]
    ys, xs = np.nonzero(whole)
    cos, wts, ok = _footprint_cos(scene, index, ys, xs, w, h)
    ys, xs, cos = ys[ok], xs[ok], cos[ok]
    # W and cos theta_o at the corners of the cells of c x c pixels that hold those pixels (c = 1 up
    # to W_GRID pixels across, so that the occlusion quadrature's cost is bounded whatever the size)
    c = max(1, -(-max(w, h) // W_GRID))
    gy, gx = np.arange(0, h + c, c)[: h // c + 2], np.arange(0, w + c, c)[: w // c + 2]
    used = np.zeros((len(gy), len(gx)), dtype=bool)
    for dy in (0, 1):
        for dx in (0, 1):
            used[ys // c + dy, xs // c + dx] = True
    cy, cx = np.nonzero(used)
    origin, dirs = raycast.camera_rays_at(cam, w, h, gx[cx], gy[cy])
    who_c, t_c = raycast.nearest(objs, origin, dirs)
    hit = who_c == index
    p = origin + np.where(hit, t_c, 0.0)[:, None] * dirs
    n = (p - centre) / sph["radius"]
    cos_c = np.full(used.shape, np.nan)
    cos_c[cy[hit], cx[hit]] = np.clip(-np.sum(dirs * n, axis=-1), 0.0, 1.0)[hit]
    w_c = np.full(used.shape, np.nan)
    w_c[cy[hit], cx[hit]] = occluded_weight(scene, index, p[hit], -dirs[hit])
    qy, qx = ys // c, xs // c
    quad = lambda a, f: f(np.stack([a[qy, qx], a[qy + 1, qx], a[qy, qx + 1], a[qy + 1, qx + 1]]), axis=0)  # noqa: E731
    return ys, xs, cos, wts, quad(w_c, np.max), quad(cos_c, np.min)


def intervals(scene, index, geometry, obs=colorimetry.GROUND_TRUTH, at=None):
    """(lo, hi) per pixel of ``geometry`` (sphere_geometry's) in linear sRGB (N x 3). ``at``: the
    footprint cosines' ``_lookup_at`` (the same for every observer's table: computed once)."""
    bsdf = scene["objects"][index]["bsdf"]
    theta, rgb, l_pos, l_neg = colour_table(bsdf, scene["environment"]["radiance"], obs)
    _ys, _xs, cos, wts, w_occ, cos_min = geometry
    r = np.einsum("nkc,k->nc", _lookup(theta, rgb, cos, at), wts)
    tail = tail_bound(cos_min, float(bsdf["roughness"]["alpha"]))
    lo = r - w_occ[:, None] * l_pos[None, :] + tail[:, None] * l_neg[None, :]
    hi = r - w_occ[:, None] * l_neg[None, :] + tail[:, None] * l_pos[None, :]
    return lo, hi


def _tiles(ys, xs):
    keys = (ys // TILE) * 100000 + xs // TILE
    out = []
    for key in np.unique(keys):
        idx = np.nonzero(keys == key)[0]
        if len(idx) >= MIN_TILE:
            out.append(idx)
    return out


def _judge(px, lo, hi, blocks, alpha):
    """One-sided tests of the region's and each tile's mean against the mean bounds (see module)."""
    from scipy import stats as _st
    n = len(px)
    groups = [np.arange(n)] + list(blocks)
    tests = len(groups) * 6
    threshold = stats.sidak_threshold(alpha, tests)
    z_his, z_los, z_all, out = [], [], [], {}
    kept = {"measured": [], "lo": [], "hi": [], "se": [], "dof": []}  # every test's means (stats.rejudge_interval)
    for g_i, g in enumerate(groups):
        m, lo_m, hi_m = px[g].mean(axis=0), lo[g].mean(axis=0), hi[g].mean(axis=0)
        se = (px[g] - lo[g]).std(axis=0, ddof=1) / np.sqrt(len(g))
        for key, value in (("measured", m), ("lo", lo_m), ("hi", hi_m), ("se", se)):
            kept[key].append(np.round(value, 10).tolist())
        kept["dof"].append(len(g) - 1)
        z_hi = (m - hi_m) / np.maximum(se, 1e-300)
        z_lo = (lo_m - m) / np.maximum(se, 1e-300)
        z_his.append(z_hi)
        z_los.append(z_lo)
        z_all.append(np.maximum(z_hi, z_lo))
        if g_i == 0:
            shift = _st.t.isf(threshold, n - 1) + _st.t.isf(1 - POWER, n - 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                out = {"lo": lo_m.tolist(), "hi": hi_m.tolist(), "measured": m.tolist(), "se": se.tolist(),
                       "dof": n - 1, "detectable_up": (shift * se / np.abs(hi_m)).tolist(),
                       "detectable_down": (shift * se / np.abs(lo_m)).tolist(),
                       "width": ((hi_m - lo_m) / np.abs(lo_m)).tolist(), "region_p": None}
    # every group's p in one call each side (Student's t survival function, elementwise: the same
    # numbers as a call per group, without scipy's per-call cost over the ~70 groups of a sphere;
    # issue 45 item 1, tests/probes/test_probe_speedups.py pins it to the per-group calls)
    dof = np.array(kept["dof"], dtype=np.float64)[:, None]
    p_all = np.minimum(stats.one_sided_p(np.array(z_his), dof), stats.one_sided_p(np.array(z_los), dof))
    out["region_p"] = float(np.min(p_all[0]))
    z_all = np.array(z_all)
    worst = np.unravel_index(np.argmin(p_all), p_all.shape)
    out.update({"pass": bool(np.all(p_all >= threshold) and np.all(np.isfinite(px))), "p": float(p_all.min()),
                "threshold": threshold, "tests": tests, "tiles": len(blocks), "z": float(np.max(z_all)),
                "worst": "region" if worst[0] == 0 else f"tile {worst[0]}", "worst_channel": "RGB"[worst[1]],
                "groups": kept})
    return out


def rough_films(m, alpha=None):
    alpha = stats.ALPHA if alpha is None else alpha
    scene, image = m.scene, m.image
    found = applies(scene)
    if not found or "R" not in m.names[:3]:
        return []
    h, w = image.shape[:2]
    rgb = image[..., :3].astype(np.float64)
    observers = [o for o in m.observers if o != colorimetry.GROUND_TRUTH]
    out = []
    for i in found:
        obj = scene["objects"][i]
        name = f"rough film {obj['name']}: sky exact, other objects bounded"
        geo = sphere_geometry(scene, i, w, h)
        ys, xs, _cos, _wts, w_occ, cos_min = geo
        at = _lookup_at(np.linspace(0.0, np.pi / 2, THETA_TABLE), geo[2])  # colour_table's theta grid
        lo, hi = intervals(scene, i, geo, at=at)
        with np.errstate(divide="ignore", invalid="ignore"):
            narrow = np.all((lo > 0) & (hi - lo <= WIDTH_MAX * lo), axis=1) & (cos_min >= COS_MIN)
        n, whole = int(narrow.sum()), len(ys)
        film = obj["bsdf"].get("thin_film")
        extra = {"film_nm": None if film is None else float(film["thickness"]), "sphere_pixels": whole,
                 "unjudged": whole - n}
        if n < MIN_PIXELS:
            out.append(_probe(name, None, None, None, "sigma beyond the interval", None, pixels=n, **extra,
                              why="no pixel of the sphere has a narrow interval at this resolution"))
            continue
        jy, jx = ys[narrow], xs[narrow]
        px = rgb[jy, jx]
        blocks = _tiles(jy, jx)
        stat = _judge(px, lo[narrow], hi[narrow], blocks, alpha)
        alternatives = {}
        for o in observers:
            lo_o, hi_o = intervals(scene, i, geo, o, at)
            alternatives[o] = _judge(px, lo_o[narrow], hi_o[narrow], blocks, alpha)
        best = int(np.nanargmin(np.array(stat["width"]) + np.array(stat["detectable_up"])))
        mid = (np.array(stat["lo"]) + np.array(stat["hi"])) / 2
        out.append(_probe(name, mid, stat["measured"], stat["z"], "sigma beyond the interval", stat["pass"],
                          pixels=n, **extra, lo=stat["lo"], hi=stat["hi"], channel="RGB"[best],
                          detectable=max(stat["detectable_up"][best], stat["detectable_down"][best]),
                          width=stat["width"][best], z=stat["z"], interval=stat, alternatives=alternatives,
                          occluded_weight=[float(w_occ[narrow].min()), float(w_occ[narrow].max())]))
    return out
