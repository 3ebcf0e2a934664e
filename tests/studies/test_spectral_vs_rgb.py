"""--study spectral-vs-rgb (batch/studies/spectral_vs_rgb.py): what spectral rendering changes for
a scene, in its own words, with no reference. A ColorChecker-red sphere under a uniform sky renders
alike spectrally and in RGB under D65 (the sRGB white) and visibly differently under F11 (a line
spectrum: the product of spectra is not the product of their RGBs)."""
import json

import numpy as np
import pytest

from conftest import GOLDEN, ROOT, metrics, run_batch, run_bpy

EXAMPLE = ROOT / "examples" / "scenes" / "red_sphere.json"


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study") / "out"
    proc = run_batch("--study", "spectral-vs-rgb", "-i", EXAMPLE, "-r", "mitsuba", "--illuminants", "F11",
                     "--spp", "1024", "-o", out)
    return proc, out


@pytest.mark.slow
def test_a_study_exits_0_with_its_own_words_and_a_map_per_pair(study):
    proc, out = study
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = {r["light"]: r for r in metrics(out).entries("studies")}
    assert set(rows) == {"own", "F11"} and all(r["rgb"] == "mitsuba" and r["rgb_mode"].endswith("_rgb") for r in rows.values())
    own, f11 = rows["own"], rows["F11"]
    # power: noise alone would show far less than a visible difference, so "not visible" means something
    assert own["de00"]["noise_p95"] < 0.5 * own["de00"]["visible"], own["de00"]
    assert own["status"] in ("same", "below") and own["de00"]["p95"] < 1.0, own
    assert f11["status"] == "visible" and f11["test"]["beyond_noise"] and f11["de00"]["p95"] >= 1.0, f11
    assert f11["de00"]["p95"] > 3 * own["de00"]["p95"]
    assert f11["verdict"].startswith("differs visibly (dE00 p95 ")
    for r in rows.values():  # the maps beside the renders, as the report shows them
        assert all((out / r["images"][k]).is_file() for k in ("spectral", "rgb", "de00")), r["images"]
    summary = (out / "summary.md").read_text()
    assert "## What spectral rendering changes" in summary and "| red_sphere | F11 | mitsuba llvm_ad_rgb | differs visibly" in summary
    assert "failed" not in summary
    html = (out / "report.html").read_text()
    assert "<h2>What spectral rendering changes</h2>" in html and html.count("<figure>") == 6
    assert "<h2>Summary</h2>" not in html  # no judged jobs, no empty table


def test_the_verdict_follows_the_noise_and_the_size_of_the_difference():
    """compare() on synthetic renders with known noise: the same image is not 'visible', a
    difference of 5 % in red is beyond noise and visible, a tiny one beyond noise but not visible,
    and a visible-sized difference drowned in noise is 'too noisy to tell'."""
    from spectral_bench.batch.studies import spectral_vs_rgb as study
    scene = json.loads((GOLDEN / "macbeth_chart_D65.json").read_text())
    rng = np.random.default_rng(3)
    mean = np.full((32, 32, 3), 0.3)

    def noisy(m, se):
        return m + rng.normal(0.0, se, m.shape), np.full(m.shape, se)
    spp = 1024  # blocks of 8 x 8 pixels (65536 samples each, the noise test's minimum), 16 of them

    def verdict(shift, se):
        other = mean * np.array([1.0 + shift, 1.0, 1.0])
        return study.compare(scene, noisy(mean, se), noisy(other, se), spp)[0]["status"]
    assert verdict(0.0, 1e-4) == "same"
    assert verdict(0.05, 1e-4) == "visible"
    assert verdict(0.002, 1e-4) == "below"
    assert verdict(0.05, 0.2) == "noisy"


