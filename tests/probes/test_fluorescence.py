"""Fluorescence (issue 12): Mitsuba renders re-radiation through sb_fluorescent_path without
bias, judged against ground truth from no renderer and against the renders' own noise.

- the lone fluorescent sphere meets rho L + integral P L, and misses it when the emission peak
  moves by 20 nm;
- a white furnace with a fluorescent Lambertian never returns more than the incident energy (and
  returns exactly the closed form), while a deliberately energy-gaining material does;
- re-radiation zero renders as the plain diffuse sphere within noise (and the scene's own
  re-radiation does not);
- the 450 nm-lit spheres agree with their references: absorbing at 370 nm dark, at 450 nm red;
- bad fluorescent inputs are refused, naming scene, object and field.
ART renders skip with a visible reason where no ``artist`` is installed."""
import copy
import json
import os
import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from conftest import FLUORESCENCE, ROOT, metrics, run_batch
from spectral_bench.batch import backends, exr
from spectral_bench.batch.backends.mitsuba import llvm
from spectral_bench.batch.verdict import compare, probes, raycast, references, stats
from spectral_bench.exporters import (art_writer, fluorescence, ir, ir_json, mitsuba_writer, spectra,
                                      validate)

from installed import ART_EXEC, needs_artist  # ART as the runner finds it (.art/env.json, PATH, ART_ARTIST)
LONE = "fluorescent_sphere_lone"
PROBE_SIZE, PROBE_SPP = 64, 64


def _derive(sc):
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    return sc


def _render(scene, out, spp, size=None, passes=2, seed=0):
    """Render an IR scene with the Mitsuba backend (no validation: a test may break the physics
    on purpose); returns (scene as rendered, channel names, image, stderr)."""
    sc = _derive(copy.deepcopy(scene))
    if size:
        sc["render"]["width"] = sc["render"]["height"] = size
    backend = backends.get("mitsuba")
    mode, why = backend.mode_for(sc)
    assert mode, why
    xml = backend.export(sc, out / "mitsuba")
    backend.render(xml, mode, spp, out / "render.exr", passes=passes, seed=seed)
    names, img, se = exr.read_image_and_stderr(out / "render.exr")
    return sc, names, img, se


def _lone_probe(scene, names, image, stderr):
    recs = [r for r in probes.evaluate(scene, names, image, stderr=stderr, observers=("mitsuba3",))
            if r["name"].startswith("lone ")]
    assert len(recs) == 1, recs
    return recs[0]


def _sphere_bsdf(sc):
    return next(o for o in sc["objects"] if o["shape"]["type"] == "sphere")["bsdf"]


@pytest.fixture(scope="module")
def lone(golden, tmp_path_factory):
    return _render(golden[LONE], tmp_path_factory.mktemp("lone"), PROBE_SPP, PROBE_SIZE)


# ---- the analytic probe ---------------------------------------------------------------------------

def test_lone_sphere_meets_the_analytic_probe(lone):
    """Judged under the film Mitsuba 3.9.1 integrates with (the "mitsuba3" observer of the known
    deviation mitsuba-cie-y-normalisation): under the CIE 1931 1 nm ground truth the sphere's blue,
    0.0017 of its red, reads about 10 % high, which the probe resolves at |z| 2 to 4 depending on
    the seed (measured over 5 seeds: plainly 2 of 5 fail, under the recorded observer |z| <= 2.1)."""
    rec = _lone_probe(*lone)
    assert rec["alternatives"]["mitsuba3"]["pass"] is True, rec
    assert rec["pixels"] > 500 and rec["expected"][0] > 0.9  # the fluorescent red is in the probe


@pytest.mark.parametrize("shift", [20.0, -20.0])
def test_probe_fails_when_the_emission_peak_moves_20nm(lone, shift):
    sc, names, img, se = lone
    moved = copy.deepcopy(sc)
    _sphere_bsdf(moved)["fluorescence"]["emission_peak"] += shift
    rec = _lone_probe(moved, names, img, se)
    assert rec["pass"] is False and rec["error"] > 10, rec


