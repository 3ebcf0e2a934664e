"""Material error models, through the probes' closed forms (the GGX plates: the scene's truth
recomputed with the material changed) and emitter units (a factor pi on the reference evidence)."""
import copy

import numpy as np

from . import Fit, Model, RegionEvidence, least_squares, reference_model, region_fit

FAMILY = "materials"
# ev.cache's key for the GGX probe's quadrature geometry (probes/ggx.py expected_images ``cache``),
# shared by every trial of every plate model of one render: only D, G and the Fresnel table change
GGX_CACHE = "ggx quadrature"
# and for the Airy probe's sub-rays and film interfaces (probes/thin_film.py expected_images ``cache``),
# shared by every trial thickness of the film models of one render
FILM_CACHE = "airy film"


def _plates(ev):
    """(scene, plate ids, light ids, rgb render, block) when the GGX probe applies, else None."""
    from .. import compare
    from ..probes import ggx
    found = ggx._applies(ev.scene)
    if not found or "R" not in ev.names:
        return None
    rgb = ev.image[..., [ev.names.index(c) for c in "RGB"]].astype(np.float64)
    return ev.scene, found[0], found[1], rgb, compare.block_size(ev.scene["render"]["spp"], ev.image.shape)


def _plate_model(change, starts=None, bounds=None):
    """A fit on the first GGX plate's region: ``change(bsdf, x)`` edits a copy of the plate's BSDF
    (x: the parameters, [] without any); the expected image is the probe's quadrature of it."""
    def fit(ev):
        from ..probes import ggx
        got = _plates(ev)
        if got is None:
            return None
        scene, plate_ids, light_ids, rgb, block = got
        plate = plate_ids[0]
        h, w = rgb.shape[:2]

        def predict(x):
            sc = scene
            if x is not None:
                sc = copy.deepcopy(scene)
                change(sc["objects"][plate]["bsdf"], x)
            mask, images = ggx.expected_images(sc, plate, light_ids, w, h, cache=ev.cache.setdefault(GGX_CACHE, {}))
            return np.where(mask[..., None], images["cie1931"], 0.0)
        truth = predict(None)
        mask = np.any(truth != 0, axis=-1)
        region = RegionEvidence(rgb, truth, mask, block)
        if len(region) < 2:
            return None
        f = region_fit(region, predict, starts(scene["objects"][plate]["bsdf"]) if starts else [], bounds)
        return f, scene["objects"][plate]["bsdf"]
    return fit


def _ggx_plates(scene):
    """(plate ids, light ids) of rough conductor rectangles and rectangle lights, whatever else the
    scene holds (a floor): the closed form then gives the plates' direct light only."""
    objs = scene["objects"]
    plates = [i for i, o in enumerate(objs) if (o.get("bsdf") or {}).get("type") == "conductor"
              and o["shape"]["type"] == "rectangle" and (o["bsdf"].get("roughness") or {}).get("alpha", 0) > 0
              and not o["bsdf"].get("thin_film") and not o.get("emitter")]
    lights = [i for i, o in enumerate(objs) if o.get("emitter") and not o.get("bsdf") and o["shape"]["type"] == "rectangle"]
    return (plates, lights) if plates and lights else None


