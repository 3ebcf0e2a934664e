"""Iridescence case: the thin-film conductor plugin (exporters/mitsuba_plugins/thin_film_conductor.py)
against an independent numpy Airy summation and against Mitsuba's own conductor, its sampling
(chi-square, weight = eval / pdf), its limits (thickness 0, a very thick film), the Airy probe
(passes for the scene's film, fails for one 200 nm thinner), the IR/writers around it, and the
scenes against their references through the real command line."""
import copy
import subprocess
import sys

import numpy as np
import pytest

from conftest import IRIDESCENCE, assert_sees, metrics, noise_test, render, render_with_noise, run_batch
from spectral_bench.batch import backends, exr
from spectral_bench.batch.verdict import airy, probes, references, stats
from spectral_bench.exporters import art_writer, ir, mitsuba_plugins, mitsuba_writer, spectra, validate

PLUGIN = "sb_thin_film_conductor"


def _variant(name):
    import mitsuba as mi
    mi.set_variant(name)
    mitsuba_plugins.register([PLUGIN])
    return mi


def _si(mi, wi, wavelengths):
    import drjit as dr
    n = wi.shape[1]
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*wi)
    si.wavelengths = mi.UnpolarizedSpectrum(np.ascontiguousarray(wavelengths, dtype=np.float32))
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    return si


def _film(mi, thickness, rough=None, film_ior=1.33, eta=1.9, k=1.5, ext_ior=1.0, material=None):
    d = {"type": PLUGIN, "film_ior": film_ior, "film_thickness": thickness, "ext_ior": ext_ior}
    d.update({"material": material} if material else {"eta": eta, "k": k})
    if rough:
        d.update(distribution=rough[0], alpha=rough[1])
    return mi.load_dict(d)


# -- the optics -------------------------------------------------------------------------------
@pytest.mark.parametrize("n1, n2, d, eta, k", [(1.0, 1.33, 550.0, 1.9, 1.5), (1.0, 1.0001, 550.0, 0.27, 2.78),
                                               (1.5, 1.2, 300.0, 1.9, 1.5),  # total reflection in the film
                                               (1.0, 2.8, 2000.0, 0.2, 3.0), (1.0, 1.5, 0.0, 1.9, 1.5)])
def test_plugin_amplitudes_equal_the_independent_airy_sum(n1, n2, d, eta, k):
    """Complex s and p amplitudes, phases included: the plugin (Mitsuba's e^{+iwt}, n = eta - ik)
    is the complex conjugate of the numpy module (Born and Wolf's e^{-iwt}, n = eta + ik)."""
    mi = _variant("llvm_ad_spectral")
    from spectral_bench.exporters.mitsuba_plugins import thin_film_conductor as tfc
    theta, wl = np.linspace(0.0, 1.56, 200), np.linspace(360.0, 830.0, 200)
    u = lambda a: mi.UnpolarizedSpectrum(np.tile(np.asarray(a, np.float32), (4, 1)))
    rs, rp = tfc.airy_amplitudes(u(np.cos(theta)), u(wl), n1, n2, d, u(eta + 0 * wl), u(k + 0 * wl))
    expect_s, expect_p = airy.film_amplitudes(np.cos(theta), wl, n1, n2, d, eta + 1j * k)
    for got, expect in ((rs, expect_s), (rp, expect_p)):
        z = np.array(got[0])[0] + 1j * np.array(got[1])[0]
        # float32 against float64: near grazing (cos 0.01) the roots and quotients keep ~4 digits
        # (measured 1e-4 at d = 0), and the phase 4 pi n2 d cos / lambda (up to 195 rad at 2000 nm)
        # is good to a few ulp of itself, ~2e-6 rad per rad; amplitudes are <= 1
        phase_max = 4 * np.pi * n2 * d / wl.min()
        assert np.abs(z - np.conj(expect)).max() < 2e-4 + 2e-6 * phase_max


