"""A Lambertian sphere (fluorescent or not) resting above a finite diffuse floor rectangle under a
uniform environment of radiance L(l), nothing else in the scene (yellow_sphere_F8,
fluorescent_sphere_D50_red, _mono_red, _mono_invisible): the sky's share of each sphere point's
irradiance is exact, the floor's share is a bounded nuisance, so every pixel of the sphere has an
interval [lo, hi] that its expected value must lie in.

Derivation. A point p of the sphere with outward normal n sees, over the hemisphere H(n) above its
tangent plane, only the sky and the floor: the sphere is convex, so no direction of H(n) meets it
again. With G(p) the projected (cosine-weighted) solid angle of the floor rectangle as seen from p,
clipped to H(n), the sky's projected solid angle is pi - G(p) and the irradiance is

    E(p, l) = (pi - G(p)) L(l) + F(p, l),   F(p, l) = integral over the floor of L_floor cos dw.

The sphere scatters by the bispectral Lambertian model of exporters/fluorescence.py (Mojzik et al.
2018): its outgoing radiance is S(p, l_o) = K[E(p)](l_o) / pi, with the positive linear operator
K[X](l_o) = rho(l_o) X(l_o) + integral P(l_i, l_o) X(l_i) dl_i (P = 0 for the yellow sphere).
Writing f = G / pi (the floor's share of the cosine-weighted hemisphere) and A = K[L] (the lone
sphere's radiance, probes/fluorescence.py):

    S(p) = (1 - f) A + K[F(p)] / pi.

Bounds on F (both hold wavelength by wavelength, so K, being positive, keeps their order):

- above: the floor's radiance is rho_f / pi times its irradiance, at most pi B(l), where B bounds
  every radiance in the scene: B = max(L, T B), T B = max(rho_f B, rho B + integral P B) (a surface
  sends at most its albedo times, plus its re-radiation of, the largest radiance it receives).
  T is bounded by the positive linear T_lin = max(rho_f, rho) + P; with v = (1 - T_lin)^-1 1 > 0,
  T_lin v <= q v, q < 1, so T contracts in the norm sup |X| / v, the true sup radiance (a
  sub-solution) lies below the unique fixed point, found by iterating from B = L plus the known
  remainder (B = L exactly when P = 0 and every albedo <= 1; a 1 nm trapezoid rule for P here). So
  F <= G rho_f B and S <= (1 - f) A + f K[rho_f B].
- below: a floor point at distance rho from the foot of the sphere's centre (height h above the
  floor's plane, radius r) sees the sphere under a cap of half-angle asin(r / d), d^2 = rho^2 + h^2,
  whose projected solid angle is at most pi r^2 / d^2 (a cap's projected solid angle is largest
  about the normal); the rest of its hemisphere is sky. So outside the square Q_R of half-side R
  about the foot (which contains the disc of radius R), L_floor >= rho_f L c_R, c_R = 1 - r^2 /
  (R^2 + h^2), and F >= c_R (G - G_Q(R)) rho_f L for every R whose square lies inside the floor.
  With g = max(0, max_R c_R (G - G_Q(R))) / pi: S >= (1 - f) A + g K[rho_f L].

A pixel's expected value is the footprint mean of S (box filter), and f and g enter linearly, so
its interval uses their means over the footprint (a 3 x 3 Gauss-Legendre rule, raycast.footprint_
offsets). To linear sRGB channel c the spectrum maps by the weights w_c(l) (the observer's CMFs on
its 1 nm grid, the trapezoid rule and the IEC matrix, colorimetry.xyz): a channel's bounds take the
positive part of w_c against the spectrum's upper bound and the negative part against its lower one.

Projected solid angle of a polygon (G): Lambert's contour formula (J. H. Lambert, Photometria,
1760; in graphics, Baum, Rushmeier and Winget, "Improving radiosity solutions through the use of
analytically determined form-factors", SIGGRAPH 1989, which also clips the polygon to the
hemisphere first; Arvo, "Applications of irradiance tensors", SIGGRAPH 1995): for a polygon wholly
in H(n) with vertices v_i relative to p,

    G = 1/2 | sum_i theta_i n . (v_i x v_(i+1)) / |v_i x v_(i+1)| |,  theta_i the angle v_i, v_(i+1),

after clipping the polygon to the half-space (v - p) . n >= 0 (Sutherland-Hodgman, one plane).

Judged on the render's own noise, on the pixels where the bound leaves power: those whose
interval is narrow (relative width below WIDTH_MAX in at least one channel, which selects the
upper part of the sphere, where the floor lies near the horizon: the selection depends on the
scene alone, never on the render). The region's mean per channel is
tested one-sided against the region's mean lo (too dark) and mean hi (too bright), its standard
error from the pixels' residuals to their own lo (Student's t, n - 1), Sidak over the 3 channels x
2 sides at stats.ALPHA. ``detectable``: how far (relative) beyond the interval a render's mean must
lie, in its best channel, for the test to fail with 90 % power; ``width``: the interval's relative
width in that channel (a change smaller than width + detectable may stay inside the interval)."""
import numpy as np