def test_a_swapped_illuminant_keeps_each_lights_luminance():
    from spectral_bench.exporters import colorimetry, ir_json
    from spectral_bench.batch.studies import spectral_vs_rgb as study
    scene = ir_json.load(EXAMPLE)
    for key in ("F11", "A", "LED-B3"):
        swapped = study.under(scene, key)
        (holder, k), = study.lights(swapped)
        y_old = colorimetry.spectrum_xyz(scene["environment"]["radiance"])[1]
        assert colorimetry.spectrum_xyz(holder[k])[1] == pytest.approx(y_old, rel=1e-9)
        x, y, _ = colorimetry.spectrum_xyz(holder[k]) / sum(colorimetry.spectrum_xyz(holder[k]))
        assert abs(x - 0.3127) > 0.01  # not D65's chromaticity: the spectrum did change


def test_a_scene_no_rgb_variant_models_is_unsupported_naming_why(tmp_path, run_batch_here):
    proc = run_batch_here("--study", "spectral-vs-rgb", "-i", GOLDEN / "polarizing_plane_0.json", "-r", "mitsuba",
                          "-o", tmp_path / "out")
    assert proc.returncode == 4, proc.stderr  # nothing ran: the only pair cannot be rendered in RGB
    (row,) = metrics(tmp_path / "out").entries("studies")
    assert row["status"] == "unsupported" and "cannot model polarization" in row["reason"]


@pytest.mark.slow
def test_the_panel_button_runs_the_study_on_the_open_scene(tmp_path):
    out = run_bpy(f"""
        from spectral_bench.batch import backends
        s = bpy.context.window_manager.spectral_bench_run
        s.backends_off = ",".join(n for n in backends.BACKENDS if n != "mitsuba")
        s.spp, s.scale, s.passes, s.output_parent = 64, 0.1, 2, {str(tmp_path)!r}
        with bpy.context.temp_override(scene=bpy.data.scenes["macbeth_chart_D65"]):
            r = bpy.ops.spectral_bench.run_benchmark(study="spectral-vs-rgb", wait=True)
        print(json.dumps({{"r": list(r), "out": s.output_dir, "status": s.status}}))
    """)
    assert out["r"] == ["FINISHED"] and out["status"].startswith("passed"), out
    (row,) = metrics(out["out"]).entries("studies")
    assert row["scene"] == "macbeth_chart_D65" and row["light"] == "own" and row["status"] in study_words()


def study_words():
    from spectral_bench.batch.studies import spectral_vs_rgb
    return tuple(spectral_vs_rgb.VERDICTS)