def test_numpy_airy_limits():
    """Thickness 0 and film index = exterior index are the bare base; the identity r13 =
    (r12 + r23) / (1 + r12 r23) holds for both polarisations."""
    cos1, wl, n3 = np.linspace(0.01, 1.0, 50), 550.0, 0.27 + 2.78j
    bare = airy.bare_reflectance(cos1, 1.0, n3)
    for got in (airy.film_reflectance(cos1, wl, 1.0, 1.5, 0.0, n3), airy.film_reflectance(cos1, wl, 1.0, 1.0, 400.0, n3)):
        np.testing.assert_allclose(got, bare, atol=1e-12)
    # a lossless film on a lossless base conserves energy: R + T = 1 is not checked here, but R <= 1 is
    assert np.all(np.asarray(airy.film_reflectance(cos1, np.linspace(360, 830, 50), 1.0, 1.8, 900.0, 1.5 + 0j)) <= 1 + 1e-12)


def test_thickness_zero_is_mitsubas_conductor_mueller_matrix():
    """*_polarized: with no film the Mueller matrix (Stokes bases included) is Mitsuba's conductor's
    and roughconductor's; a film whose index equals the exterior's is invisible too."""
    mi = _variant("llvm_ad_spectral_polarized")
    rng = np.random.default_rng(1)
    n = 512
    theta, phi = rng.uniform(0.0, 1.5, n), rng.uniform(0, 2 * np.pi, n)
    wi = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    si = _si(mi, wi, rng.uniform(360, 830, (4, n)))
    ctx = mi.BSDFContext()
    sample2 = mi.Point2f(rng.uniform(size=n), rng.uniform(size=n))
    pairs = [(_film(mi, 0.0), mi.load_dict({"type": "conductor", "eta": 1.9, "k": 1.5})),
             (_film(mi, 0.0, material="Cu"), mi.load_dict({"type": "conductor", "material": "Cu"})),
             (_film(mi, 777.0, film_ior=1.0), mi.load_dict({"type": "conductor", "eta": 1.9, "k": 1.5}))]
    for film, native in pairs:
        a, b = np.array(film.sample(ctx, si, 0.5, sample2)[1]), np.array(native.sample(ctx, si, 0.5, sample2)[1])
        # float32 rounding of a reordered formula (measured up to 2e-4 near grazing)
        assert np.abs(a - b).max() < 5e-4 and np.abs(b).max() > 0.1
    rough = _film(mi, 0.0, ("ggx", 0.3))
    native = mi.load_dict({"type": "roughconductor", "distribution": "ggx", "alpha": 0.3, "eta": 1.9, "k": 1.5})
    bs, _ = native.sample(ctx, si, 0.5, sample2)
    a, b = np.array(rough.eval(ctx, si, bs.wo)), np.array(native.eval(ctx, si, bs.wo))
    assert np.abs(a - b).max() < 5e-4 * max(1.0, np.abs(b).max())
    # with a film the s/p phase difference changes: the circular block differs from the bare one
    c = np.array(_film(mi, 550.0).sample(ctx, si, 0.5, sample2)[1])
    assert np.abs(c[3, 3] - np.array(pairs[0][1].sample(ctx, si, 0.5, sample2)[1])[3, 3]).max() > 0.05


def test_polarized_m00_is_the_unpolarized_reflectance():
    mi = _variant("llvm_ad_spectral_polarized")
    theta = np.linspace(0.05, 1.5, 64)
    wl = np.tile(np.linspace(400, 700, 64), (4, 1)) + np.arange(4)[:, None] * 7
    si = _si(mi, np.stack([np.sin(theta), 0 * theta, np.cos(theta)]), wl)
    m = np.array(_film(mi, 300.0).sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.5, 0.5))[1])
    expect = airy.unpolarized_reflectance(np.cos(theta)[None, :], wl, 1.0, 1.33, 300.0, 1.9 + 1.5j)
    np.testing.assert_allclose(m[0, 0], expect, atol=1e-5)