def _reference_plate_model(change, starts):
    """A fit on the reference evidence: the render predicted as the reference plus the change of
    the plates' direct light (the GGX probe's quadrature) when ``change(bsdf, x)`` edits every
    plate's BSDF. The light a plate gets from elsewhere (a floor: the reference minus the
    closed form's direct light, on the plate) changes with the material too, by a factor no
    closed form gives here: where there is such light, a second parameter scales its change
    (``indirect``: 0 unchanged), a nuisance fitted beside the material's parameter."""
    def fit(ev):
        from ..probes import ggx
        found = _ggx_plates(ev.scene) if ev.has_reference else None
        if not found or ev.ref_names[:3] != ["R", "G", "B"]:
            return None
        plates, lights = found
        others = len(ev.scene["objects"]) > len(plates) + len(lights)
        h, w = ev.ref_mean.shape[:2]
        cache = {}

        def direct(x):
            key = None if x is None else tuple(np.round(np.asarray(x, dtype=np.float64), 12))
            if key not in cache:
                sc = ev.scene if x is None else copy.deepcopy(ev.scene)
                total = np.zeros((h, w, 3))
                for plate in plates:
                    if x is not None:
                        change(sc["objects"][plate]["bsdf"], x)
                    mask, images = ggx.expected_images(sc, plate, lights, w, h,
                                                       cache=ev.cache.setdefault(GGX_CACHE, {}))
                    total += np.where(mask[..., None], images["cie1931"], 0.0)
                cache[key] = total
            return cache[key]
        base = direct(None)
        on_plate = np.any(base != 0, axis=-1)[..., None]
        indirect = np.where(on_plate, ev.ref_mean[..., :3] - base, 0.0)

        if starts is None:  # a fixed change: the indirect light's factor is the only parameter (if any)
            def predict_fixed(x, ev):
                out = ev.ref_mean.copy()
                out[..., :3] += direct(()) - base + (x[0] * indirect if others and len(x) else 0.0)
                return out
            if others:
                return reference_model(predict_fixed, starts=[[0.0]], bounds=([-1.0], [1.0]))(ev)
            return reference_model(predict_fixed)(ev)

        def predict(x, ev):
            out = ev.ref_mean.copy()
            out[..., :3] += direct(x[:1]) - base + (x[1] * indirect if others else 0.0)
            return out
        x0 = [s + ([0.0] if others else []) for s in starts(ev.scene["objects"][plates[0]]["bsdf"])]
        bounds = ([1e-3, -1.0], [1.0, 1.0]) if others else ([1e-3], [1.0])
        return reference_model(predict, starts=x0, bounds=bounds)(ev)
    return fit


def _set_alpha(bsdf, x):
    bsdf["roughness"]["alpha"] = float(x[0])


def _alpha_fit(ev):
    """On the reference evidence where there is one (the plates' change of direct light), else on
    the GGX probe's region."""
    starts = lambda b: [[b["roughness"]["alpha"]]]  # noqa: E731
    f = _reference_plate_model(_set_alpha, starts)(ev)
    if f is None:
        got = _plate_model(_set_alpha, starts=starts, bounds=([1e-3], [1.0]))(ev)
        f = None if got is None else got[0]
    found = _ggx_plates(ev.scene)
    if f is None or not found:
        return f
    declared = float(ev.scene["objects"][found[0][0]]["bsdf"]["roughness"]["alpha"])
    for label, value in (("sqrt(alpha): the renderer squares it", declared ** 0.5),
                         ("alpha^2: the renderer takes roughness for alpha", declared ** 2)):
        if abs(f.values[0] - value) <= 2 * f.se[0]:
            f.note = f"alpha {value:.4g} = {label}"
    return f


def _beckmann(bsdf, x):
    if bsdf["roughness"]["distribution"] != "ggx":
        raise _NotApplicable
    bsdf["roughness"]["distribution"] = "beckmann"


def _no_k(bsdf, x):
    from ....exporters import spectra
    if "material" in bsdf:
        eta, _k = spectra.named_conductor(bsdf.pop("material"))
        bsdf["eta"] = eta
    bsdf["k"] = {"type": "constant", "value": 0.0}


class _NotApplicable(Exception):
    pass


def _fixed(change):
    """A fixed change of the plates' material (no parameter of its own): on the reference evidence
    where there is one (the reference plus the change of the plates' direct light, the indirect
    light's change a nuisance as for alpha: measured, a Beckmann plant on ggx_copper_50 failed
    only the noise test, which the probe's evidence alone never saw), else on the GGX probe's region."""
    def fit(ev):
        try:
            f = _reference_plate_model(change, None)(ev)
            if f is None:
                got = _plate_model(change)(ev)
                f = None if got is None else got[0]
        except _NotApplicable:
            return None
        return f
    return fit