@pytest.mark.slow
def test_an_ordinary_blend_answers_what_spectral_changes(tmp_path):
    """Issue 35's done-when: an ordinary .blend made by a bpy script (four Principled spheres, one
    gold; a point light, a 300 W area light, a world colour), no annotation: the study exits 0 with
    a dE00 map per render pair, every conversion or loss a warning naming object and field; under
    F11 the difference is visible."""
    import subprocess
    import sys
    blend = tmp_path / "ordinary.blend"
    made = subprocess.run([sys.executable, str(ROOT / "scripts" / "make_ordinary_blend.py"), str(blend)],
                          capture_output=True, text=True, timeout=300)
    assert made.returncode == 0 and blend.is_file(), made.stderr[-2000:]
    out = tmp_path / "out"
    proc = run_batch("--study", "spectral-vs-rgb", "-i", blend, "-s", "ordinary", "-r", "mitsuba", "--illuminants", "F11",
                     "--scale", "0.5", "--spp", "512", "-o", out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = {r["light"]: r for r in metrics(out).entries("studies")}
    assert set(rows) == {"own", "F11"}
    for r in rows.values():
        assert all((out / r["images"][k]).is_file() for k in ("spectral", "rgb", "de00"))
        warned = {(w["object"], w["field"].split(".")[0]) for w in r["scene_warnings"]}
        assert {("point_light", "data"), ("area_light", "data"), ("world[sky]", "node_tree")} <= warned, warned
        assert any(w["object"] == "sphere_gold" and "Au" in w["message"] for w in r["scene_warnings"])
    f11 = rows["F11"]
    assert f11["status"] == "visible" and f11["de00"]["noise_p95"] < f11["de00"]["p95"], f11["de00"]
    assert rows["own"]["de00"]["p95"] < f11["de00"]["p95"] / 2, (rows["own"]["de00"], f11["de00"])
    summary = (out / "summary.md").read_text()
    assert "## Conversions from the source scene" in summary and "| ordinary | sphere_gold |" in summary


def test_only_rgb_renderers_are_the_rgb_side(tmp_path):
    """A declared spectral renderer (available here: the example) or ART in the run is not compared
    as if it rendered in RGB."""
    from spectral_bench.batch import backends
    from spectral_bench.batch.backends import command
    from spectral_bench.batch.jobs import job, plan
    from spectral_bench.batch.studies import spectral_vs_rgb as study
    from spectral_bench.exporters import ir_json
    toy = ROOT / "examples" / "your_renderer" / "toy.toml"
    declared = command.load_file(toy)
    made = {"mitsuba": backends.get("mitsuba"), "toy_spectral": backends.get("toy_spectral", declaration=declared["toy_spectral"])}
    assert made["toy_spectral"].availability()[0]
    jobs, rows = study.jobs([("red_sphere", ir_json.load(EXAMPLE))], made, {"illuminants": None}, tmp_path,
                            job.make, plan.for_run)
    assert sorted((j["backend"], j["extra"]["role"]) for j in jobs) == [("mitsuba", "rgb"), ("mitsuba", "spectral")]


def _delta_lit(tmp_path, name, environment):
    """red_sphere lit by a point light (D65, 20 W/sr-like) above the camera, with or without its
    sky (``environment``: the sky's scale, None for none), written as an IR JSON scene."""
    scene = json.loads(EXAMPLE.read_text())
    scene.update(name=name, lights=[{"name": "bulb", "type": "point", "position": [0.0, -4.0, 2.0],
                                     "intensity": {"type": "named", "name": "cie_d65", "scale": 20.0}}])
    scene["render"].update(width=32, height=32)
    if environment is None:
        del scene["environment"]
    else:
        scene["environment"]["radiance"]["scale"] = environment
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(scene))
    return path


def _spd_xyz(path):
    from spectral_bench.exporters import colorimetry
    wl, v = np.loadtxt(path, ndmin=2).T
    return np.asarray(colorimetry.spectrum_xyz({"type": "sampled", "wavelengths": list(wl), "values": list(v)}))