# -- sampling ---------------------------------------------------------------------------------
@pytest.mark.parametrize("distribution, alpha, theta_deg", [("ggx", 0.1, 0), ("ggx", 0.1, 60), ("ggx", 0.5, 30),
                                                            ("ggx", 0.5, 80), ("beckmann", 0.3, 45)])
def test_chi2_sampling_matches_pdf(distribution, alpha, theta_deg):
    mi = _variant("llvm_ad_spectral")
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain
    t = np.radians(theta_deg)
    extra = (f'<float name="film_ior" value="1.33"/><float name="film_thickness" value="550"/>'
             f'<spectrum name="eta" value="1.9"/><spectrum name="k" value="1.5"/>'
             f'<string name="distribution" value="{distribution}"/><float name="alpha" value="{alpha}"/>')
    sample_func, pdf_func = BSDFAdapter(PLUGIN, extra, wi=mi.Vector3f(float(np.sin(t)), 0.0, float(np.cos(t))))
    chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func, sample_dim=3,
                         sample_count=400_000)
    assert chi2.run(), chi2.messages


@pytest.mark.parametrize("variant", ["llvm_ad_spectral", pytest.param("llvm_ad_spectral_polarized", marks=pytest.mark.slow)])  # polarised: 1.9-2.6 s of CPU
def test_sample_weight_equals_eval_over_pdf(variant):
    mi = _variant(variant)
    rng = np.random.default_rng(2)
    n = 4096
    theta, phi = rng.uniform(0.0, 1.45, n), rng.uniform(0, 2 * np.pi, n)
    si = _si(mi, np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]),
             rng.uniform(360, 830, (4, n)))
    ctx = mi.BSDFContext()
    for rough in (("ggx", 0.2), ("beckmann", 0.4)):
        bsdf = _film(mi, 420.0, rough)
        bs, weight = bsdf.sample(ctx, si, 0.5, mi.Point2f(rng.uniform(size=n), rng.uniform(size=n)))
        value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
        w, v, p = np.array(weight), np.array(value), np.array(pdf)
        valid = np.abs(w).reshape(-1, n).max(axis=0) > 0  # sampled directions above the surface
        assert valid.mean() > 0.9
        np.testing.assert_allclose(np.array(bs.pdf)[valid], p[valid], rtol=1e-4)
        np.testing.assert_allclose(np.array(bsdf.pdf(ctx, si, bs.wo)), p, rtol=1e-5)
        ok = valid & (p > 1e-3)
        np.testing.assert_allclose(w[..., ok], (v / np.where(p > 0, p, 1))[..., ok], rtol=2e-4, atol=2e-5)


# -- limits -----------------------------------------------------------------------------------
def _xyz_of_reflectance(refl, wl):
    """XYZ of a reflectance sampled on ``wl`` under a flat light, with the CIE CMFs."""
    cw, xb, yb, zb = spectra.cie_1931_cmfs()
    cmf = np.stack([np.interp(wl, cw, c) for c in (xb, yb, zb)])
    return np.trapz(refl[None, :] * cmf, wl, axis=-1) / np.trapz(yb, cw)