from ....exporters import colorimetry, fluorescence as fluo, spectra
from .. import raycast, stats
from .common import MIN_PIXELS, probe as _probe, remembered

WIDTH_MAX = 0.02  # relative width of a pixel's interval, in its narrowest channel, for it to be judged
SQUARES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0)  # half-sides R, in units of the sphere's radius
FOOTPRINT = 3  # Gauss-Legendre points per pixel axis
POWER = 0.9


def projected_solid_angle(points, normals, polygon):
    """Projected solid angle (cosine-weighted, pi for a whole hemisphere) of a convex planar
    ``polygon`` (V x 3, in order) seen from each of ``points`` (N x 3) within the hemisphere about
    each unit normal of ``normals`` (N x 3): the polygon is clipped to that hemisphere, then
    Lambert's contour formula is summed edge by edge."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(polygon, dtype=np.float64)[None, :, :] - p[:, None, :]  # N x V x 3
    d = np.einsum("nvk,nk->nv", v, n)  # signed heights above the tangent plane
    a, b = v, np.roll(v, -1, axis=1)
    da, db = d, np.roll(d, -1, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = da / (da - db)
    x = a + np.where(np.isfinite(t), t, 0.0)[..., None] * (b - a)  # where the edge crosses the plane
    ina, inb = da >= 0, db >= 0
    total = np.zeros(len(p))
    # the clipped polygon's edges: a->b (both in), a->x (leaving), x->b (entering), and the one
    # along the tangent plane from the exit crossing to the entry crossing
    total += np.sum(np.where(ina & inb, _edge(a, b, n), 0.0), axis=1)
    leave, enter = ina & ~inb, ~ina & inb
    total += np.sum(np.where(leave, _edge(a, x, n), 0.0), axis=1)
    total += np.sum(np.where(enter, _edge(x, b, n), 0.0), axis=1)
    has = leave.any(axis=1) & enter.any(axis=1)
    xe = x[np.arange(len(p)), np.argmax(leave, axis=1)]
    xi = x[np.arange(len(p)), np.argmax(enter, axis=1)]
    total += np.where(has, _edge(xe[:, None], xi[:, None], n)[:, 0], 0.0)
    return np.abs(total) / 2.0


def _edge(a, b, n):
    """theta n . (a x b) / |a x b| for edges a -> b (N x E x 3), 0 for degenerate edges."""
    c = np.cross(a, b)
    cn = np.linalg.norm(c, axis=-1)
    theta = np.arctan2(cn, np.einsum("nek,nek->ne", a, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        out = theta * np.einsum("nek,nk->ne", c, n) / cn
    return np.where(cn > 1e-300, out, 0.0)


def _corners(shape):
    m = np.asarray(shape["to_world"], dtype=np.float64)
    return (np.array([[-1, -1, 0, 1], [1, -1, 0, 1], [1, 1, 0, 1], [-1, 1, 0, 1]], dtype=np.float64) @ m.T)[:, :3]


def applies(scene):
    """(sphere index, floor index) when ``scene`` is one diffuse sphere and one diffuse,
    non-emitting, non-fluorescent rectangle under a uniform environment, the sphere wholly on the
    floor's camera side, seen from outside; else None."""
    env, objs = scene.get("environment"), scene["objects"]
    if not env or env.get("type", "uniform") != "uniform" or len(objs) != 2 or scene.get("lights"):
        return None
    kinds = [o["shape"]["type"] for o in objs]
    if sorted(kinds) != ["rectangle", "sphere"]:
        return None
    si, fi = kinds.index("sphere"), kinds.index("rectangle")
    for o in objs:
        b = o.get("bsdf") or {}
        if b.get("type") != "diffuse" or o.get("emitter"):
            return None
    if (objs[fi].get("bsdf") or {}).get("fluorescence") is not None:
        return None
    sph = objs[si]["shape"]
    c, r = np.asarray(sph["center"], dtype=np.float64), float(sph["radius"])
    center, normal, _hx, _hy = raycast.rectangle_frame(objs[fi]["shape"])
    cam = np.asarray(scene["camera"]["to_world"], dtype=np.float64)[:3, 3]
    h = float((c - center) @ normal)
    if abs(h) < r * (1 - 1e-9) or np.linalg.norm(cam - c) <= r:
        return None  # the sphere pierces the floor's plane, or the camera is inside it
    if np.sign((cam - center) @ normal) != np.sign(h):
        return None  # the camera sees the floor's other side
    return si, fi