def test_illuminants_swap_point_lights_too(tmp_path, run_batch_here):
    """--illuminants A on a scene lit only by a point light, and on one lit by a sky and a point
    light: every light of the exported scene (the sky's radiance, the bulb's intensity) is A with
    its own luminance, the point-lit row is a comparison (not "no light spectrum to swap"), and the
    spectral render shifts to A's colour: with every light A, the lone red sphere's every lit pixel
    has one chromaticity, the same in both scenes."""
    from spectral_bench.batch import exr
    from spectral_bench.exporters import colorimetry
    a_xy = colorimetry.spectrum_xyz({"type": "named", "name": "cie_a"})
    a_xy = a_xy[:2] / a_xy.sum()
    renders = {}
    for name, env in (("sky_and_bulb", 0.2), ("point_lit", None)):
        out = tmp_path / name
        proc = run_batch_here("--study", "spectral-vs-rgb", "-i", _delta_lit(tmp_path, name, env), "-r", "mitsuba",
                              "--illuminants", "A", "--spp", "64", "-o", out)
        assert proc.returncode == 0, proc.stderr[-3000:]
        rows = {r["light"]: r for r in metrics(out).entries("studies")}
        assert set(rows) == {"own", "A"}, rows
        assert rows["A"]["status"] in study_words() and "de00" in rows["A"], rows["A"]
        folder = out / "studies" / "spectral_vs_rgb" / name
        (own_dir,), (a_dir,) = (list((folder / light).glob("mitsuba-*_spectral")) for light in ("own", "A"))
        spds = sorted(p.name for p in (a_dir / "export" / "spectra").glob("*.spd") if p.name != "ball_reflectance.spd")
        assert spds == (["bulb_intensity.spd"] if env is None else ["bulb_intensity.spd", "environment_radiance.spd"])
        for spd in spds:  # each light: A's chromaticity, its own luminance
            new, old = _spd_xyz(a_dir / "export" / "spectra" / spd), _spd_xyz(own_dir / "export" / "spectra" / spd)
            assert new[:2] / new.sum() == pytest.approx(a_xy, abs=2e-3), (name, spd)
            assert new[1] == pytest.approx(old[1], rel=1e-3), (name, spd)
        renders[name] = {light: exr.read_image_and_stderr(d / "render.exr")[1][..., :3] for light, d in
                         (("own", own_dir), ("A", a_dir))}
    lit = renders["point_lit"]["own"][..., 1] > 0.3 * renders["point_lit"]["own"][..., 1].max()  # well inside the silhouette
    assert lit.sum() > 20

    def x_of(img):  # the chromaticity x of the lit pixels' sum
        xyz = colorimetry.srgb_to_xyz(img[lit].sum(axis=0))
        return float(xyz[0] / xyz.sum())
    point_own, point_a = x_of(renders["point_lit"]["own"]), x_of(renders["point_lit"]["A"])
    assert point_a > point_own + 0.03, (point_own, point_a)  # A (2856 K) is far redder than D65
    assert x_of(renders["sky_and_bulb"]["A"]) == pytest.approx(point_a, abs=0.004), (point_a, point_own)


