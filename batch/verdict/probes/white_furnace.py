"""The GGX white furnace (issue 41 item 2): one rough sphere of a perfect conductor (Fresnel 1 at
every angle and wavelength) under a uniform environment of radiance L(l), nothing else in the scene
(furnace_ggx_010, _030, _060, _100: GGX alpha 0.1, 0.3, 0.6, 1.0).

Truth. A sphere is convex: every direction of a point's upper hemisphere leaves the sphere and meets
the uniform sky, so the light leaving it towards the camera is, per wavelength,

    L_o(mu_o, l) = E(mu_o, alpha) L(l),    E = integral f_r cos_i dw_i = integral D G (o . h) / mu_o dw_h

with F = 1 (Walter et al. 2007 eq. 20 and eq. 14's Jacobian dw_i = 4 (o . h) dw_h), mu_o the
cosine between the view and the sphere's normal: E is the single-scattering directional albedo,
computed by the project's quadrature (probes/ggx.py ``directional_albedo``, checked against
1 - ln 2 at alpha 1, mu 1 and Heitz 2014's weak white furnace identity; tests/probes/
test_ggx_furnace.py), here vectorised over a table of THETA_TABLE view angles (``albedo_table``,
linear interpolation in theta_o). The spectrum enters through L alone, so a pixel's colour is the
mean of E over its footprint (FOOTPRINT x FOOTPRINT Gauss-Legendre sub-rays, box filter) times the
linear sRGB colour of L (exporters/colorimetry.py).

A perfect conductor in the IR: eta 0 and k > 0. A complex index i k (a lossless plasma below its
plasma frequency) reflects totally at every angle: with n = 0 the conductor Fresnel formulas give
r_s = r_p = 1 exactly (Born and Wolf, Principles of Optics, 7th ed., 14.2; Mitsuba 3's
fresnel_conductor, pbrt-v4's FrComplex and Cycles' fresnel_conductor all reduce to 1 there). The
probe applies where the conductor's Fresnel reflectance, computed from its eta and k
(optics.fresnel_conductor) on the CMF grid and F_CHECK cosines, is within F_TOL of 1 everywhere.

What a renderer that keeps multiple scattering gets: the light that single scattering loses, 1 - E,
comes back in part (Kulla and Conty 2017, "Revisiting Physically Based Shading at Imageworks",
SIGGRAPH course: an energy-compensation lobe of albedo 1 - E(mu_o) for F = 1; Heitz et al. 2016,
"Multiple-scattering microfacet BSDFs with the Smith model", ACM TOG 35(4): the random walk, energy
conserving for F = 1): the diagnosis fits L_o = (E + s (1 - E)) L on the record's rings
(diagnosis/materials.py "multiple scattering"), s the share of the missing energy kept.

Judged on the render's own noise: the judged pixels are the sphere's whole pixels whose footprint
sees the sphere at every sub-ray and whose view is not grazing (cos theta_o >= COS_MIN at every
sub-ray); the pixels are independent draws (box filter, independent sampling) with per-pixel
expectations E L, so their residuals (render - expected) are tested: the region's mean and each
ring of mu_o (RING_EDGES, at least MIN_RING pixels: the multiple-scattering energy changes with the
view angle, so a ring sees it where a region mean dilutes it) per channel against the expected
means, the standard error from the residuals' spread (Student's t, n - 1), Sidak over every test
at stats.ALPHA (stats.compare_means: a recorded deviation's scale and observer re-judge it). The
other Smith form (height-correlated, pbrt-v4's and Cycles' G2) and the observers' films are judged
too (``alternatives``, keys as probes/ggx.py). ``detectable``: the smallest relative change of the
region's mean (best channel) the region's test sees with 90 % power.
"""
import numpy as np

from ....exporters import colorimetry, spectra
from .. import optics, raycast, stats
from .common import MIN_PIXELS, probe as _probe, remembered
from .ggx import ALBEDO_NODES, SHADOWING, SHADOWING_FORMS, _half_vector_rule, shadowing_key

THETA_TABLE = 257      # theta_o samples of E on [0, pi/2]
FOOTPRINT = 4          # Gauss-Legendre sub-rays per pixel axis
COS_MIN = 0.2          # judged where every sub-ray's cos theta_o is at least this
F_TOL = 1e-4           # the conductor counts as perfect where 1 - F <= F_TOL at every angle and wavelength
F_CHECK = 65           # cosines of that check on [0, 1]
RING_EDGES = (0.2, 0.5, 0.7, 0.85, 0.95, 1.0)  # rings of the pixels' mean mu_o
MIN_RING = 32
POWER = 0.9
CHUNK = 32             # view angles per vectorised step of the table