def _emitter_units(ev):
    """The reference evidence with the render pi (or 1/pi) times the reference: no free parameter;
    the freely fitted scale is reported beside it (its value and standard error)."""
    from .image import _uniform
    free = reference_model(_uniform, starts=[[1.0]])(ev)
    if free is None:
        return None
    factor = np.pi if free.values[0] > 1 else 1 / np.pi
    f = reference_model(lambda x, e: _uniform([factor], e))(ev)
    f.values, f.se, f.note = free.values, free.se, f"fixed factor {factor:.6g}"
    return f


def _ior_fit(ev):
    """The dielectric's IOR fitted on the Fresnel probe's region (the reflection through the
    camera's polariser, or unpolarised): the closed form at each trial IOR."""
    from .polarisation import fresnel_image, fresnel_setup
    got = fresnel_setup(ev)
    if got is None:
        return None
    scene, di, li, rgb, light, block = got
    h, w = rgb.shape[:2]
    pol = scene["camera"].get("polarizer")
    angle = None if not pol else float(pol["angle"])
    declared = float(scene["objects"][di]["bsdf"]["int_ior"])
    mask, truth = fresnel_image(scene, di, li, w, h, light, angle)
    if mask.sum() < 8:
        return None

    def predict(x):
        if x is None:
            return truth
        sc = copy.deepcopy(scene)
        sc["objects"][di]["bsdf"]["int_ior"] = float(x[0])
        return np.where(mask[..., None], fresnel_image(sc, di, li, w, h, light, angle)[1], 0.0)
    region = RegionEvidence(rgb, truth, mask, block)
    if len(region) < 2:
        return None
    return region_fit(region, predict, [[declared]], bounds=([1.0], [4.0]))


