"""The probes' faster computations (issue 45 item 1) pinned to the straightforward ones they
replace, bit for bit, on small cases: the same expected images, so the same verdicts."""
import numpy as np
import pytest

from spectral_bench.batch.verdict.probes import common


def test_lerp_is_the_fancy_indexed_interpolation_bit_for_bit():
    rng = np.random.default_rng(45)
    table = rng.normal(size=(1025, 3))
    x = rng.random((64, 33)) * (len(table) - 1)
    x[0, :3] = [0.0, len(table) - 1, len(table) - 1.5]  # both ends of the table
    i = np.minimum(x.astype(np.intp), len(table) - 2)
    f = x - i
    plain = table[i] + f[..., None] * (table[1:] - table[:-1])[i]
    fast = common.lerp(table, i, f)
    assert fast.shape == plain.shape == (64, 33, 3)
    assert np.array_equal(fast.view(np.int64), plain.view(np.int64))


def _hit_rectangle_plain(shape, origin, dirs, margin=1.0):
    """raycast.hit_rectangle as it was written before issue 45: the whole local hit point."""
    m = np.asarray(shape["to_world"], dtype=np.float64)
    inv = np.linalg.inv(m)
    o_local = (inv @ np.append(origin, 1.0))[:3] if np.ndim(origin) == 1 else (origin @ inv[:3, :3].T + inv[:3, 3])
    d_local = dirs @ inv[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o_local[..., 2] / d_local[..., 2]
    p = o_local + np.where(np.isfinite(t), t, 0.0)[..., None] * d_local
    inside = (np.abs(p[..., 0]) <= margin) & (np.abs(p[..., 1]) <= margin) & (t > 1e-9)
    return np.where(inside, t, np.inf)


def test_hit_rectangle_is_the_plain_intersection_bit_for_bit():
    from spectral_bench.batch.verdict import raycast
    rng = np.random.default_rng(45)
    m = np.eye(4)
    m[:3, :3] = [[2.0, 0.0, 0.0], [0.0, 0.0, -2.0], [0.0, 2.0, 0.0]]  # a floor, turned and shifted
    m[:3, 3] = [0.1, -0.5, 0.2]
    shape = {"type": "rectangle", "to_world": m.tolist()}
    camera = {"to_world": [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 5], [0, 0, 0, 1]], "fov": 60}
    origin, corners = raycast.camera_rays(camera, 40, 30, "corners")
    points, dirs = rng.normal(size=(30, 40, 3)), rng.normal(size=(30, 40, 3))
    dirs[0, 0] = [1.0, 0.0, 0.0]  # parallel to the rectangle: no hit
    for o, d in ((origin, corners), (points, dirs), (origin, dirs)):
        for margin in (1.0, 0.7):
            plain = _hit_rectangle_plain(shape, o, d, margin)
            fast = raycast.hit_rectangle(shape, o, d, margin)
            assert np.isfinite(plain).any() and not np.isfinite(plain).all()
            assert np.array_equal(fast, plain)


def test_thin_film_tile_moments_are_each_tiles_own_bit_for_bit():
    from spectral_bench.batch.verdict.probes import thin_film
    rng = np.random.default_rng(45)
    rgb, expected = rng.random((48, 40, 3)), rng.random((48, 40, 3))
    mask = rng.random((48, 40)) < 0.75
    blocks = thin_film.tiles(mask)
    counts = {len(ys) for ys, _xs in blocks}
    assert len(counts) >= 5 and min(counts) >= thin_film.MIN_TILE_PIXELS  # tiles of many sizes
    meas, exp, se, n = thin_film.tile_moments(rgb, expected, blocks)
    for k, (ys, xs) in enumerate(blocks):  # the straightforward loop the function replaces
        m_px, e_px = rgb[ys, xs], expected[ys, xs]
        assert n[k] == len(ys)
        assert np.array_equal(meas[k], m_px.mean(axis=0))
        assert np.array_equal(exp[k], e_px.mean(axis=0))
        assert np.array_equal(se[k], (m_px - e_px).std(axis=0, ddof=1) / np.sqrt(len(ys)))