def _perfect(bsdf):
    """Whether a conductor's Fresnel reflectance is within F_TOL of 1 everywhere (eta/k given inline;
    a named conductor is a real metal, never perfect)."""
    if "eta" not in bsdf or "k" not in bsdf or bsdf.get("thin_film"):
        return False
    wl = spectra.cie_1931_cmfs()[0]
    eta, k = spectra.evaluate(bsdf["eta"], wl), spectra.evaluate(bsdf["k"], wl)
    cos = np.linspace(0.0, 1.0, F_CHECK)
    with np.errstate(all="ignore"):
        f = optics.fresnel_conductor(cos[:, None], eta[None, :], k[None, :])
    return bool(np.all(np.isfinite(f)) and np.max(np.abs(1.0 - f)) <= F_TOL)


def applies(scene):
    """The index of the lone rough sphere of a perfect conductor (GGX or Beckmann, no film, no
    emitter, the camera outside) when ``scene`` has a uniform environment and nothing else; else None."""
    env = scene.get("environment")
    if not env or env.get("type", "uniform") != "uniform" or scene.get("lights") or len(scene["objects"]) != 1:
        return None
    o = scene["objects"][0]
    b = o.get("bsdf") or {}
    rough = b.get("roughness") or {}
    if (o.get("emitter") or o["shape"]["type"] != "sphere" or b.get("type") != "conductor"
            or rough.get("distribution") not in ("ggx", "beckmann") or not rough.get("alpha", 0) > 0
            or not _perfect(b)):
        return None
    cam = np.asarray(scene["camera"]["to_world"], dtype=np.float64)[:3, 3]
    if np.linalg.norm(cam - np.asarray(o["shape"]["center"], dtype=np.float64)) <= o["shape"]["radius"]:
        return None
    return 0


@remembered(16)
def albedo_table(alpha, kind="ggx", form=SHADOWING, nodes=ALBEDO_NODES):
    """(theta_o grid, E(cos theta_o)) on THETA_TABLE angles of [0, pi/2]: ggx.directional_albedo's
    sum, for every view angle over one half-vector rule (its nodes do not depend on the view; only
    the view straight down the normal has a kink the rule places a break at, and that one angle is
    computed by directional_albedo itself). E(0) is the limit the grid's next angle gives."""
    from .ggx import directional_albedo
    theta = np.linspace(0.0, np.pi / 2, THETA_TABLE)
    mu = np.cos(theta)
    h, w = _half_vector_rule(kind, alpha, nodes)
    out = np.empty(THETA_TABLE)
    for s in range(1, THETA_TABLE - 1, CHUNK):
        m = mu[s:min(s + CHUNK, THETA_TABLE - 1)][:, None]
        o = np.stack([np.sqrt(np.maximum(1.0 - m * m, 0.0)), np.zeros_like(m), m], axis=-1)  # V x 1 x 3
        oh = np.einsum("vik,nk->vn", o, h)
        cos_i = 2.0 * oh * h[None, :, 2] - m
        ok = (oh > 0) & (cos_i > 0)
        g = optics.shadowing(kind, np.where(ok, cos_i, 1.0), np.broadcast_to(m, oh.shape), alpha, form)
        out[s:s + len(m)] = np.sum(w[None, :] * np.where(ok, g * oh / (m * h[None, :, 2]), 0.0), axis=1)
    out[0] = directional_albedo(1.0, alpha, kind, form, nodes)
    out[-1] = out[-2]
    return theta, out


def _lookup(theta, table, cos):
    x = np.arccos(np.clip(cos, 0.0, 1.0)) * ((len(theta) - 1) / (np.pi / 2))
    i = np.minimum(x.astype(np.intp), len(theta) - 2)
    return table[i] + (x - i) * (table[i + 1] - table[i])


@remembered(16)
def geometry(cam, shape, w, h):
    """(ys, xs, footprint cosines (N x K), weights (K)) of the sphere's judged pixels at a w x h
    image: whole pixels, every sub-ray on the sphere with cos theta_o >= COS_MIN."""
    objs = [{"shape": shape}]
    centre = np.asarray(shape["center"], dtype=np.float64)
    origin, corners = raycast.camera_rays(cam, w, h, "corners")
    who, _t = raycast.nearest(objs, origin, corners)
    on = who == 0
    whole = on[:-1, :-1] & on[1:, :-1] & on[:-1, 1:] & on[1:, 1:]
    ys, xs = np.nonzero(whole)
    offs = raycast.footprint_offsets(FOOTPRINT)
    cos, ok = np.zeros((len(ys), len(offs))), np.ones(len(ys), dtype=bool)
    for j, ((ox, oy), _wt) in enumerate(offs):
        o, d = raycast.camera_rays_at(cam, w, h, xs + ox, ys + oy)
        hit, t = raycast.nearest(objs, o, d)
        ok &= hit == 0
        p = o + np.where(np.isfinite(t), t, 0.0)[:, None] * d
        cos[:, j] = np.clip(-np.sum(d * (p - centre), axis=-1) / shape["radius"], 0.0, 1.0)
    ok &= np.min(cos, axis=1) >= COS_MIN
    return ys[ok], xs[ok], cos[ok], np.array([wt for _o, wt in offs])