def _fluorescence_dropped(ev):
    """The lone fluorescent sphere's probe (rho L + integral P L) against rho L alone: the
    renderer drops the re-radiated light (a fluorescent material rendered as its plain
    reflectance). No free parameter."""
    from .. import stats
    from ..probes import fluorescence
    rec = next((r for r in ev.entry.get("probes") or [] if r.get("stat") and r["name"].startswith("lone fluorescent")),
               None)
    env, objs = ev.scene.get("environment"), ev.scene["objects"]
    if rec is None or not env or len(objs) != 1 or (objs[0].get("bsdf") or {}).get("fluorescence") is None:
        return None
    st = rec["stat"]
    m, e, se = (np.asarray(st[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    plain = {k: v for k, v in objs[0]["bsdf"].items() if k != "fluorescence"}
    e0 = fluorescence.expected_rgb(plain, env["radiance"])
    chi2_none = float(np.sum(((m - e) / np.maximum(se, 1e-300)) ** 2))
    chi2 = float(np.sum(((m - e0) / np.maximum(se, 1e-300)) ** 2))
    ok = stats.compare_means(m, e0, se, dof=st.get("dof"))["pass"]
    return Fit([], [], chi2, chi2_none, m.size, 0, ok)


def _rgb_transport(ev):
    """The spectral furnace's probe (probes/furnace.py) against what an RGB renderer gets there:
    rho and Le reduced to linear sRGB channels first (exporters/rgb_reduction.py), then the
    interreflection series per channel (its ``rgb`` record). No free parameter."""
    from .. import stats
    rec = next((r for r in ev.entry.get("probes") or [] if r.get("stat") and r.get("rgb")
                and r["name"].startswith("furnace ")), None)
    if rec is None:
        return None
    st = rec["stat"]
    m, e, se = (np.asarray(st[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    e0 = np.asarray(rec["rgb"]["expected"], dtype=np.float64)
    chi2_none = float(np.sum(((m - e) / np.maximum(se, 1e-300)) ** 2))
    chi2 = float(np.sum(((m - e0) / np.maximum(se, 1e-300)) ** 2))
    ok = stats.compare_means(m, e0, se, dof=st.get("dof"))["pass"]
    gap = ", ".join(f"{c} {100 * g:+.2f} %" for c, g in zip("RGB", rec["rgb"]["gap"]))
    # reported, not fitted (k = 0): the render's measured gap to the spectral truth, per channel, in %
    measured = (100 * (m / e - 1)).tolist()
    return Fit(measured, (100 * se / np.abs(e)).tolist(), chi2, chi2_none, m.size, 0, ok,
               note=f"predicted gap to the spectral truth (rgb_reduction first, then the series): {gap}")


def _white_furnace_record(ev):
    """The GGX white furnace probe's record (probes/white_furnace.py) with its rings, or None."""
    return next((r for r in ev.entry.get("probes") or [] if r.get("stat") and r.get("env_rgb") is not None
                 and " white furnace " in r["name"]), None)


def _multiple_scattering(ev):
    """The white furnace's render as a renderer that keeps a share s of single scattering's
    missing energy: L = (E + s (1 - E)) L_env per pixel (Kulla and Conty 2017, "Revisiting
    Physically Based Shading at Imageworks", SIGGRAPH course: the compensation lobe's albedo is
    1 - E(mu_o) for F = 1; s = 1 is an energy-conserving BSDF, such as Heitz et al. 2016's random
    walk or Turquin 2019's scaled lobe, "Practical multiple scattering compensation for microfacet
    models"). Fitted by weighted least squares on the probe's rings of mu_o (disjoint; the region
    record overlaps them), their rows' means and standard errors as the probe judged them, the
    standard error of s cluster-robust with a ring's three channels one cluster (least_squares);
    reported beside s: the region's measured energy over single scattering's, in %."""
    from .. import stats
    from . import least_squares
    rec = _white_furnace_record(ev)
    if rec is None:
        return None
    st = rec["stat"]
    m, e, se = (np.asarray(st[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    white = np.asarray(rec["env_rgb"], dtype=np.float64)
    miss = white[None, :] - e  # the mean (1 - E) L_env of each group
    rows = slice(1, None)
    if m[rows].shape[0] < 2:
        return None
    w = 1.0 / np.maximum(se, 1e-300)

    def residual(x):
        return ((m[rows] - e[rows] - x[0] * miss[rows]) * w[rows]).ravel()
    found = least_squares(residual, [[0.0]], var_ratio="residuals", channels=3)
    if found is None:
        return None
    x, sx, chi2 = found
    r0 = residual([0.0])
    predicted = e + x[0] * miss
    ok = stats.compare_means(m.ravel(), predicted.ravel(), se.ravel(), dof=None if st.get("dof") is None else np.ravel(st["dof"]),
                             tests=m.size)["pass"]
    gain = 100 * (float(np.sum(m[0])) / float(np.sum(e[0])) - 1.0)
    gain_se = 100 * float(np.sqrt(np.sum(se[0] ** 2))) / float(np.sum(e[0]))
    return Fit([float(x[0]), gain], [float(sx[0]), gain_se], float(chi2), float(r0 @ r0), r0.size, 1, ok,
               note=f"alpha {rec.get('alpha')}: the region {gain:+.2f} % brighter than single scattering; "
                    f"1 - E there {100 * (1 - rec['mean_albedo'][0]):.2f} %")


def _height_correlated_furnace(ev):
    """The white furnace judged with the height-correlated Smith G2 = 1 / (1 + Lambda(o) +
    Lambda(i)) (pbrt-v4's and Cycles' form; the IR's is separable G1 G1): the probe's own
    alternative, no free parameter."""
    from ..probes.ggx import SHADOWING_FORMS, shadowing_key
    rec = _white_furnace_record(ev)
    if rec is None:
        return None
    other = next(f for f in SHADOWING_FORMS if f != rec.get("shadowing"))
    alt = (rec.get("alternatives") or {}).get(shadowing_key(other))
    if alt is None:
        return None
    st = rec["stat"]
    m, e, se = (np.asarray(st[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    e1, se1 = (np.asarray(alt[k], dtype=np.float64) for k in ("expected", "se"))
    chi2_none = float(np.sum(((m - e) / np.maximum(se, 1e-300)) ** 2))
    chi2 = float(np.sum(((m - e1) / np.maximum(se1, 1e-300)) ** 2))
    return Fit([], [], chi2, chi2_none, m.size, 0, bool(alt["pass"]))


def _film_setup(ev):
    """(scene, index of the filmed sphere, the render's R, G, B, the probe's tiles, the trial cache) or None."""
    from ..probes import thin_film
    if "R" not in ev.names[:3] or not ev.scene.get("environment"):
        return None
    films = [i for i, o in enumerate(ev.scene["objects"]) if thin_film.applies(o) and "material" not in o["bsdf"]]
    if not films or not any(r["name"].startswith("airy film") and r.get("stat") for r in ev.entry.get("probes") or []):
        return None
    i = films[0]
    rgb = np.asarray(ev.image[..., :3], dtype=np.float64)
    h, w = rgb.shape[:2]
    _, mask = thin_film.expected_image(ev.scene, i, w, h, cache=ev.cache.setdefault(FILM_CACHE, {}))
    blocks = thin_film.tiles(mask)
    return (ev.scene, i, rgb, blocks, ev.cache[FILM_CACHE]) if blocks else None


def _film_stat(scene, i, rgb, blocks, thickness, cache=None):
    """The Airy probe's tile test with the film ``thickness`` nm thick (0: no film: the bare
    conductor's Fresnel reflectance, Airy's limit). ``cache``: the probe's sub-rays and the film's
    interfaces kept across trial thicknesses (probes/thin_film.py ``expected_images``)."""
    from .. import stats
    from ..probes import thin_film
    sc = copy.deepcopy(scene)
    sc["objects"][i]["bsdf"]["thin_film"]["thickness"] = float(thickness)
    h, w = rgb.shape[:2]
    expected, _ = thin_film.expected_image(sc, i, w, h, cache=cache)
    return thin_film._tile_stat(rgb, expected, blocks, stats.ALPHA)


def _chi2(stat):
    m, e, s = (np.asarray(stat[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    return float(np.sum(((m - e) / np.maximum(s, 1e-300)) ** 2)), m.size


def _film_missing(ev):
    got = _film_setup(ev)
    if got is None:
        return None
    scene, i, rgb, blocks, cache = got
    chi2_none, n = _chi2(_film_stat(scene, i, rgb, blocks, scene["objects"][i]["bsdf"]["thin_film"]["thickness"],
                                    cache))
    bare = _film_stat(scene, i, rgb, blocks, 0.0, cache)
    return Fit([], [], _chi2(bare)[0], chi2_none, n, 0, bare["pass"])


def _film_thickness(ev):
    """The film's thickness fitted on the Airy probe's tiles: a coarse scan around the declared one
    (a film's colour repeats with its thickness: local minima), then weighted least squares from
    the best with the cluster-robust standard error (a tile's R, G and B one cluster: least_squares)."""
    got = _film_setup(ev)
    if got is None:
        return None
    scene, i, rgb, blocks, cache = got
    declared = float(scene["objects"][i]["bsdf"]["thin_film"]["thickness"])

    def residual(x):
        st = _film_stat(scene, i, rgb, blocks, float(x[0]), cache)
        m, e, s = (np.asarray(st[k], dtype=np.float64) for k in ("measured", "expected", "se"))
        return (m - e) / np.maximum(s, 1e-300)
    lo, hi = max(0.0, declared * 0.5), declared * 1.5 + 10.0
    grid = np.linspace(lo, hi, 21)
    start = grid[int(np.argmin([float(residual([d]) @ residual([d])) for d in grid]))]
    found = least_squares(residual, [[start]], bounds=([lo], [hi]), var_ratio="residuals", channels=3)
    if found is None:
        return None
    x, err, chi2 = found
    r0 = residual([declared])
    ok = _film_stat(scene, i, rgb, blocks, float(x[0]), cache)["pass"]
    return Fit([float(x[0])], [float(err[0])], chi2, float(r0 @ r0), r0.size, 1, ok)


def _prism_setup(ev):
    """(scene, index of the dispersive dielectric, the positions probe's record, the screen's
    pixel coordinates along the fan) when the prism's band-position probe was computed, else None."""
    from ....exporters import dispersion
    from ..probes import prism
    rec = next((r for r in ev.entry.get("probes") or [] if r["name"].startswith("prism band positions")
                and r.get("origin_px") and r.get("measured") is not None), None)
    if rec is None:
        return None
    glass = [i for i, o in enumerate(ev.scene["objects"])
             if dispersion.is_dispersive((o.get("bsdf") or {}).get("int_ior"))]
    if not glass:
        return None
    h, w = ev.image.shape[:2]
    gt = prism.expected(ev.scene, w, h, step_nm=DISPERSION_STEP_NM)
    if gt is None or "error" in gt:
        return None
    ys, xs = np.nonzero(gt["mask"])
    s = (np.stack([xs + 0.5, ys + 0.5], axis=-1) - np.asarray(rec["origin_px"])) @ np.asarray(rec["fan_direction"])
    return ev.scene, glass[0], rec, gt["mask"], s


DISPERSION_STEP_NM = 5.0  # one IOR: every wavelength lands on the same spot, only the colour's weights are summed


def _centroids(scene, glass, ior, mask, s, shape):
    """Each channel's centroid along the fan (the positions probe's coordinate) of the expected
    image with the dielectric's dispersion replaced by one IOR."""
    from ..probes import prism
    sc = copy.deepcopy(scene)
    sc["objects"][glass]["bsdf"]["int_ior"] = float(ior)
    gt = prism.expected(sc, shape[1], shape[0], step_nm=DISPERSION_STEP_NM)
    if gt is None or "error" in gt:
        return None
    e = gt["image"][mask]
    tot = e.sum(axis=0)
    return np.where(np.abs(tot) > 0, (s[:, None] * e).sum(axis=0) / np.where(np.abs(tot) > 0, tot, 1.0), np.nan)


def _dispersion_missing(ev):
    """The prism's band positions as one IOR would put them (a dielectric rendered without its
    dispersion: every wavelength refracted alike, one white spot): the IOR fitted to the three
    channels' measured centroids along the fan (the positions probe's statistic, its standard
    errors), a coarse scan over the glass's own n(360..830 nm) widened by 0.05, then a bounded
    scalar search; its standard error from the centroid's slope in n (one parameter, three
    independent channel centroids: 1 / sqrt(sum (ds/dn / se_c)^2)). Fully explains when the
    centroids then pass the probe's test (Sidak over the channels, the record's degrees of freedom)."""
    from scipy import optimize

    from ....exporters import dispersion
    from .. import stats
    got = _prism_setup(ev)
    if got is None:
        return None
    scene, glass, rec, mask, s = got
    m = np.asarray(rec["measured"], dtype=np.float64)
    se = np.asarray([np.nan if x is None else x for x in rec["standard_error_px"]], dtype=np.float64)
    e0 = np.asarray(rec["expected"], dtype=np.float64)
    use = np.isfinite(m) & np.isfinite(se) & (se > 0)
    if use.sum() < 2:
        return None
    shape = ev.image.shape[:2]

    def chi2(n):
        c = _centroids(scene, glass, n, mask, s, shape)
        if c is None or not np.all(np.isfinite(c[use])):
            return np.inf
        return float(np.sum(((m - c) / se)[use] ** 2))
    n_wl = dispersion.ior(scene["objects"][glass]["bsdf"]["int_ior"], np.array([360.0, 830.0]))
    lo, hi = float(n_wl.min()) - 0.05, float(n_wl.max()) + 0.05
    grid = np.linspace(lo, hi, 21)
    values = [chi2(n) for n in grid]
    k = int(np.argmin(values))
    if not np.isfinite(values[k]):
        return None
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    r = optimize.minimize_scalar(chi2, bounds=(a, b), method="bounded", options={"xatol": 1e-6})
    n_hat = float(r.x)
    h = 1e-4
    c_hi, c_lo = _centroids(scene, glass, n_hat + h, mask, s, shape), _centroids(scene, glass, n_hat - h, mask, s, shape)
    slope = (c_hi - c_lo) / (2 * h)
    info = float(np.sum((slope / se)[use] ** 2))
    err = 1 / np.sqrt(info) if info > 0 else np.inf
    c = _centroids(scene, glass, n_hat, mask, s, shape)
    dof = rec.get("dof") or [None] * 3
    dof = np.asarray([np.inf if d is None else d for d in dof], dtype=np.float64)[use]
    ok = stats.compare_means(m[use], c[use], se[use], dof=dof)["pass"]
    chi2_none = float(np.sum(((m - e0) / se)[use] ** 2))
    return Fit([n_hat], [float(err)], float(r.fun), chi2_none, int(use.sum()), 1, bool(ok),
               note="the centroids of R, G and B along the fan, one IOR for every wavelength")


MODELS = [
    Model("GGX alpha", FAMILY, ("alpha", "indirect"), "reference+ggx",
          "the microfacet roughness is not the declared alpha (or alpha vs alpha squared conventions)",
          lambda ev: _alpha_fit(ev), slow=True),
    Model("Beckmann for GGX", FAMILY, ("indirect",), "reference+ggx",
          "a Beckmann distribution rendered where GGX is declared", _fixed(_beckmann), slow=True),
    Model("conductor without k", FAMILY, ("indirect",), "reference+ggx",
          "the conductor's extinction coefficient k dropped (only eta used)", _fixed(_no_k), slow=True),
    Model("dielectric IOR", FAMILY, ("ior",), "probe:fresnel",
          "the dielectric's index of refraction is not the declared one (another IOR, or one of another medium)",
          _ior_fit, slow=True),
    Model("dispersion missing", FAMILY, ("ior",), "probe:prism",
          "the dielectric rendered with one IOR for every wavelength (no dispersion: the fan collapses to one spot)",
          _dispersion_missing, slow=True),
    Model("fluorescence dropped", FAMILY, (), "probe:lone",
          "the fluorescent material rendered without its re-radiation (rho L alone, the integral of P L dropped)",
          _fluorescence_dropped),
    Model("RGB transport", FAMILY, ("measured gap R %", "G %", "B %"), "probe:furnace",
          "rho and Le reduced to RGB channels before the interreflection series (an RGB renderer: per wavelength "
          "the series 1 / (1 - rho) is convex, so the channel averages miss it)", _rgb_transport),
    Model("multiple scattering", FAMILY, ("kept share of 1 - E", "region gain %"), "probe:white furnace",
          "the renderer keeps multiple scattering between microfacets (Kulla and Conty 2017: a share of the energy "
          "1 - E that single scattering loses comes back; Cycles' Multiscatter GGX): not wrong, but not the IR's "
          "single scattering", _multiple_scattering),
    Model("height-correlated Smith", FAMILY, (), "probe:white furnace",
          "the renderer's shadowing-masking is the height-correlated G2 = 1 / (1 + Lambda(o) + Lambda(i)), not the "
          "IR's separable G1 G1 (pbrt-v4, Cycles)", _height_correlated_furnace),
    Model("thin film missing", FAMILY, (), "probe:airy",
          "the conductor rendered without its thin film (the bare interface's Fresnel reflectance)", _film_missing,
          slow=True),
    Model("thin film thickness", FAMILY, ("thickness nm",), "probe:airy",
          "the film's thickness is not the declared one (another unit, or the film measured another way)",
          _film_thickness, slow=True),
    Model("emitter radiance x pi", FAMILY, ("factor",), "reference",
          "emitter units: radiance where exitance was due, or the other way (a factor pi)",
          _emitter_units, deviation=lambda f: {"scale": float(np.pi if f.values[0] > 1 else 1 / np.pi), "scale_se": 0.0}),
]
