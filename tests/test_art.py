"""ART: the .arm writer (golden files, structure, what ART cannot express, radiometric factors)
and, where an ``artist`` is installed, renders judged by the analytic probes.

The render tests need ART 2.1.2 (not in any package registry; CI has none): they skip with a
visible reason when ``artist`` is not on PATH (or ART_ARTIST points elsewhere)."""
import copy
import os
import re
import shutil

import pytest

from conftest import ALL_SCENES, ROOT, metrics, run_batch, write_scene
from spectral_bench.batch import backends, exr
from spectral_bench.batch.verdict import probes
from spectral_bench.exporters import art_writer

ARTIST = os.environ.get("ART_ARTIST") or shutil.which("artist")
needs_artist = pytest.mark.skipif(not ARTIST, reason="no ART 'artist' on PATH (set ART_ARTIST): ART renders not run")


@pytest.mark.parametrize("name", ALL_SCENES)
def test_writer_matches_golden_folder(golden, tmp_path, name):
    expected = ROOT / "golden" / "art" / name
    art_writer.write(golden[name], tmp_path)
    written = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if p.is_file())
    assert written == sorted(p.relative_to(expected) for p in expected.rglob("*") if p.is_file())
    for rel in written:
        assert (tmp_path / rel).read_bytes() == (expected / rel).read_bytes(), rel  # meshes are binary PLY


def _structure_ok(text, folder):
    code = re.sub(r"//[^\n]*", "", text)
    for a, b in ("()", "[]", "{}"):
        depth = 0
        for ch in code:
            depth += (ch == a) - (ch == b)
            assert depth >= 0, f"unbalanced {a}{b}"
        assert depth == 0, f"unbalanced {a}{b}"
    assert code.count("ARM_MAIN_FUNCTION(") == 1
    for ply in re.findall(r'PLY_MESH\("([^"]+)"\)', code):
        assert (folder / ply).is_file(), ply
    return True


@pytest.mark.parametrize("name", ALL_SCENES)
def test_every_scene_writes_a_well_formed_arm(golden, tmp_path, name):
    path, _ = art_writer.write(golden[name], tmp_path)
    assert _structure_ok(path.read_text(), tmp_path)