def test_a_nan_pixel_is_counted_and_said_never_a_verdict(tmp_path, run_batch_here):
    """One NaN pixel in the RGB render of a finished study (planted in its real EXR, the run then
    finished again with --resume, which compares the kept renders): the row is failed, saying how
    many pixels of which render are not finite, with no dE00 and no verdict ("dE00 p95 nan")."""
    import OpenEXR
    out = tmp_path / "out"
    proc = run_batch_here("--study", "spectral-vs-rgb", "-i", EXAMPLE, "-r", "mitsuba", "--spp", "16", "-o", out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (row,) = metrics(out).entries("studies")
    assert row["status"] in study_words()
    exr_path, = (out / "studies" / "spectral_vs_rgb" / "red_sphere" / "own").glob("mitsuba-*_rgb/render.exr")
    with OpenEXR.File(str(exr_path), separate_channels=True) as f:
        header, channels = dict(f.header()), {n: np.array(c.pixels) for n, c in f.channels().items()}
    channels["R"][32, 32] = np.nan
    OpenEXR.File(header, channels).write(str(exr_path))
    proc = run_batch_here("--resume", out)
    assert proc.returncode == 1, proc.stderr[-3000:]  # a failed row: the run is not clean
    (row,) = metrics(out).entries("studies")
    assert row["status"] == "failed" and "de00" not in row and "verdict" not in row, row
    assert row["non_finite"]["rgb"] == {"pixels": 1, "nan": 1, "inf": 0, "of": 64 * 64}, row
    assert row["non_finite"]["spectral"]["pixels"] == 0
    assert "1 of 4096 pixels of the RGB render are not finite (NaN in 1, Inf in 0)" in row["reason"], row
    summary = (out / "summary.md").read_text()
    assert "p95 nan" not in summary and "| nan " not in summary, summary
    assert "1 of 4096 pixels of the RGB render are not finite" in summary


def test_every_kind_of_light_of_the_ir_is_swapped_and_whitens_the_comparison():
    """Every emitter kind of the IR (exporters/ir.py): the sky's radiance, an area emitter's
    radiance, a collimated emitter's irradiance, a point's and a spot's intensity, a directional
    light's irradiance: under("A") gives each A's chromaticity at its own luminance, and the white
    of a scene lit by delta lights alone is theirs, not D65's."""
    from spectral_bench.exporters import colorimetry, ir_json
    from spectral_bench.batch.studies import spectral_vs_rgb as study
    scene = ir_json.load(EXAMPLE)
    panel = {"type": "rectangle", "to_world": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]}
    scene["objects"] += [
        {"name": "panel", "shape": panel, "bsdf": None, "emitter": {"type": "area", "radiance": {"type": "constant", "value": 2.0}}},
        {"name": "beam", "shape": panel, "bsdf": None,
         "emitter": {"type": "collimated", "irradiance": {"type": "named", "name": "cie_d50", "scale": 3.0}}}]
    scene["lights"] = [
        {"name": "bulb", "type": "point", "position": [0.0, -4.0, 2.0], "intensity": {"type": "named", "name": "cie_fl11", "scale": 5.0}},
        {"name": "cone", "type": "spot", "to_world": [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 2], [0, 0, 0, 1]],
         "intensity": {"type": "named", "name": "cie_d65", "scale": 7.0}, "cutoff_angle": 30.0, "beam_width": 20.0},
        {"name": "sun", "type": "directional", "direction": [0.0, 0.5, -0.866], "irradiance": {"type": "constant", "value": 3.0}}]
    before = [colorimetry.spectrum_xyz(h[k]) for h, k in study.lights(scene)]
    assert len(before) == 6
    a = colorimetry.spectrum_xyz({"type": "named", "name": "cie_a"})
    after = [colorimetry.spectrum_xyz(h[k]) for h, k in study.lights(study.under(scene, "A"))]
    for old, new in zip(before, after):
        assert new[1] == pytest.approx(old[1], rel=1e-9)
        assert new[:2] / new.sum() == pytest.approx(a[:2] / a.sum(), abs=1e-9)
    bulb_only = {k: v for k, v in scene.items() if k not in ("environment", "lights")}
    bulb_only.update(objects=scene["objects"][:1], lights=scene["lights"][:1])
    fl11 = colorimetry.spectrum_xyz(scene["lights"][0]["intensity"])
    assert study.white_of(bulb_only) == pytest.approx(fl11 / fl11[1], rel=1e-9)