def _grid():
    return np.arange(fluo.DOMAIN[0], fluo.DOMAIN[1] + 0.5, 1.0)


@remembered()
def _spectra(sphere_bsdf, floor_bsdf, radiance, shares):
    """(A, U_lo, U_hi, {R: U_R}, contraction) on the CMF grid: A = K[L], U_lo = K[rho_f L], U_hi =
    K[rho_f B], U_R = K[rho_f (L + s_R (B - L)^+)] for ``shares`` ((R, s_R), ...) (module
    docstring); contraction: q, the factor T contracts by (>= 1: no bound)."""
    wl = spectra.cie_1931_cmfs()[0]
    grid = _grid()
    light = np.asarray(spectra.evaluate(radiance, grid), dtype=np.float64)
    rho = np.clip(np.asarray(spectra.evaluate(sphere_bsdf["reflectance"], grid), dtype=np.float64), 0, None)
    rho_f = np.clip(np.asarray(spectra.evaluate(floor_bsdf["reflectance"], grid), dtype=np.float64), 0, None)
    fl = sphere_bsdf.get("fluorescence")
    if fl is None:
        p = np.zeros((grid.size, grid.size))
    else:  # P on the 1 nm grid, trapezoid weights along l_i: only B's iteration uses it
        wts = np.full(grid.size, 1.0)
        wts[0] = wts[-1] = 0.5
        p = fluo.reradiation(fl, grid[None, :], grid[:, None]) * wts[None, :]
    # T is bounded by the positive linear T_lin X = max(rho_f, rho) X + P X; with v = (1 - T_lin)^-1 1
    # (the Neumann series' sum when it converges) T_lin v = v - 1 <= q v, q = max(T_lin v / v) < 1:
    # T contracts by q in the norm sup |X| / v, so B is unique and the iteration's remainder known
    t_lin = np.diag(np.maximum(rho, rho_f)) + p
    try:
        v = np.linalg.solve(np.eye(grid.size) - t_lin, np.ones(grid.size))
    except np.linalg.LinAlgError:
        v = np.full(grid.size, -1.0)
    contraction = float(np.max((t_lin @ v) / v)) if np.all(v > 0) and np.all(np.isfinite(v)) else np.inf
    bound = light.copy()
    if contraction < 1.0:
        step = lambda b: np.maximum(light, np.maximum(rho_f * b, rho * b + p @ b))  # noqa: E731
        for _ in range(100000):
            new = step(bound)
            change = np.max(np.abs(new - bound) / v)
            bound = new
            if change <= 1e-12 * max(np.max(bound / v), 1e-300):
                break
        # the iterates approach the fixed point from below; with B' = step(B), the contraction
        # bounds the rest: |B* - B'| <= q / (1 - q) |B' - B| in the v-norm
        nxt = step(bound)
        bound = nxt + v * contraction / (1 - contraction) * np.max(np.abs(nxt - bound) / v)

    def k_each(values):
        """K[X] for each spectrum X of ``values`` (on the grid): the sphere's reflection of X plus
        its fluorescence (one table of P for all: fluo.emitted_each)."""
        fns = [lambda x, v=v: np.interp(x, grid, v) for v in values]
        emitted = fluo.emitted_each(fl, fns, wl) if fl is not None else [0.0] * len(fns)
        return [np.clip(np.asarray(spectra.evaluate(sphere_bsdf["reflectance"], wl), dtype=np.float64), 0, None)
                * fn(wl) + e for fn, e in zip(fns, emitted)]
    # outside the square Q_R the floor sees the sphere in at most s_R of its cosine-weighted
    # hemisphere: its radiance is at most rho_f (L + s_R (B - L)^+)
    ks = k_each([light, rho_f * light, rho_f * bound]
                + [rho_f * (light + big_share * np.clip(bound - light, 0, None)) for _big, big_share in shares])
    ups = {big: ks[3 + j] for j, (big, _share) in enumerate(shares)}
    return ks[0], ks[1], ks[2], ups, contraction