def test_emitted_each_is_one_emitted_call_per_spectrum_bit_for_bit():
    from spectral_bench.exporters import fluorescence as fluo
    fl = {"type": "bands", "absorption_peak": 450.0, "absorption_width": 40.0, "emission_peak": 560.0,
          "emission_width": 50.0, "strength": 0.01}
    wl = np.arange(380.0, 781.0, 5.0)
    lights = [lambda x: np.ones_like(x), lambda x: 1.0 + np.sin(x / 30.0) ** 2, lambda x: x / 500.0]
    each = fluo.emitted_each(fl, lights, wl)
    assert len(each) == 3 and np.any(each[0] > 0)
    l_i = np.arange(fluo.DOMAIN[0], fluo.DOMAIN[1] + 0.025, 0.05)  # emitted's own grid (step 0.05 nm)
    for light, got in zip(lights, each):  # the loop emitted ran per spectrum before issue 45
        plain = np.empty(wl.shape)
        for k in range(0, wl.size, 64):
            p = fluo.reradiation(fl, l_i[None, :], wl[k:k + 64, None])
            plain[k:k + 64] = np.trapz(p * light(l_i)[None, :], l_i, axis=1)
        assert np.array_equal(got, plain)
        assert np.array_equal(fluo.emitted(fl, light, wl), plain)


def test_ggx_block_moments_are_each_blocks_own_bit_for_bit():
    from spectral_bench.batch.verdict import compare
    from spectral_bench.batch.verdict.probes import ggx
    rng = np.random.default_rng(45)
    h, w = 90, 75
    measured = rng.random((h, w, 3)).astype(np.float32)  # renders are float32, the expected float64
    expected = rng.random((h, w, 3))
    yy, xx = np.mgrid[:h, :w]
    mask = (yy - 40) ** 2 + (xx - 35) ** 2 < 33 ** 2  # a plate's edge cuts blocks of many sizes
    edges = (compare.block_edges(h, 16), compare.block_edges(w, 16))  # blocks of 16 to 31 pixels a side
    y_row = np.array([0.2126, 0.7152, 0.0722])
    blocks = ggx.block_pixels(mask, edges)
    meas, exp, se, n, rows = ggx.block_moments(measured, expected, blocks, y_row)
    k = 0
    for y0, y1 in zip(edges[0][:-1], edges[0][1:]):  # the loop ggx._judge ran before issue 45
        for x0, x1 in zip(edges[1][:-1], edges[1][1:]):
            sel = mask[y0:y1, x0:x1]
            if sel.sum() < ggx.MIN_PIXELS:
                continue
            m_px = measured[y0:y1, x0:x1][sel].astype(np.float64)
            e_px = expected[y0:y1, x0:x1][sel]
            resid = m_px - e_px
            assert n[k] == len(m_px)
            assert np.array_equal(meas[k], m_px.mean(axis=0)) and np.array_equal(exp[k], e_px.mean(axis=0))
            assert np.array_equal(se[k], resid.std(axis=0, ddof=1) / np.sqrt(len(m_px)))
            assert rows[k] == (m_px.mean(axis=0) @ y_row, e_px.mean(axis=0) @ y_row,
                               float((resid @ y_row).std(ddof=1) / np.sqrt(len(m_px))))
            k += 1
    assert k == len(blocks) and len(set(n.tolist())) >= 5 and n.max() >= 256