def test_uv_excitation_below_mitsubas_360nm_counts(golden, tmp_path, monkeypatch):
    """Half of the lone sphere's absorption band lies below 360 nm, where Mitsuba's camera never
    samples: the excitation wavelength is drawn there all the same, and the light there is the
    scene's because fluorescent scenes tabulate spectra from 300 nm. Tabulated from 360 nm (as
    other scenes are), Mitsuba's spectra read 0 below it and the probe sees the missing red."""
    monkeypatch.setattr(fluorescence, "FLUORESCENT_SPECTRA_FROM", 360.0)
    rec = _lone_probe(*_render(golden[LONE], tmp_path, PROBE_SPP, PROBE_SIZE))
    assert rec["pass"] is False and rec["measured"][0] < rec["expected"][0], rec


def test_probe_ground_truth_outweighs_the_renderers_tabulation(golden):
    """The renderers integrate a 1 nm tabulation of P; the probe integrates P itself. Their
    difference in the re-radiated light must be negligible (< 1e-3) against what the probe
    resolves (a region standard error of ~1e-3 of Y at the scene's settings)."""
    bsdf, env = _sphere_bsdf(golden[LONE]), golden[LONE]["environment"]["radiance"]
    wt, m = fluorescence.table(bsdf["fluorescence"])
    tabulated = m.T @ spectra.evaluate(env, wt)  # 1 nm cells
    exact = fluorescence.emitted(bsdf["fluorescence"], lambda wl: spectra.evaluate(env, wl), wt)
    assert np.abs(tabulated - exact).sum() / exact.sum() < 1e-3


# ---- white furnace ----------------------------------------------------------------------------------

FLAT_BAND = (360.0, 830.0)


def _furnace(rho, strength):
    """A fluorescent Lambertian sphere alone in a uniform environment of radiance 1 at every
    wavelength, seen whole by the camera."""
    return _derive({
        "format": ir.FORMAT, "version": ir.VERSION, "name": "fluorescent_furnace", "case": "fluorescence", "needs": [],
        "render": {"spp": 64, "width": 48, "height": 48, "max_depth": 64},
        "camera": {"to_world": [[1, 0, 0, 0], [0, 0, -1, -6], [0, 1, 0, 0], [0, 0, 0, 1]], "fov": 25.0,
                   "fov_axis": "x"},
        "environment": {"type": "uniform", "radiance": {"type": "constant", "value": 1.0}},
        "objects": [{"name": "furnace_sphere", "emitter": None, "shape": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
                     "bsdf": {"type": "diffuse", "reflectance": rho,
                              "fluorescence": {"type": "bands", "absorption_peak": 450.0, "absorption_width": 40.0,
                                               "emission_peak": 600.0, "emission_width": 50.0,
                                               "strength": strength}}}]})


# a reflectance that absorbs only in the absorption band (90 % at its peak): elastic 1 elsewhere
BAND_ABSORBER = {"type": "sampled", "wavelengths": [410.0, 450.0, 490.0], "values": [1.0, 0.1, 1.0]}