def test_very_thick_film_approaches_the_incoherent_average():
    """A 100 um film's fringes are ~1 nm apart: integrated to colour, the plugin's exact coherent
    reflectance equals the incoherent sum of the internal reflections (computed here), while a
    1500 nm film is still far from it (the check has power)."""
    mi = _variant("llvm_ad_spectral")
    from spectral_bench.exporters.mitsuba_plugins import thin_film_conductor as tfc
    wl = np.arange(360.0, 830.0, 0.02)  # 50 samples per fringe at 100 um
    for theta in (0.0, 0.6, 1.2):
        rs_i, rp_i = airy.incoherent_reflectance(np.cos(theta), 1.0, 1.33, 1.9 + 1.5j)
        incoherent = _xyz_of_reflectance(np.full(wl.shape, 0.5 * (rs_i + rp_i)), wl)
        gaps = {}
        for d in (1e5, 1500.0):
            u = lambda a: mi.UnpolarizedSpectrum(np.tile(np.asarray(a, np.float32), (4, 1)))
            rs, rp = tfc.airy_amplitudes(u(np.full(wl.shape, np.cos(theta))), u(wl), 1.0, 1.33, d,
                                         u(np.full(wl.shape, 1.9)), u(np.full(wl.shape, 1.5)))
            refl = 0.5 * (np.array(rs[0])[0] ** 2 + np.array(rs[1])[0] ** 2 + np.array(rp[0])[0] ** 2
                          + np.array(rp[1])[0] ** 2)
            gaps[d] = np.abs(_xyz_of_reflectance(refl, wl) / incoherent - 1).max()
        # 1e-3: the residual fringe contrast after CMF integration at 100 um (~1/(fringes per CMF
        # lobe) ~ 1e-2 of the fringe amplitude ~0.1) plus float32 phase error (~2e-4 rad)
        assert gaps[1e5] < 1e-3 and gaps[1500.0] > 10 * gaps[1e5], (theta, gaps)


def _sphere_scene(bsdf, spp=64, size=32):
    from spectral_bench.batch.studies import stability
    sc = stability._furnace_sphere(bsdf)
    sc["render"]["spp"], sc["render"]["width"], sc["render"]["height"] = spp, size, size
    sc["environment"]["radiance"] = {"type": "named", "name": "cie_d65", "scale": 1.0}
    return sc


def _render_with_noise(sc, tmp_path, seed, passes=4):
    backend = backends.get("mitsuba")
    sc = copy.deepcopy(sc)
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    xml = backend.export(sc, tmp_path / "m")
    backend.render(xml, backend.mode_for(sc)[0], sc["render"]["spp"], tmp_path / "r.exr", passes=passes, seed=seed)
    names, img, stderr = exr.read_image_and_stderr(tmp_path / "r.exr")
    return img[..., :3].astype(np.float64), stderr[..., :3].astype(np.float64)