def pixel_albedo(bsdf, cos, wts, form=SHADOWING):
    """E averaged over each pixel's footprint (N)."""
    rough = bsdf["roughness"]
    theta, table = albedo_table(float(rough["alpha"]), rough["distribution"], form)
    return _lookup(theta, table, cos) @ wts


def env_rgb(radiance, obs=colorimetry.GROUND_TRUTH):
    return colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(radiance, None, obs))


def rings(mu):
    """Index arrays of the pixels in each ring of mean mu_o (RING_EDGES) with at least MIN_RING pixels."""
    out = []
    for lo, hi in zip(RING_EDGES[:-1], RING_EDGES[1:]):
        idx = np.nonzero((mu >= lo) & (mu < hi if hi < 1.0 else mu <= hi))[0]
        if len(idx) >= MIN_RING:
            out.append(idx)
    return out


def judge(px, expected, groups, tests=None):
    """compare_means of every group's mean pixel against its mean expected value, the standard
    error from the group's residuals (n - 1 dof), Sidak over groups x channels."""
    m = np.array([px[g].mean(axis=0) for g in groups])
    e = np.array([expected[g].mean(axis=0) for g in groups])
    se = np.array([(px[g] - expected[g]).std(axis=0, ddof=1) / np.sqrt(len(g)) for g in groups])
    dof = np.repeat(np.array([len(g) - 1.0 for g in groups])[:, None], px.shape[1], axis=1)
    return stats.compare_means(m, e, se, dof=dof, tests=tests or m.size)


def white_furnace(m):
    i = applies(m.scene)
    if i is None or "R" not in m.names[:3]:
        return []
    scene, image = m.scene, m.image
    obj = scene["objects"][i]
    bsdf = obj["bsdf"]
    rough = bsdf["roughness"]
    label = f"{rough['distribution']} white furnace {obj['name']}: E(mu_o, {float(rough['alpha']):g}) L_env, single scattering"
    hgt, wid = image.shape[:2]
    # keyed by the camera's ray-cast fields, not its name: furnace_ggx_010 ... 100 share one geometry
    ys, xs, cos, wts = geometry(raycast.camera_fields(scene["camera"]), obj["shape"], wid, hgt)
    n = len(ys)
    if n < max(MIN_PIXELS, MIN_RING):
        return [_probe(label, None, None, None, "sigma", None, pixels=n)]
    radiance = scene["environment"]["radiance"]
    e_px = pixel_albedo(bsdf, cos, wts)
    mu = cos @ wts
    groups = [np.arange(n)] + rings(mu)
    px = image[ys, xs][:, :3].astype(np.float64)
    white = env_rgb(radiance)
    stat = judge(px, e_px[:, None] * white[None, :], groups)
    alternatives = {o: judge(px, e_px[:, None] * env_rgb(radiance, o)[None, :], groups)
                    for o in m.observers if o != colorimetry.GROUND_TRUTH}
    other = next(f for f in SHADOWING_FORMS if f != SHADOWING)
    e_other = pixel_albedo(bsdf, cos, wts, other)
    alternatives[shadowing_key(other)] = judge(px, e_other[:, None] * white[None, :], groups)
    # power: the region's mean (best channel), two-sided at the family's per-test threshold
    e0, se0 = np.asarray(stat["expected"][0]), np.asarray(stat["se"][0])
    sens = np.abs(e0) / np.maximum(se0, 1e-300)
    curve = stats.power_curve(stat["threshold"], n - 1, sens.shape)
    det = stats.smallest_detectable(lambda eps: float(np.max(curve(eps * sens))), POWER, hi=100.0)
    mean_m, mean_e = np.asarray(stat["measured"][0]), e0
    ring_mu = [[float(mu[g].min()), float(mu[g].max())] for g in groups[1:]]
    return [_probe(label, mean_e, mean_m, float(np.sum(mean_m) / np.sum(mean_e) - 1.0), "relative", stat["pass"],
                   z=stat["z"], stat=stat, alternatives=alternatives, pixels=n, detectable=det,
                   alpha=float(rough["alpha"]), shadowing=SHADOWING, env_rgb=white.round(8).tolist(),
                   groups=["region"] + [f"mu {a:.3f}-{b:.3f}" for a, b in ring_mu],
                   mean_albedo=[float(e_px[g].mean()) for g in groups],
                   mean_albedo_other=[float(e_other[g].mean()) for g in groups],
                   table=f"{THETA_TABLE} view angles, {ALBEDO_NODES[0]} x {ALBEDO_NODES[1]} half vectors, "
                         f"{FOOTPRINT}x{FOOTPRINT} sub-rays per pixel")]