def _furnace_energy(scene, tmp_path, spp=256):
    """Mean spectral radiance over 360-830 nm per pixel (Mitsuba's specfilm with a flat response),
    as a fraction of the environment's."""
    xml = mitsuba_writer.write(scene, tmp_path / "mitsuba")
    flat = tmp_path / "mitsuba" / "spectra" / "flat_response.spd"
    flat.write_text(f"{FLAT_BAND[0]:g} 1\n{FLAT_BAND[1]:g} 1\n")
    text = re.sub(r'<film type="hdrfilm">.*?</film>',
                  f'<film type="specfilm"><integer name="width" value="{scene["render"]["width"]}"/>'
                  f'<integer name="height" value="{scene["render"]["height"]}"/>'
                  '<spectrum name="energy" filename="spectra/flat_response.spd"/><rfilter type="box"/></film>',
                  xml.read_text(), flags=re.S)
    xml.write_text(text)
    npy = tmp_path / "energy.npy"
    code = textwrap.dedent(f"""
        import sys, numpy as np, mitsuba as mi
        mi.set_variant("llvm_ad_spectral")
        sys.path.insert(0, {str(xml.parent)!r}); import load_plugins; load_plugins.register()
        img = np.array(mi.render(mi.load_file({str(xml)!r}), spp={spp}))
        np.save({str(npy)!r}, img[..., 0])
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=llvm.env())
    assert proc.returncode == 0, proc.stderr[-3000:]
    # specfilm records the band integral of L times the response: the environment's is the band width
    energy = np.load(npy) / (FLAT_BAND[1] - FLAT_BAND[0])
    r = scene["render"]
    mask = raycast.pixels_inside(scene["camera"], r["width"], r["height"], scene["objects"], 0)
    return energy[mask]


def _closed_form_energy(bsdf):
    """Outgoing over incident energy in 360-830 nm under flat light: (integral rho + integral of A)
    / band, with A(l_o) = integral P(l_i, l_o) dl_i (all of P lies inside the band here)."""
    wl = np.arange(FLAT_BAND[0], FLAT_BAND[1] + 0.01, 0.05)
    elastic = np.trapz(spectra.evaluate(bsdf["reflectance"], wl), wl)
    reradiated = fluorescence.emitted(bsdf["fluorescence"], np.ones_like, wl)
    return (elastic + np.trapz(reradiated, wl)) / (FLAT_BAND[1] - FLAT_BAND[0])


def _max_strength(rho):
    """The strength at which the furnace material's quantum yield reaches 1."""
    probe = _furnace(rho, 1.0)["objects"][0]["bsdf"]
    qy, _ = fluorescence.quantum_yield(probe["fluorescence"], lambda wl: spectra.evaluate(rho, wl))
    return 1.0 / qy


@pytest.mark.slow
def test_white_furnace_returns_no_more_than_the_incident_energy(tmp_path):
    strength = 0.999 * _max_strength(BAND_ABSORBER)  # quantum yield just below 1: the most allowed
    scene = validate.check(_furnace(BAND_ABSORBER, strength))
    ratio = _furnace_energy(scene, tmp_path)
    n = ratio.size
    mean, se = ratio.mean(), ratio.std(ddof=1) / np.sqrt(n)
    # one-sided: returning more than came in is rejected at alpha 0.01 against the region's noise
    p_gain = stats.two_sided_p((mean - 1.0) / se, n - 1) / 2 if mean > 1.0 else 1.0
    assert p_gain >= stats.ALPHA, (mean, se)
    # and the furnace returns exactly its closed form (elastic plus the Stokes-shifted re-emission)
    expected = _closed_form_energy(scene["objects"][0]["bsdf"])
    assert 0.9 < expected < 1.0
    test = stats.region_mean_test(ratio - expected)
    assert test["pass"], (mean, expected, test)


def test_white_furnace_catches_an_energy_gaining_material(tmp_path):
    """Quantum yield 3 (validation refuses it; written straight to Mitsuba here): more energy
    comes back than came in, and the furnace says so."""
    strength = 3.0 * _max_strength(BAND_ABSORBER)
    scene = _furnace(BAND_ABSORBER, strength)
    with pytest.raises(validate.SceneError, match="quantum yield"):
        validate.check(scene)
    ratio = _furnace_energy(scene, tmp_path)
    mean, se = ratio.mean(), ratio.std(ddof=1) / np.sqrt(ratio.size)
    assert (mean - 1.0) / se > 10, (mean, se)


# ---- re-radiation zero -----------------------------------------------------------------------------

def test_zero_reradiation_renders_as_the_plain_diffuse_sphere(golden, lone, tmp_path):
    zero = copy.deepcopy(golden[LONE])
    _sphere_bsdf(zero)["fluorescence"]["strength"] = 0.0
    plain = copy.deepcopy(golden[LONE])
    del _sphere_bsdf(plain)["fluorescence"]
    sc_z, _, img_z, se_z = _render(zero, tmp_path / "zero", PROBE_SPP, PROBE_SIZE, seed=0)
    sc_p, _, img_p, se_p = _render(plain, tmp_path / "plain", PROBE_SPP, PROBE_SIZE, seed=100)
    assert "fluorescence" in sc_z["needs"] and "fluorescence" not in sc_p["needs"]
    assert "sb_fluorescent_path" in (tmp_path / "zero" / "mitsuba" / "scene.xml").read_text()
    assert '<integrator type="path">' in (tmp_path / "plain" / "mitsuba" / "scene.xml").read_text()

    def agree(img, se):  # each render brings its own noise (two passes each)
        plain_at = compare.ReferenceAt(img_p[..., :3], se_p[..., :3] ** 2, np.zeros_like(img_p[..., :3]), 1.0)
        return compare.z_test(img[..., :3], plain_at, PROBE_SPP, own_var_of_mean=se[..., :3] ** 2, own_passes=2)
    zt = agree(img_z, se_z)
    assert zt.passed, zt
    _, _, img_f, se_f = lone  # the scene's own re-radiation is visible to the same test
    assert not agree(img_f, se_f).passed


# ---- the thesis' scenes against their references ---------------------------------------------------

MONO = ["fluorescent_sphere_mono_invisible", "fluorescent_sphere_mono_red"]


@pytest.fixture(scope="module")
def mono_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("mono") / "out"
    args = ["-r", "mitsuba", "--scale", 0.25, "--spp", 64, "--passes", 2, "--no-flip", "-o", out]
    for name in MONO:
        args += ["-s", name]
    proc = run_batch(*args)
    return proc, out, {r["scene"]: r for r in metrics(out)["runs"]}


def _sphere_rgb(out, run, scene):
    names, img = exr.read_image(out / run["image"])
    sc = copy.deepcopy(scene)
    h, w = img.shape[:2]
    i = next(k for k, o in enumerate(sc["objects"]) if o["shape"]["type"] == "sphere")
    mask = raycast.pixels_inside(sc["camera"], w, h, sc["objects"], i)
    return img[mask][:, :3].mean(axis=0), img[..., :3]


def test_references_exist_with_provenance_and_noise():
    for name in FLUORESCENCE:
        ref = references.load(name)
        assert ref is not None, f"references/{name}.exr missing: run batch/make_references.py -s {name}"
        assert ref.provenance["passes"] >= 4 and ref.stderr.shape == ref.mean.shape


@pytest.mark.slow
def test_450nm_light_spheres_agree_with_their_references_dark_and_red(golden, mono_run):
    proc, out, runs = mono_run
    assert sorted(runs) == MONO
    for name, run in runs.items():
        assert run["status"] == "ok" and run["test"]["pass"], (name, run["reason"], run.get("test"))
    dark, image_dark = _sphere_rgb(out, runs["fluorescent_sphere_mono_invisible"], golden["fluorescent_sphere_mono_invisible"])
    red, _ = _sphere_rgb(out, runs["fluorescent_sphere_mono_red"], golden["fluorescent_sphere_mono_red"])
    # absorbing at 370 nm, lit at 450 nm: only the yellow base's elastic 5 % of blue, no red
    luminance = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB -> Y
    assert dark[0] < 0.05 * red[0] and dark @ luminance < 0.1 * (red @ luminance), (dark, red)
    # absorbing at 450 nm: re-emitted red dominates
    assert red[0] > 3 * max(red[1], red[2]), red


# ---- bad input ---------------------------------------------------------------------------------------

def _bad(golden, how):
    sc = copy.deepcopy(golden["fluorescent_sphere_D50_red"])
    obj = next(o for o in sc["objects"] if o["shape"]["type"] == "sphere")
    fl = obj["bsdf"]["fluorescence"]
    if how == "anti-stokes bands":
        fl["emission_peak"] = 350.0
        return sc, obj["name"], "bsdf.fluorescence.emission_peak", "longer wavelength"
    if how == "quantum yield":
        fl["strength"] = 0.025  # the thesis' value: 2.3 photons out per photon absorbed
        return sc, obj["name"], "bsdf.fluorescence.strength", "quantum yield 2.3"
    if how == "width":
        fl["absorption_width"] = 0.0
        return sc, obj["name"], "bsdf.fluorescence.absorption_width", "> 0"
    if how == "below 300 nm":
        fl["absorption_peak"] = 310.0
        return sc, obj["name"], "bsdf.fluorescence.absorption_width", "300-830"
    w = [400.0, 500.0, 600.0]
    if how == "anti-stokes matrix":
        obj["bsdf"]["fluorescence"] = {"type": "matrix", "wavelengths": w,
                                       "matrix": [[0, 0.001, 0], [0, 0, 0], [0.001, 0, 0]]}
        return sc, obj["name"], "bsdf.fluorescence.matrix[2][0]", "shorter"
    if how == "matrix quantum yield":
        obj["bsdf"]["fluorescence"] = {"type": "matrix", "wavelengths": w,
                                       "matrix": [[0, 0.05, 0.05], [0, 0, 0.05], [0, 0, 0]]}
        return sc, obj["name"], "bsdf.fluorescence.matrix", "quantum yield"
    if how == "unknown form":
        obj["bsdf"]["fluorescence"] = {"type": "gaussian", "peak": 500}
        return sc, obj["name"], "bsdf.fluorescence", "does not match"
    raise ValueError(how)


@pytest.mark.parametrize("how", ["anti-stokes bands", "quantum yield", "width", "below 300 nm", "anti-stokes matrix",
                                 "matrix quantum yield", "unknown form"])
def test_bad_fluorescence_names_scene_object_field(golden, tmp_path, how):
    sc, obj, field, words = _bad(golden, how)
    with pytest.raises(validate.SceneError) as info:
        ir_json.load(ir_json.write(sc, tmp_path / "bad.json"))
    problems = [(o, f, m) for o, f, m in info.value.problems]
    assert any(o == obj and f == field and words in m for o, f, m in problems), problems
    assert sc["name"] in str(info.value)


@pytest.mark.slow
def test_valid_matrix_form_loads_and_renders_in_mitsuba_but_not_art(golden, tmp_path):
    """The explicit re-radiation matrix: bilinear P, written as the same table; ART's writer
    reports it (this writer maps only CONST_FLUORESCENT_COLOUR's bands)."""
    sc = copy.deepcopy(golden[LONE])
    bsdf = _sphere_bsdf(sc)
    w = [340.0, 360.0, 380.0, 560.0, 600.0, 640.0]
    m = [[0.0] * 6 for _ in w]
    for i in range(3):
        for o, v in zip(range(3, 6), (0.5, 1.0, 0.5)):
            m[i][o] = 0.004 * v * (1.0 if i == 1 else 0.5)
    bsdf["fluorescence"] = {"type": "matrix", "wavelengths": w, "matrix": m}
    loaded = ir_json.load(ir_json.write(sc, tmp_path / "matrix.json"))
    assert loaded["needs"] == ["fluorescence", "spectral"]
    assert [(o, f) for o, f, _ in art_writer.unsupported(loaded)] == [(_lone_name(sc), "bsdf.fluorescence")]
    _, names, img, se = _render(loaded, tmp_path / "r", PROBE_SPP, 48)
    assert _lone_probe(_derive(dict(loaded, render=dict(loaded["render"], width=48, height=48))),
                       names, img, se)["pass"] is True


def _lone_name(sc):
    return next(o for o in sc["objects"] if o["shape"]["type"] == "sphere")["name"]


def test_backends_say_what_they_cannot_model(golden):
    sc = copy.deepcopy(golden[LONE])
    sc["camera"]["polarizer"] = {"angle": 0.0}
    sc = _derive(sc)
    mode, why = backends.get("mitsuba").mode_for(sc)
    assert mode is None and "polarisation" in why
    for variant in ("llvm_ad_rgb", "scalar_spectral"):  # RGB cannot; scalar would call Python per sample
        mode, why = backends.get("mitsuba", force_variant=variant).mode_for(_derive(copy.deepcopy(golden[LONE])))
        assert mode is None and "llvm_ad_spectral" in why, (variant, why)
    assert backends.get("mitsuba").mode_for(golden["yellow_sphere_F8"])[0].endswith("_spectral")


def test_without_llvm_fluorescence_is_unsupported_with_the_reason(tmp_path):
    """Scalar variants would call the Python integrator once per sample: refused, saying why."""
    code = textwrap.dedent(f"""
        import json, sys
        sys.path.insert(0, {str(ROOT)!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        from spectral_bench.batch.backends.mitsuba import llvm
        from spectral_bench.batch import backends
        from spectral_bench.exporters import ir_json
        llvm.CANDIDATES = ()
        llvm.glob.glob = lambda pattern: []
        print(json.dumps(backends.get("mitsuba").mode_for(ir_json.load({str(ROOT / "golden" / "ir" / (LONE + ".json"))!r}))))
    """)
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=str(tmp_path / "libLLVM-missing.so"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    mode, why = json.loads(proc.stdout.strip().splitlines()[-1])
    assert mode is None and "llvm_ad_spectral" in why and "libLLVM-missing" in why


def test_writers_model_no_more_than_a_scene_needs(golden, tmp_path):
    """Only fluorescent scenes get the Python plugins; they tabulate spectra from 300 nm, ART gets
    CONST_FLUORESCENT_COLOUR with the IR's numbers and FL8 from its own table."""
    plain = mitsuba_writer.write(golden["yellow_sphere_F8"], tmp_path / "f8")
    assert '<integrator type="path">' in plain.read_text() and not (plain.parent / "load_plugins.py").exists()
    assert (plain.parent / "spectra" / "environment_radiance.spd").read_text().startswith("360 ")
    fluo = mitsuba_writer.write(golden["fluorescent_sphere_D50_red"], tmp_path / "d50")
    text = fluo.read_text()
    assert 'type="sb_fluorescent_path"' in text and 'type="sb_fluorescent_diffuse"' in text
    assert (fluo.parent / "spectra" / "environment_radiance.spd").read_text().startswith("300 ")
    assert sorted(p.name for p in (fluo.parent / "plugins").iterdir()) == ["fluorescent_diffuse.py", "fluorescent_path.py"]
    arm = (ROOT / "golden" / "art" / "fluorescent_sphere_D50_red" / "scene.arm").read_text()
    assert "CONST_FLUORESCENT_COLOUR" in arm and "0.01,\n            PNT2D(370.0 NM, 650.0 NM)" in arm
    assert "VEC2D(40.0 NM, 50.0 NM)" in arm
    f8 = (ROOT / "golden" / "art" / "yellow_sphere_F8" / "scene.arm").read_text()
    assert "UNIFORM_ENVIRONMENT_MATERIAL(CIE_ILLUMINANT_FL8, 0.085034014)" in f8  # 1 / 11.76, FL8's raw value at 560 nm


# ---- ART ----------------------------------------------------------------------------------------------

@pytest.mark.slow  # an ART render: 9.8 s in the fast subset once ART is built (benchmarks/TESTS.md, 2026-12-06)
@needs_artist
def test_art_renders_the_450nm_spheres_dark_and_red(golden, tmp_path):
    """ART (fluorescent natively) shows the thesis' two 450 nm cases the same way."""
    out = tmp_path / "art"
    proc = run_batch("-r", "art", *ART_EXEC, "-s", MONO[0], "-s", MONO[1], "--scale", 0.125, "--spp", 64, "--no-flip", "-o", out)
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert all(r["mode"] == "spectral46" and r["image"] for r in runs.values()), (runs, proc.stderr[-2000:])
    dark, _ = _sphere_rgb(out, runs[MONO[0]], golden[MONO[0]])
    red, _ = _sphere_rgb(out, runs[MONO[1]], golden[MONO[1]])
    luminance = np.array([0.2126, 0.7152, 0.0722])
    assert red[0] > 3 * max(red[1], red[2]) and dark[0] < 0.05 * red[0], (dark, red)
    assert dark @ luminance < 0.1 * (red @ luminance), (dark, red)


# ---- Blender ------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_blender_annotations_reach_the_ir_and_a_bad_matrix_file_is_named(tmp_path):
    from conftest import run_bpy
    good = tmp_path / "donaldson.json"
    good.write_text(json.dumps({"wavelengths": [400.0, 450.0, 600.0],
                                "matrix": [[0, 0, 0.002], [0, 0, 0.004], [0, 0, 0]]}))
    out = run_bpy(f"""
        from spectral_bench.exporters import extract_blender, validate
        from spectral_bench.addon import validation
        scene = bpy.data.scenes["{LONE}"]
        mat = bpy.data.materials["yellow_fluorescent_360_600"]
        bands = extract_blender.extract_scene(scene)["objects"][0]["bsdf"]["fluorescence"]
        mat.spectral_bench.fluorescence = "MATRIX"
        mat.spectral_bench.fluorescence_matrix_file = {str(good)!r}
        matrix = extract_blender.extract_scene(scene)["objects"][0]["bsdf"]["fluorescence"]
        mat.spectral_bench.fluorescence_matrix_file = {str(tmp_path / "missing.json")!r}
        try:
            extract_blender.extract_scene(scene)
            problems = []
        except validate.SceneError as exc:
            problems = [list(p) for p in exc.problems]
        mat.spectral_bench.fluorescence = "BANDS"
        mat.spectral_bench.emission_peak = 300.0
        panel = validation.material_problems(mat)
        print(json.dumps({{"bands": bands, "matrix": matrix, "problems": problems, "panel": panel}}))
    """)
    assert out["bands"] == {"type": "bands", "absorption_peak": 360.0, "absorption_width": 40.0,
                            "emission_peak": 600.0, "emission_width": 50.0, "strength": 0.01}
    assert out["matrix"]["type"] == "matrix" and out["matrix"]["matrix"][1][2] == 0.004
    assert [p[:2] for p in out["problems"]] == [
        ["lone_sphere", "material[yellow_fluorescent_360_600].spectral_bench.fluorescence_matrix_file"]]
    assert any("fluorescence.emission_peak" in p for p in out["panel"]), out["panel"]
