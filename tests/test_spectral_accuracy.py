"""Spectral accuracy case: ColorChecker under uniform D65/D50, judged by analytic probes."""
import copy
import re

import numpy as np
import pytest

from conftest import metrics, run_batch
from spectral_bench.batch import backends, exr
from spectral_bench.exporters import colorimetry
from spectral_bench.batch.verdict import compare, probes, references
from spectral_bench.exporters import spectra

CHARTS = ["macbeth_chart_D65", "macbeth_chart_D50"]


def _ir_name(label):
    return "colorchecker_" + re.sub(r"[^a-z0-9]+", "_", re.sub(r"\s*\(.*\)", "", label).lower()).strip("_")


def test_probe_colorimetry_agrees_with_colour_science():
    """Our numpy integration (rho * L -> XYZ -> linear sRGB) against colour-science's own
    ASTM E308 computation of the ColorChecker under D65: within the methods' difference."""
    import colour
    cc = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    env = {"type": "named", "name": "cie_d65", "scale": 1.0}
    white = colorimetry.spectrum_xyz(env)
    d65_xy = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    assert len(cc) == 24
    for label, sd in cc.items():
        ours = colorimetry.spectrum_xyz({"type": "named", "name": _ir_name(label)},
                                        lambda wl: spectra.evaluate(env, wl)) / white[1]
        theirs = colour.sd_to_XYZ(sd, cmfs, colour.SDS_ILLUMINANTS["D65"]) / 100
        rgb_ours = colorimetry.xyz_to_srgb(ours)
        rgb_theirs = colour.XYZ_to_sRGB(theirs, apply_cctf_encoding=False)
        assert np.abs(rgb_ours - rgb_theirs).max() < 1e-3, label
        de = colour.delta_E(colour.XYZ_to_Lab(ours, colour.XYZ_to_xy(white)),
                            colour.XYZ_to_Lab(theirs, d65_xy), method="CIE 2000")
        assert de < 0.1, (label, de)


def test_white_patch_under_d65_is_neutral_in_the_probe():
    env = {"type": "named", "name": "cie_d65", "scale": 1.0}
    white = colorimetry.spectrum_xyz(env)
    rgb = colorimetry.xyz_to_srgb(white)
    assert rgb == pytest.approx([rgb[1]] * 3, rel=2e-3)  # sRGB's white point is D65


@pytest.fixture(scope="module")
def chart_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("charts") / "out"
    proc = run_batch("-r", "mitsuba", "-c", "spectral_accuracy", "--scale", 0.5, "--spp", 64, "--alpha", 0.001, "-o", out)
    return proc, out, {r["scene"]: r for r in metrics(out)["runs"]}


def test_rendered_charts_meet_the_probe_bounds_and_their_references(chart_run):
    proc, out, runs = chart_run
    assert sorted(runs) == sorted(CHARTS)
    for name, run in runs.items():
        assert run["status"] == "ok", (name, run["reason"])
        patches = [p for p in run["probes"] if p["name"].startswith("lambert patch_")]
        assert len(patches) == 24 and all(p["pass"] for p in patches), name
        assert max(p["error"] for p in patches) <= probes.lambert.PATCH_DE_MAX
        assert run["test"]["pass"]
    neutral = [p for p in runs["macbeth_chart_D65"]["probes"] if p["name"].startswith("neutral")]
    assert len(neutral) == 1 and neutral[0]["pass"]
    assert not any(p["name"].startswith("neutral") for p in runs["macbeth_chart_D50"]["probes"])
    assert proc.returncode == 0


def test_d50_rendered_as_d65_fails(golden, tmp_path):
    """The D65 chart's probes and reference must reject a render lit by D50."""
    d65 = golden["macbeth_chart_D65"]
    wrong = copy.deepcopy(d65)
    wrong["environment"]["radiance"]["name"] = "cie_d50"
    for sc in (wrong,):
        sc["render"]["width"], sc["render"]["height"] = 310, 210
    backend = backends.get("mitsuba")
    xml = backend.export(wrong, tmp_path / "m")
    backend.render(xml, backend.mode_for(wrong)[0], 64, tmp_path / "r.exr")
    names, img = exr.read_image(tmp_path / "r.exr")
    judged = copy.deepcopy(d65)
    judged["render"]["width"], judged["render"]["height"] = 310, 210
    found = probes.evaluate(judged, names, img)
    mean = next(p for p in found if p["name"] == "lambert mean dE00")
    assert mean["pass"] is False and mean["error"] > 2.0
    neutral = next(p for p in found if p["name"].startswith("neutral"))
    assert neutral["pass"] is False
    ref = references.load("macbeth_chart_D65")
    m, v, s2 = compare.reference_at(ref.mean, ref.stderr, ref.spp, img.shape)
    assert not compare.z_test(img, m, v, s2, 64).passed