def test_rough_film_geometry_is_shared_by_scenes_that_differ_in_camera_name_bit_for_bit(golden):
    """iridescent_spheres_film, _height and _materials differ in their materials and camera names
    alone: the rough-film probe's sphere geometry (the occlusion quadrature) is computed for the
    first and taken by the others, and it is what each scene's own camera, name and all, gives."""
    import copy
    from spectral_bench.batch.verdict.probes import rough_film
    names = ["iridescent_spheres_film", "iridescent_spheres_height", "iridescent_spheres_materials"]
    w, h = 100, 32  # the 800 x 256 scenes at 1/8
    scenes = [copy.deepcopy(golden[n]) for n in names]
    assert len({s["camera"]["name"] for s in scenes}) == 3
    index = rough_film.applies(scenes[0])[1]
    rough_film._geometry.cache.clear()
    first = rough_film.sphere_geometry(scenes[0], index, w, h)
    for scene in scenes:
        got = rough_film.sphere_geometry(scene, index, w, h)
        assert got is first  # remembered: the later scenes pay nothing
        alpha = float(scene["objects"][index]["bsdf"]["roughness"]["alpha"])
        plain = rough_film._geometry.__wrapped__(scene["camera"], [o["shape"] for o in scene["objects"]], index,
                                                 alpha, w, h)  # the whole camera, as before issue 45's key
        assert len(plain) == len(got) == 6 and len(got[0]) > 50
        for a, b in zip(got, plain):
            assert a.dtype == b.dtype and np.array_equal(a, b) and np.array_equal(a.view(np.uint8), b.view(np.uint8))