def _same_within_noise(a, b, block=4):
    """Two independent renders agree per block of pixels and channel (Z on the passes' standard
    errors), Sidak-corrected over blocks and channels; returns (pass, max |z|)."""
    (ia, sa), (ib, sb) = a, b
    h, w = ia.shape[:2]
    d = (ia - ib).reshape(h // block, block, w // block, block, 3).sum(axis=(1, 3))
    var = (sa**2 + sb**2).reshape(h // block, block, w // block, block, 3).sum(axis=(1, 3))
    z = d / np.sqrt(np.maximum(var, 1e-30))
    p = stats.two_sided_p(z.ravel(), dof=None)
    return bool(np.min(p) >= stats.sidak_threshold(stats.ALPHA, z.size)), float(np.abs(z).max())


@pytest.mark.slow
def test_thickness_zero_renders_like_roughconductor(tmp_path):
    """A rough (GGX 0.3) sphere under uniform D65: the plugin with thickness 0 and Mitsuba's
    roughconductor, rendered with independent seeds, agree within their passes' noise; a 100 nm
    film does not (the comparison has power)."""
    base = {"type": "conductor", "eta": {"type": "constant", "value": 1.9}, "k": {"type": "constant", "value": 1.5},
            "roughness": {"distribution": "ggx", "alpha": 0.3}}
    native = _render_with_noise(_sphere_scene(base), tmp_path / "native", seed=0)
    film0 = _render_with_noise(_sphere_scene(dict(base, thin_film={"ior": 1.33, "thickness": 0.0})), tmp_path / "f0",
                               seed=100)
    film100 = _render_with_noise(_sphere_scene(dict(base, thin_film={"ior": 1.33, "thickness": 100.0})),
                                 tmp_path / "f100", seed=200)
    ok, z = _same_within_noise(native, film0)
    assert ok, z
    ok, z = _same_within_noise(native, film100)
    assert not ok and z > 10, z


# -- the Airy probe ---------------------------------------------------------------------------
@pytest.mark.slow
def test_airy_probe_passes_for_the_scene_and_fails_for_a_film_200nm_thinner(golden, tmp_path):
    scene = copy.deepcopy(golden["iridescent_sphere_smooth"])
    scene["render"]["width"] = scene["render"]["height"] = 64
    sc, names, img = render(scene, tmp_path / "right", 64)
    environment, film = probes.evaluate(sc, names, img, observers=["mitsuba3"])
    assert film["name"].startswith("airy film") and film["pass"] is True and film["tiles"] >= 100, film
    assert film["alternatives"]["mitsuba3"]["pass"]
    # Mitsuba 3.9.1's film is 0.1 % bright (Y normalised by 1/106.7503, its CIE table integrates to
    # 106.857): the environment record sees it, and under Mitsuba's observer (the recorded
    # deviation, known_deviations.toml) it passes; this fails once Mitsuba is fixed
    assert environment["pass"] is False and 1.0005 < environment["ratio"][1] < 1.0015, environment
    assert environment["alternatives"]["mitsuba3"]["pass"], environment
    thinner = copy.deepcopy(scene)
    thinner["objects"][0]["bsdf"]["thin_film"]["thickness"] -= 200.0
    _, names, img = render(thinner, tmp_path / "thin", 64)
    film = probes.evaluate(sc, names, img, observers=["mitsuba3"])[-1]  # judged against the scene's own film
    assert film["pass"] is False and film["error"] > 20 and not film["alternatives"]["mitsuba3"]["pass"], film


@pytest.mark.slow
def test_airy_probe_footprint_and_exclusions(golden):
    """The footprint integral has converged: doubling the sub-rays per side moves no tile's
    expected mean by more than 1e-3 of its value (a quarter of a tile's standard error at the
    scene's 64 spp, ~4e-3); silhouette pixels are excluded; a named conductor (the renderer's own
    table) is not probed."""
    from spectral_bench.batch.verdict.probes import thin_film
    sc = golden["iridescent_sphere_smooth"]
    sub = thin_film.supersampling(32, 32)
    e1, m1 = thin_film.expected_image(sc, 0, 32, 32)
    e2, m2 = thin_film.expected_image(sc, 0, 32, 32, sub=2 * sub)
    assert (m1 == m2).all() and 0.3 < m1.mean() < 0.7
    origin, corners = thin_film.raycast.camera_rays(sc["camera"], 32, 32, "corners")
    hit, _ = thin_film.raycast.nearest(sc["objects"], origin, corners)
    assert (hit[:-1, :-1] == 0)[m1].all() and not m1[0].any()  # whole pixels on the sphere only
    worst = max(np.abs(e1[ys, xs].mean(0) / e2[ys, xs].mean(0) - 1).max() for ys, xs in thin_film.tiles(m1))
    assert worst < 1e-3, worst
    named = copy.deepcopy(sc)
    named["objects"][0]["bsdf"] = {"type": "conductor", "material": "Cu",
                                   "thin_film": {"ior": 1.33, "thickness": 550.0}}
    p = probes.evaluate(named, ["R", "G", "B"], np.ones((64, 64, 3)))[-1]
    assert p["pass"] is None and "table" in p["note"]


def test_film_strip_limit_check_catches_a_jump(tmp_path):
    """The stability strips' limit check: a 100 nm film posing as the thickness-0 end of the strip
    differs from the bare conductor beyond noise."""
    from spectral_bench.batch.studies import stability
    backend = backends.get("mitsuba")
    strip = next(s for s in stability.STRIPS if s.name == "film_thickness_furnace")
    sc = copy.deepcopy(strip.base)
    strip.apply(sc, 100.0)
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    folder = tmp_path / "film"
    backend.render(backend.export(sc, folder / "scene"), backend.mode_for(sc)[0], 64, folder / "render.exr", passes=4)
    bare = strip.limit(sc)
    bare["needs"] = ir.derived_needs({k: v for k, v in bare.items() if k != "needs"})
    limit = tmp_path / "limit"
    backend.render(backend.export(bare, limit / "scene"), backend.mode_for(bare)[0], 64, limit / "render.exr", passes=4,
                   seed=1000)
    found = stability.compare_to_limit(strip, sc, folder / "render.exr", limit / "render.exr", 4, tests=3)
    assert found["problem"] and found["limit_z"] > 10, found


# -- IR, writers, export ------------------------------------------------------------------------
def test_validation_names_object_and_field(golden):
    sc = copy.deepcopy(golden["iridescent_spheres_height"])
    obj = next(o for o in sc["objects"] if (o.get("bsdf") or {}).get("thin_film"))
    for field, value, text in (("thickness", -5.0, "thin_film.thickness"), ("thickness", float("nan"), "thin_film.thickness"),
                               ("ior", 0.0, "thin_film.ior"), ("ext_ior", float("inf"), "thin_film.ext_ior")):
        bad = copy.deepcopy(sc)
        next(o for o in bad["objects"] if o["name"] == obj["name"])["bsdf"]["thin_film"][field] = value
        with pytest.raises(validate.SceneError) as err:
            validate.check(bad)
        assert f"object {obj['name']!r}, field 'bsdf.{text}'" in str(err.value)
    bad = copy.deepcopy(sc)
    next(o for o in bad["objects"] if o["name"] == obj["name"])["bsdf"]["thin_film"]["colour"] = 1
    with pytest.raises(validate.SceneError, match=f"object {obj['name']!r}, field 'bsdf.thin_film'.*'colour' was unexpected"):
        validate.check(bad)


@pytest.mark.slow
def test_blender_film_annotations_are_validated_inline():
    from conftest import run_bpy
    out = run_bpy("""
        from spectral_bench.addon import validation
        from spectral_bench.exporters import extract_blender
        m = bpy.data.materials["film_1.33_300nm"]
        ok = validation.material_problems(m)
        film = extract_blender.material_bsdf(m)["thin_film"]
        m.spectral_bench.film_thickness = -5.0
        m.spectral_bench.film_ior = 0.0
        bad = validation.material_problems(m)
        m.spectral_bench.thin_film = False
        print(json.dumps([ok, film, bad, "thin_film" in extract_blender.material_bsdf(m)]))
    """)
    ok, film, bad, still = out
    assert ok == [] and film == {"ior": 1.33, "thickness": 300.0, "ext_ior": 1.0} and still is False
    assert any(msg.startswith("thin_film.thickness") and "-5" in msg for msg in bad)
    assert any(msg.startswith("thin_film.ior") for msg in bad)


def test_needs_writers_and_art(golden, tmp_path):
    sc = golden["iridescent_spheres_height"]
    assert sc["needs"] == ["spectral", "thin_film"]
    assert backends.get("mitsuba").mode_for(sc)[0].endswith("_spectral")
    assert all("thin_film" not in golden[n]["needs"] for n in golden if not n.startswith("iridescent"))
    missing = art_writer.unsupported(sc)
    filmed = [o["name"] for o in sc["objects"] if (o.get("bsdf") or {}).get("thin_film")]
    assert sorted(o for o, f, _ in missing if f == "bsdf.thin_film") == sorted(filmed) and len(filmed) == 3
    mode, why = backends.get("art").mode_for(sc)  # what the user reads: per object and field
    assert mode is None and all(f"{o}.bsdf.thin_film" in why for o in filmed), why
    xml = mitsuba_writer.write(sc, tmp_path / "m")
    assert xml.read_text().count(f'type="{PLUGIN}"') == 3 and (tmp_path / "m" / "plugins" / "thin_film_conductor.py").is_file()


def test_exported_folder_renders_with_its_own_loader(golden, tmp_path):
    """The exported folder carries the plugin: its load_plugins.py renders scene.xml in a fresh
    Python that knows nothing of this project."""
    sc = copy.deepcopy(golden["iridescent_sphere_smooth"])
    sc["render"]["width"] = sc["render"]["height"] = 16
    mitsuba_writer.write(sc, tmp_path / "export")
    proc = subprocess.run([sys.executable, "load_plugins.py", "llvm_ad_spectral", "4"], cwd=tmp_path / "export",
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    img = exr.read_rgb(tmp_path / "export" / "scene.exr")
    assert img.shape == (16, 16, 3) and np.isfinite(img).all() and img[8, 8].mean() > 0.05


# -- the scenes against their references, through the command line -------------------------------
CASE_SPP = 16  # a quarter of the scenes' 64 (issue 31: their default settings are the main command's)
SEES = 0.01  # the uniform error each scene's run must see (its own detectable at 16 spp: 0.02-0.08 %)


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("iridescence") / "out"
    # through the references' own colour route (the CMF film), as tests/probes/test_reflectance.py
    proc = run_batch("-r", "mitsuba", "--film", "cmf", "-c", "iridescence", "--no-flip", "--spp", CASE_SPP, "-o", out)
    return proc, out, {r["scene"]: r for r in metrics(out)["runs"]}


def test_references_exist_with_provenance(golden):
    for name in IRIDESCENCE:
        ref = references.load(name)
        assert ref is not None, f"references/{name}.exr missing: run batch/make_references.py -s {name}"
        assert references.check_usable(ref, golden[name]) is None
        assert ref.provenance["passes"] >= 4 and ref.stderr.shape == ref.mean.shape


@pytest.mark.slow
def test_every_iridescence_scene_agrees_with_its_reference(batch_run):
    proc, out, runs = batch_run
    assert sorted(runs) == IRIDESCENCE
    for name, run in runs.items():
        assert run["test"]["pass"] and run["mode"] == "llvm_ad_spectral", (name, run["reason"], run.get("test"))
        assert run["spp"] == CASE_SPP and run["passes"] == 2, run
        assert_sees(run, SEES, "a uniform error this test claims to see")
        assert run["status"] == "ok", (name, run["reason"])
    smooth = {p["name"]: p for p in runs["iridescent_sphere_smooth"]["probes"]}
    assert smooth["airy film smooth_film_sphere"]["pass"] is True, smooth
    # through the CMF film the environment seen directly meets the IR's colour too (Mitsuba's own
    # film is 0.1 % bright there: known_deviations.toml, seen in the main command's run)
    assert smooth["environment seen directly"]["pass"] is True, smooth["environment seen directly"]
    # the rough spheres are judged by probes/rough_film.py, not only against Mitsuba's own reference
    from spectral_bench.batch.report import results
    for name in IRIDESCENCE[1:]:
        rough = [p for p in runs[name]["probes"] if p["name"].startswith("rough film")]
        assert len(rough) == 4 and all(p["pass"] is True for p in rough), (name, rough)
        assert not results.checked_against_itself(runs[name]) and "4 probes" in results.judged_by(runs[name])
    assert proc.returncode == 0


def test_a_thinner_film_fails_the_reference_test(golden, tmp_path):
    sc = copy.deepcopy(golden["iridescent_spheres_height"])
    sc["render"]["width"], sc["render"]["height"] = 100, 32
    for o in sc["objects"]:
        if (o.get("bsdf") or {}).get("thin_film"):
            o["bsdf"]["thin_film"]["thickness"] -= 200.0
    _, names, img, se = render_with_noise(sc, tmp_path, 256)
    zt = noise_test("iridescent_spheres_height", img, se, 256)
    assert not zt.passed and zt.z_max > 10, zt