@pytest.mark.slow
def test_a_textured_hdri_lit_blend_keeps_its_highlights_texture_and_sky(tmp_path):
    """Issue 42's done-when on scripts/make_ordinary_blend.py's "textured" scene (Principled spheres
    at Blender's defaults but roughness 0.3, a floor whose base colour is an image texture, an HDRI
    world, an emissive panel; no annotation): no warning drops or flattens the specular layer, the texture or the
    HDRI; the study exits 0 with both images in its export folder; in its scene file (exported with
    the images beside it) rendered by Mitsuba, the floor's checker is the texture's (its blocks
    vary beyond an F test against the same floor with the texture's mean colour) and the spheres' brightest block is above the
    diffuse-only export's beyond noise (the coat's highlight)."""
    import subprocess
    import sys
    from conftest import render_with_noise
    from spectral_bench.exporters import ir_json
    blend = tmp_path / "ordinary.blend"
    made = subprocess.run([sys.executable, str(ROOT / "scripts" / "make_ordinary_blend.py"), str(blend)],
                          capture_output=True, text=True, timeout=300)
    assert made.returncode == 0 and (tmp_path / "floor_checker.png").is_file(), made.stderr[-2000:]
    out = tmp_path / "out"
    proc = run_batch("--study", "spectral-vs-rgb", "-i", blend, "-s", "textured", "-r", "mitsuba", "--scale", "0.25",
                     "--spp", "64", "-o", out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (row,) = metrics(out).entries("studies")
    assert row["status"] in study_words()
    lost = [w for w in row["scene_warnings"] if any(s in w["message"] for s in
                                                    ("not converted", "substituted", "lost", "is used instead"))]
    assert not lost, lost
    (spectral,) = (out / "studies" / "spectral_vs_rgb" / "textured" / "own").glob("mitsuba-*_spectral")
    assert {p.name for p in (spectral / "export" / "textures").iterdir()} == {"tex_floor_reflectance.exr",
                                                                              "environment.exr"}
    exported = run_batch("-i", blend, "-s", "textured", "--export-only", "--format", "json", "-o", tmp_path / "json")
    assert exported.returncode == 0, exported.stderr[-2000:]
    scene = ir_json.load(tmp_path / "json" / "textured" / "json" / "textured.json")
    assert scene["environment"]["type"] == "map"
    size = (160, 120)

    y_row = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB -> luminance (IEC 61966-2-1)

    def luminance(sc, name):
        """Y and its standard error (the channels' errors taken as fully correlated: an upper bound)."""
        _sc, names, img, se = render_with_noise(sc, tmp_path / name, 64, size)
        idx = [names.index(c) for c in "RGB"]
        return img[..., idx] @ y_row, se[..., idx] @ y_row
    coat, coat_se = luminance(scene, "coat")
    bare = json.loads(json.dumps(scene))
    for o in bare["objects"]:
        if o["name"].startswith("tex_sphere") and o["bsdf"]["type"] == "coated_diffuse":
            o["bsdf"] = {"type": "diffuse", "reflectance": o["bsdf"]["reflectance"]}
    flat = json.loads(json.dumps(scene))
    for o in flat["objects"]:
        o["bsdf"] = {k: v for k, v in (o.get("bsdf") or {}).items() if k != "reflectance_texture"} or o.get("bsdf")
    diffuse, diffuse_se = luminance(bare, "diffuse")
    untextured, _ = luminance(flat, "untextured")
    # the floor in the lower fifth of the view: the checker's squares against the mean colour's floor
    floor = (slice(96, 120), slice(0, 160))
    # the floor's 4 x 4 blocks vary more with the texture than with its mean colour (the same
    # geometry, light and noise besides): their variances' ratio beyond the F test at the suite's alpha
    from scipy import stats as sps
    from spectral_bench.batch.verdict import stats

    def blocks(img):
        f = img[floor]
        return f.reshape(f.shape[0] // 4, 4, f.shape[1] // 4, 4).mean(axis=(1, 3)).ravel()
    tex_b, plain_b = blocks(coat), blocks(untextured)
    ratio = tex_b.var(ddof=1) / plain_b.var(ddof=1)
    assert ratio > sps.f.ppf(1 - stats.ALPHA, len(tex_b) - 1, len(plain_b) - 1), ratio
    # each sphere's brightest 4 x 4 block (whole blocks inside its silhouette) with the coat, against
    # the brightest one of the diffuse-only export (the issue's criterion), beyond their noise
    from spectral_bench.batch.verdict import raycast
    origin, dirs = raycast.camera_rays(scene["camera"], *size)
    for k, name in enumerate(("red", "green", "blue")):
        inside = np.isfinite(raycast.hit_sphere({"center": [-1.6 + 1.6 * k, 0.0, 0.6], "radius": 0.55}, origin, dirs))

        def brightest(img, se):
            best = None
            for y in range(0, size[1] - 3, 2):
                for x in range(0, size[0] - 3, 2):
                    if inside[y:y + 4, x:x + 4].all():
                        v = float(img[y:y + 4, x:x + 4].mean())
                        if best is None or v > best[0]:
                            best = (v, float(np.sqrt((se[y:y + 4, x:x + 4] ** 2).mean() / 16)))
            return best
        (c, c_se), (d, d_se) = brightest(coat, coat_se), brightest(diffuse, diffuse_se)
        assert c - d > 5 * np.hypot(c_se, d_se), (name, c, c_se, d, d_se)