def test_meshes_are_written_as_ply_in_world_space(golden, tmp_path):
    sc = copy.deepcopy(golden["ggx_glass"])
    sc["objects"].append({"name": "tri", "bsdf": {"type": "diffuse", "reflectance": {"type": "constant", "value": 0.5}},
                          "emitter": None, "shape": {"type": "mesh", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                                                     "faces": [[0, 1, 2]], "to_world": [[1, 0, 0, 5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}})
    path, _ = art_writer.write(sc, tmp_path)
    assert _structure_ok(path.read_text(), tmp_path)
    from spectral_bench.exporters import mesh_io
    verts, faces = mesh_io.read_ply(tmp_path / "meshes" / "tri.ply")
    assert verts[1] == [6.0, 0.0, 0.0] and faces == [[0, 1, 2]]


def test_ggx_is_reported_not_substituted_and_the_option_writes_it(golden, tmp_path):
    problems = art_writer.unsupported(golden["ggx_copper_50"])
    assert [(o, f) for o, f, _ in problems] == [("copper_plate_50", "bsdf.roughness.distribution")]
    assert "Blinn" in problems[0][2]
    path, left = art_writer.write(golden["ggx_copper_50"], tmp_path, ggx=True)
    assert left == [] and "GGX_MICROFACET_DISTRIBUTION_CONST(0.2)" in path.read_text()
    mode, why = backends.get("art").mode_for(golden["ggx_glass"])  # needs no artist to decide
    assert mode is None and "glass_sphere.bsdf.roughness.distribution" in why


def test_radiometric_factors_follow_the_ir_normalisation(golden):
    """IR: named illuminants are 1.0 at 560 nm times scale; ART's tables are 100 there."""
    text = (ROOT / "golden" / "art" / "polarizing_plane_0" / "scene.arm").read_text()
    assert "LAMBERT_EMITTER(CIE_ILLUMINANT_D65, 0.04)" in text  # the IR's scale 4
    chart = (ROOT / "golden" / "art" / "macbeth_chart_D50" / "scene.arm").read_text()
    assert "UNIFORM_ENVIRONMENT_MATERIAL(CIE_ILLUMINANT_D50, 0.01)" in chart
    assert "LINEAR_POLARISATION_FILTER angle: 90.0 DEGREES" in (
        ROOT / "golden" / "art" / "polarizing_plane_90" / "scene.arm").read_text()


def test_missing_artist_gives_skipped_jobs_never_passed(golden, tmp_path):
    out = tmp_path / "o"
    proc = run_batch("-i", write_scene(tmp_path, golden["polarizing_plane_0"]), "-r", "art",
                     "-e", f"art={tmp_path / 'no_artist'}", "-o", out)
    runs = metrics(out)["runs"]
    assert [r["status"] for r in runs] == ["skipped"] and "not found" in runs[0]["reason"]
    assert proc.returncode == 4  # nothing ran: every job skipped (exit 4, batch/verdict/status.py); the summary lists it
    assert "skipped" in (out / "summary.md").read_text()


def test_art46_observer_is_the_backends_band_film(tmp_path):
    """The art46 observer (exporters/colorimetry.py) must be exactly what the backend computes
    from ART's band film: each 10 nm band's box average, read from a spectral EXR named as ART
    names its channels, weighted by its hat function times the CMFs (batch/spectral_exr.py). And
    it must differ from the CIE observer where the deviation says it does (a saturated colour)."""
    import numpy as np
    import OpenEXR
    from spectral_bench.batch.backends.art.backend import stokes_to_rgb
    from spectral_bench.exporters import colorimetry, spectra
    start, width, count = colorimetry.ART_BANDS_NM
    fine = np.linspace(300.0, 850.0, 55001)
    wl = spectra.cie_1931_cmfs()[0]
    for centre, sigma in ((450.0, 12.0), (610.0, 25.0), (540.0, 150.0)):
        radiance = lambda x: np.exp(-0.5 * ((x - centre) / sigma) ** 2) * ((x >= 360) & (x <= 830))  # noqa: E731
        channels = {}
        for b in range(count):
            lo, hi = start + width * b, start + width * (b + 1)
            inside = fine[(fine >= lo) & (fine <= hi)]
            channels[f"S0.{lo + width / 2:.0f},000000nm"] = np.full((1, 1), np.trapz(radiance(inside), inside) / width)
        path = tmp_path / f"art_{centre:.0f}.exr"
        with OpenEXR.File({"type": OpenEXR.scanlineimage}, {n: a.astype(np.float32) for n, a in channels.items()}) as f:
            f.write(str(path))
        names, img = stokes_to_rgb(path)
        assert names == ["R", "G", "B"]
        model = colorimetry.xyz_to_srgb(colorimetry.xyz(radiance(wl), "art46"))
        truth = colorimetry.xyz_to_srgb(colorimetry.xyz(radiance(wl)))
        np.testing.assert_allclose(img[0, 0], model, rtol=2e-4, atol=2e-4 * np.abs(model).max())  # float32 bands
        if sigma < 20:  # saturated: the band film is measurably not the CIE integral
            assert (np.abs(model - truth) / np.abs(truth)).max() > 0.01, (centre, model, truth)


@needs_artist
def test_art_chart_at_default_settings_is_known_only_for_the_recorded_version(tmp_path):
    """ART 2.1.2's ColorChecker at the product's defaults fails the CIE probes exactly as the
    band film predicts (art-46-band-film): `known`. The same record from another ART version is
    not covered by the deviation and fails."""
    from spectral_bench.batch.verdict import known, status
    out = tmp_path / "o"
    proc = run_batch("-r", "art", "-s", "macbeth_chart_D65", "-o", out)
    run = metrics(out)["runs"][0]
    assert run["status"] == "known" and run["known"] == ["art-46-band-film"], (run["reason"], proc.stderr[-2000:])
    assert run["versions"]["art"] == "2.1.2"
    assert any(p["pass"] is False for p in run["probes"])  # the deviation is seen, not absent
    other = copy.deepcopy(run)
    other["versions"]["art"] = "2.2.0"
    assert status.decide(other, known.load())["status"] == "failed"


@needs_artist
def test_art_renders_the_chart_judged_on_its_own_noise(golden, tmp_path):
    """ART's spectral EXR integrated with the CIE CMFs (the backend's route): every patch meets
    the analytic probe on ART's own noise (two passes), and an out-of-gamut colour keeps its
    negative component (ColorChecker cyan's red), which ART's own sRGB output maps away."""
    sc = copy.deepcopy(golden["macbeth_chart_D65"])
    sc["render"]["width"], sc["render"]["height"] = 155, 105
    b = backends.get("art", executable=ARTIST)
    b.render(b.export(sc, tmp_path / "art"), b.mode_for(sc)[0], 128, tmp_path / "r.exr", passes=2)
    names, img, se = exr.read_image_and_stderr(tmp_path / "r.exr")
    assert se is not None
    found = {p["name"]: p for p in probes.evaluate(sc, names, img, stderr=se, passes=2)}
    patches = [p for n, p in found.items() if n.startswith("lambert patch_")]
    assert len(patches) == 24 and all(p["pass"] for p in patches), [(p["name"], p["z"]) for p in patches if not p["pass"]]
    assert found["lambert chart luminance scale"]["pass"]
    cyan = found["lambert patch_cyan"]
    assert cyan["expected"][0] < 0 and cyan["measured"][0] < 0, cyan


@needs_artist
@pytest.mark.parametrize("angle, turned, expect_bright", [(0.0, 0.0, True), (90.0, 0.0, False), (30.0, 30.0, True),
                                                         (-30.0, 30.0, False)])
def test_art_brewster_and_polariser_convention(golden, tmp_path, angle, turned, expect_bright):
    from test_polarization import _turned
    sc = _turned(golden["polarizing_plane_0"], turned)
    sc["camera"]["polarizer"]["angle"] = angle
    sc["render"]["width"] = sc["render"]["height"] = 96
    b = backends.get("art", executable=ARTIST)
    b.render(b.export(sc, tmp_path / "art"), b.mode_for(sc)[0], 64, tmp_path / "r.exr")
    names, img = exr.read_image(tmp_path / "r.exr")
    p = next(x for x in probes.evaluate(sc, names, img) if x["name"].startswith("brewster"))
    assert p["pass"], p
    assert (sum(p["measured"]) > 0.5) == expect_bright