def _weights(obs):
    """Linear sRGB weights (471 x 3) of a spectrum on the CMF grid under observer ``obs``."""
    wl = spectra.cie_1931_cmfs()[0]
    return colorimetry.xyz_to_srgb(colorimetry.xyz_rows(np.eye(wl.size), obs))


def _channels(a, u_lo, u_hi, ups, f, shares, obs):
    """Per pixel the channel bounds lo, hi (N x 3). ``f``: the floor's share (N); ``shares``:
    {R: (q_R, g_R)} per pixel (the square's share, the lower bound's share)."""
    w = _weights(obs)
    wp, wn = np.clip(w, 0, None), np.clip(w, None, 0)
    base = (1 - f)[:, None] * (a @ w)[None, :]
    zero = np.zeros((len(f), 3))
    low_p, low_n = [zero], [zero]  # a lower bound's spectrum against w+ and w-
    up_p, up_n = [f[:, None] * (u_hi @ wp)], [f[:, None] * (u_hi @ wn)]
    for big, (q, g) in shares.items():
        low_p.append(g[:, None] * (u_lo @ wp))
        low_n.append(g[:, None] * (u_lo @ wn))
        up_p.append((f - q)[:, None] * (ups[big] @ wp) + q[:, None] * (u_hi @ wp))
        up_n.append((f - q)[:, None] * (ups[big] @ wn) + q[:, None] * (u_hi @ wn))
    # the true floor light lies above every lower and below every upper spectrum at once
    lo = base + np.max(low_p, axis=0) + np.max(up_n, axis=0)
    hi = base + np.min(up_p, axis=0) + np.min(low_n, axis=0)
    return lo, hi