def _rough_judge_plain(px, lo, hi, blocks, alpha):
    """rough_film._judge as it was before issue 45's change: one_sided_p called per group."""
    from scipy import stats as _st
    from spectral_bench.batch.verdict import stats
    from spectral_bench.batch.verdict.probes import rough_film
    n = len(px)
    groups = [np.arange(n)] + list(blocks)
    tests = len(groups) * 6
    threshold = stats.sidak_threshold(alpha, tests)
    p_all, z_all, out = [], [], {}
    kept = {"measured": [], "lo": [], "hi": [], "se": [], "dof": []}
    for g_i, g in enumerate(groups):
        m, lo_m, hi_m = px[g].mean(axis=0), lo[g].mean(axis=0), hi[g].mean(axis=0)
        se = (px[g] - lo[g]).std(axis=0, ddof=1) / np.sqrt(len(g))
        for key, value in (("measured", m), ("lo", lo_m), ("hi", hi_m), ("se", se)):
            kept[key].append(np.round(value, 10).tolist())
        kept["dof"].append(len(g) - 1)
        z_hi = (m - hi_m) / np.maximum(se, 1e-300)
        z_lo = (lo_m - m) / np.maximum(se, 1e-300)
        p = np.minimum(stats.one_sided_p(z_hi, len(g) - 1), stats.one_sided_p(z_lo, len(g) - 1))
        p_all.append(p)
        z_all.append(np.maximum(z_hi, z_lo))
        if g_i == 0:
            shift = _st.t.isf(threshold, n - 1) + _st.t.isf(1 - rough_film.POWER, n - 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                out = {"lo": lo_m.tolist(), "hi": hi_m.tolist(), "measured": m.tolist(), "se": se.tolist(),
                       "dof": n - 1, "detectable_up": (shift * se / np.abs(hi_m)).tolist(),
                       "detectable_down": (shift * se / np.abs(lo_m)).tolist(),
                       "width": ((hi_m - lo_m) / np.abs(lo_m)).tolist(), "region_p": float(np.min(p))}
    p_all, z_all = np.array(p_all), np.array(z_all)
    worst = np.unravel_index(np.argmin(p_all), p_all.shape)
    out.update({"pass": bool(np.all(p_all >= threshold) and np.all(np.isfinite(px))), "p": float(p_all.min()),
                "threshold": threshold, "tests": tests, "tiles": len(blocks), "z": float(np.max(z_all)),
                "worst": "region" if worst[0] == 0 else f"tile {worst[0]}", "worst_channel": "RGB"[worst[1]],
                "groups": kept})
    return out


def test_rough_film_judge_takes_every_group_s_p_at_once_bit_for_bit():
    """rough_film._judge's p-values of all groups in one call per side: the same record, every
    number and key in order, as one call per group, for passing and failing groups of many sizes
    (tiles of 16 x 16 pixels, some part-covered) and both sides."""
    import json
    from spectral_bench.batch.verdict.probes import rough_film
    rng = np.random.default_rng(45)
    ys, xs = np.nonzero(rng.random((120, 150)) < 0.9)
    lo = 0.2 + 0.6 * rng.random((len(ys), 3))
    hi = lo * (1 + 0.01 * rng.random((len(ys), 3)))
    outcomes = set()
    for shift in (0.0, 0.004, -0.004, 0.05):  # inside, a little above / below, far above
        px = (lo + hi) / 2 * (1 + shift) + 0.01 * rng.normal(size=lo.shape)
        if shift:
            px[(ys // 16 == 3) & (xs // 16 == 4)] *= 1.02  # one tile off too
        blocks = rough_film._tiles(ys, xs)
        assert len(blocks) >= 50 and len({len(b) for b in blocks}) >= 3
        for alpha in (0.01, 1e-4):
            fast = rough_film._judge(px, lo, hi, blocks, alpha)
            plain = _rough_judge_plain(px, lo, hi, blocks, alpha)
            assert json.dumps(fast) == json.dumps(plain)
            outcomes.add(fast["pass"])
    assert outcomes == {True, False}  # passing and failing records alike


def test_rough_film_lookup_at_shared_cosines_is_the_plain_lookup_bit_for_bit():
    from spectral_bench.batch.verdict.probes import rough_film
    rng = np.random.default_rng(45)
    theta = np.linspace(0.0, np.pi / 2, rough_film.THETA_TABLE)
    cos = rng.random((500, 16))
    cos[0, :4] = [0.0, 1.0, 1e-12, 1 - 1e-12]  # the grid's ends
    at = rough_film._lookup_at(theta, cos)
    for _ in range(2):  # two tables (the ground truth's and an observer's) at the same cosines
        table = rng.random((rough_film.THETA_TABLE, 3))
        x = np.arccos(np.clip(cos, 0.0, 1.0)) * ((len(theta) - 1) / (np.pi / 2))  # _lookup before issue 45
        i = np.minimum(x.astype(np.intp), len(theta) - 2)
        plain = table[i] + (x - i)[..., None] * (table[i + 1] - table[i])
        assert np.array_equal(rough_film._lookup(theta, table, cos, at).view(np.int64), plain.view(np.int64))
        assert np.array_equal(rough_film._lookup(theta, table, cos).view(np.int64), plain.view(np.int64))


def _rough_fresnel_plain(bsdf):
    """rough_film.fresnel_table as it was before issue 45: airy.py's functions on the whole table."""
    from spectral_bench.batch.verdict import airy
    from spectral_bench.batch.verdict.probes import rough_film
    from spectral_bench.exporters import spectra
    wl = spectra.cie_1931_cmfs()[0]
    eta_s, k_s = rough_film._eta_k(bsdf)
    n3 = spectra.evaluate(eta_s, wl) + 1j * spectra.evaluate(k_s, wl)
    cos = np.linspace(0.0, 1.0, rough_film.COS_TABLE)
    film = bsdf.get("thin_film")
    if film is None:
        rs, rp = airy.bare_reflectance(cos[:, None], 1.0, n3[None, :])
        return 0.5 * (rs + rp)
    return airy.unpolarized_reflectance(cos[:, None], wl[None, :], film.get("ext_ior", 1.0), film["ior"],
                                        film["thickness"], n3[None, :])


@pytest.mark.parametrize("cos_table", [257, pytest.param(None, marks=pytest.mark.slow)])
def test_rough_film_fresnel_table_sharing_the_base_is_airy_s_bit_for_bit(golden, monkeypatch, cos_table):
    """The rough-film probe's Fresnel tables with the base's part (q3) computed once per base and
    exterior: the same numbers as airy.py's functions for every rough sphere of the three
    iridescent sphere scenes (filmed and bare, two bases), a named conductor and another exterior;
    on 257 cosines (fast) and on the probe's own COS_TABLE (slow: 8 s)."""
    from spectral_bench.batch.verdict.probes import rough_film
    if cos_table is not None:
        monkeypatch.setattr(rough_film, "COS_TABLE", cos_table)
    try:
        _check_rough_fresnel_tables(golden)
    finally:  # the remembered tables are keyed by the material alone: none of another size is left
        rough_film._base_side.cache.clear()
        rough_film.fresnel_table.cache.clear()


def _check_rough_fresnel_tables(golden):
    import copy
    from spectral_bench.batch.verdict.probes import rough_film
    bsdfs = [copy.deepcopy(golden[n]["objects"][i]["bsdf"])
             for n in ("iridescent_spheres_film", "iridescent_spheres_height", "iridescent_spheres_materials")
             for i in rough_film.applies(golden[n])]
    assert len(bsdfs) == 12 and sum(b.get("thin_film") is None for b in bsdfs) >= 2
    other = copy.deepcopy(bsdfs[0])
    other["thin_film"] = dict(other["thin_film"], ext_ior=1.33, thickness=333.0)
    named = {"type": "conductor", "material": "Au", "roughness": {"alpha": 0.2, "distribution": "beckmann"}}
    rough_film._base_side.cache.clear()
    rough_film.fresnel_table.cache.clear()
    for bsdf in bsdfs + [other, named, dict(named, thin_film={"ior": 1.4, "thickness": 400.0})]:
        cos, wl, got = rough_film.fresnel_table(bsdf)
        plain = _rough_fresnel_plain(bsdf)
        assert got.shape == plain.shape == (rough_film.COS_TABLE, len(wl))
        assert np.array_equal(got.view(np.int64), plain.view(np.int64))
    assert len(rough_film._base_side.cache) < len(rough_film.fresnel_table.cache) - 5  # bases shared


def test_white_furnace_geometry_is_shared_by_the_ggx_furnaces_bit_for_bit(golden):
    """furnace_ggx_010 ... 100 differ in alpha and camera name alone: the white-furnace probe's
    pixel geometry is computed for the first and taken by the others, and it is what each scene's
    own camera, name and all, gives."""
    import copy
    from spectral_bench.batch.verdict import raycast
    from spectral_bench.batch.verdict.probes import white_furnace
    scenes = [copy.deepcopy(golden[f"furnace_ggx_{a}"]) for a in ("010", "030", "060", "100")]
    assert len({s["camera"]["name"] for s in scenes}) == 4
    white_furnace.geometry.cache.clear()
    first = None
    for scene in scenes:
        i = white_furnace.applies(scene)
        shape = scene["objects"][i]["shape"]
        got = white_furnace.geometry(raycast.camera_fields(scene["camera"]), shape, 64, 64)
        first = first or got
        assert got is first
        plain = white_furnace.geometry.__wrapped__(scene["camera"], shape, 64, 64)
        assert len(got[0]) > 100
        for a, b in zip(got, plain):
            assert a.dtype == b.dtype and np.array_equal(a.view(np.uint8), b.view(np.uint8))


def test_lambert_patches_cast_no_ray_in_a_scene_without_patches(golden, monkeypatch):
    """The Lambert probe casts its corner rays only where a scene has patches: a scene with a sky
    and none gives no record, as before, without the cast; a chart still gets its records."""
    import copy
    from spectral_bench.batch.verdict import raycast
    from spectral_bench.batch.verdict.probes import common, lambert
    chart = copy.deepcopy(golden["macbeth_chart_D65"])
    chart["render"]["width"], chart["render"]["height"] = 96, 64
    casts = []
    real = raycast.corner_hits
    monkeypatch.setattr(raycast, "corner_hits", lambda *a: casts.append(1) or real(*a))
    skies = [n for n, sc in golden.items() if sc.get("environment") and not list(lambert._patches(sc))][:6]
    assert len(skies) == 6
    for name in skies:
        sc = golden[name]
        img = np.full((8, 12, 3), 0.5, dtype=np.float32)
        assert lambert.patches(common.Measurement(sc, ["R", "G", "B"], img)) == []
    assert casts == []
    img = (0.5 + 0.01 * np.random.default_rng(45).normal(size=(64, 96, 3))).astype(np.float32)
    records = lambert.patches(common.Measurement(chart, ["R", "G", "B"], img))
    assert casts == [1] and len(records) > 20 and records[-1]["name"] == "lambert chart luminance scale"