def _squares(scene, si, fi):
    """[(R, s_R, square corners)] for the squares about the sphere's foot that lie inside the floor:
    s_R = r^2 / (R^2 + h^2), the sphere's largest share of a floor point's hemisphere outside."""
    objs = scene["objects"]
    center, normal, hx, hy = raycast.rectangle_frame(objs[fi]["shape"])
    m = np.asarray(objs[fi]["shape"]["to_world"], dtype=np.float64)
    ex, ey = m[:3, 0] / np.linalg.norm(m[:3, 0]), m[:3, 1] / np.linalg.norm(m[:3, 1])
    c, r = np.asarray(objs[si]["shape"]["center"], dtype=np.float64), float(objs[si]["shape"]["radius"])
    h = float((c - center) @ normal)
    foot = c - h * normal
    u, v = float((foot - center) @ ex), float((foot - center) @ ey)
    out = []
    for big in SQUARES:
        half = big * r
        if abs(u) + half > hx or abs(v) + half > hy:
            continue  # the square must lie inside the floor
        sq = np.array([foot + sx * half * ex + sy * half * ey for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        out.append((big, r * r / (half * half + h * h), sq))
    return out


def floor_shares(scene, si, fi, points, normals):
    """(f, {R: (q_R, g_R)}) at sphere points: the floor's share of the cosine-weighted hemisphere,
    and per square Q_R its share q_R and the lower bound's share g_R = (1 - s_R)(f - q_R)."""
    f = projected_solid_angle(points, normals, _corners(scene["objects"][fi]["shape"])) / np.pi
    out = {}
    for big, share, sq in _squares(scene, si, fi):
        q = projected_solid_angle(points, normals, sq) / np.pi
        out[big] = (q, (1.0 - share) * np.clip(f - q, 0, None))
    return f, out


def _pixel_shares(scene, si, fi, mask, k=FOOTPRINT):
    """Means of floor_shares over the footprints of the pixels of ``mask`` (k x k points each;
    k = 1: the pixel centre)."""
    cam, sph = scene["camera"], scene["objects"][si]["shape"]
    h, w = mask.shape
    ys, xs = np.nonzero(mask)
    c = np.asarray(sph["center"], dtype=np.float64)
    f_sum, sums = np.zeros(len(ys)), {}
    for (ox, oy), wt in (raycast.footprint_offsets(k) if k > 1 else [((0.5, 0.5), 1.0)]):
        origin, dirs = raycast.camera_rays_at(cam, w, h, xs + ox, ys + oy)
        t = raycast.hit_sphere(sph, origin, dirs)
        pts = origin + t[:, None] * dirs
        f, per = floor_shares(scene, si, fi, pts, (pts - c) / float(sph["radius"]))
        f_sum += wt * f
        for big, (q, g) in per.items():
            q0, g0 = sums.get(big, (0.0, 0.0))
            sums[big] = (q0 + wt * q, g0 + wt * g)
    return f_sum, sums


@remembered(size=4)
def _centre_shares(camera, shapes, si, fi, w, h):
    """(mask of the sphere's whole pixels, floor_shares at their centres): the geometry alone (the
    camera's fields that raycast reads, the two shapes, the image size). The four scenes of the
    default suite with this probe (yellow_sphere_F8 and three fluorescent spheres) share it, so
    the later ones take it from the first (issue 45 item 1: 0.7 s of each one's ~2 s of CPU);
    the same arguments give the same arrays, so the verdicts are those computed anew."""
    scene = {"camera": camera, "objects": [{"shape": sh} for sh in shapes]}
    mask = raycast.pixels_inside(camera, w, h, scene["objects"], si)
    f, per = _pixel_shares(scene, si, fi, mask, 1)
    return mask, f, per


def sphere_on_floor(m):
    scene, image = m.scene, m.image
    found = applies(scene)
    if found is None:
        return []
    si, fi = found
    objs, env = scene["objects"], scene["environment"]
    sphere = objs[si]
    kind = "fluorescent " if (sphere.get("bsdf") or {}).get("fluorescence") is not None else ""
    name = f"{kind}Lambertian sphere {sphere['name']} on a floor: sky exact, floor bounded"
    shares_r = [(big, share) for big, share, _sq in _squares(scene, si, fi)]
    a, u_lo, u_hi, ups, contraction = _spectra(sphere["bsdf"], objs[fi]["bsdf"], env["radiance"], shares_r)
    h, w = image.shape[:2]
    camera = raycast.camera_fields(scene["camera"])  # what raycast reads
    mask, f, per = _centre_shares(camera, [o["shape"] for o in objs], si, fi, w, h)
    sphere_pixels = int(mask.sum())
    if contraction >= 1.0:
        return [_probe(name, None, None, None, "relative", None, pixels=int(mask.sum()),
                       why=f"no bound on the floor's radiance (contraction {contraction:.3f} >= 1)")]
    # which pixels are judged: chosen on the interval at each pixel's centre (the scene alone
    # decides); their bounds then from the footprint's mean
    lo, hi = _channels(a, u_lo, u_hi, ups, f, per, colorimetry.GROUND_TRUTH)
    narrow = np.any((lo > 0) & (hi - lo <= WIDTH_MAX * lo), axis=1)
    chosen = np.zeros_like(mask)
    chosen[mask] = narrow
    f, per = _pixel_shares(scene, si, fi, chosen)
    mask, narrow = chosen, np.ones(int(chosen.sum()), dtype=bool)
    n = int(narrow.sum())
    if n < MIN_PIXELS:
        return [_probe(name, None, None, None, "relative", None, pixels=n, sphere_pixels=sphere_pixels)]
    px = image[mask][narrow][:, :3].astype(np.float64)
    measured = px.mean(axis=0)
    threshold = stats.sidak_threshold(stats.ALPHA, 6)

    def judged(obs):
        lo_o, hi_o = _channels(a, u_lo, u_hi, ups, f[narrow], {k: (q[narrow], g[narrow]) for k, (q, g) in per.items()}, obs)
        se = (px - lo_o).std(axis=0, ddof=1) / np.sqrt(n)
        lo_m, hi_m = lo_o.mean(axis=0), hi_o.mean(axis=0)
        z_hi = (measured - hi_m) / np.maximum(se, 1e-300)
        z_lo = (lo_m - measured) / np.maximum(se, 1e-300)
        p = np.minimum(stats.one_sided_p(z_hi, n - 1), stats.one_sided_p(z_lo, n - 1))
        passed = bool(np.all(p >= threshold) and np.all(np.isfinite(measured)))
        # detectable: the relative shift beyond the interval that the one-sided test sees with POWER
        # (location shift of Student's t: t_crit + t_power standard errors)
        from scipy import stats as _st
        shift = _st.t.isf(threshold, n - 1) + _st.t.isf(1 - POWER, n - 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            up = shift * se / np.abs(hi_m)
            down = shift * se / np.abs(lo_m)
            width = (hi_m - lo_m) / np.abs(lo_m)
        return {"pass": passed, "p": float(np.min(p)), "threshold": threshold, "z": float(np.max(np.maximum(z_hi, z_lo))),
                "lo": lo_m.tolist(), "hi": hi_m.tolist(), "measured": measured.tolist(), "se": se.tolist(),
                "dof": n - 1, "detectable_up": up.tolist(), "detectable_down": down.tolist(), "width": width.tolist()}
    stat = judged(colorimetry.GROUND_TRUTH)
    alternatives = {o: judged(o) for o in m.observers if o != colorimetry.GROUND_TRUTH}
    best = int(np.nanargmin(np.array(stat["width"]) + np.array(stat["detectable_up"])))
    mid = (np.array(stat["lo"]) + np.array(stat["hi"])) / 2
    return [_probe(name, mid, measured, stat["z"], "sigma beyond the interval", stat["pass"], pixels=n, sphere_pixels=sphere_pixels,
                   lo=stat["lo"], hi=stat["hi"], channel="RGB"[best],
                   detectable=max(stat["detectable_up"][best], stat["detectable_down"][best]),
                   width=stat["width"][best], z=stat["z"], interval=stat, alternatives=alternatives,
                   floor_share=[float(f[narrow].min()), float(f[narrow].max())])]
