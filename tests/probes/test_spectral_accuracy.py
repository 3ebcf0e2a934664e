"""Spectral accuracy case: ColorChecker under uniform D65/D50, judged by analytic probes."""
import copy
import re

import numpy as np
import pytest

from conftest import assert_sees, metrics, noise_test, render_with_noise, run_batch
from spectral_bench.exporters import colorimetry
from spectral_bench.batch.verdict import probes
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


def test_mitsuba3_observer_is_mitsubas_own_conversion():
    """The "mitsuba3" observer (the model of mitsuba-cie-y-normalisation) must be Mitsuba's own
    spectrum-to-sRGB conversion, function by function: mi.cie1931_xyz, 1 / MI_CIE_Y_NORMALIZATION
    and mi.xyz_to_srgb, applied in a child process to spectra on the 1 nm grid. Without Mitsuba's
    XYZ -> sRGB matrix the model is off by 8.6e-5 in G for D65 (seen on renders at 5 sigma)."""
    import json
    import subprocess
    import sys
    wl = spectra.cie_1931_cmfs()[0]
    tests = {"d65": spectra.evaluate({"type": "named", "name": "cie_d65"}, wl),
             "narrow 450": np.exp(-0.5 * ((wl - 450) / 8) ** 2), "flat": np.ones_like(wl)}
    code = ("import json, sys, numpy as np, mitsuba as mi; mi.set_variant('scalar_spectral')\n"
            "wl, vals = json.loads(sys.stdin.read())\n"
            "cmf = np.array([list(mi.cie1931_xyz(float(w))) for w in wl]).T\n"
            "out = {}\n"
            "for k, v in vals.items():\n"
            "    xyz = np.trapz(np.array(v) * cmf, wl, axis=1) / 106.7502593994140625\n"
            "    out[k] = list(mi.xyz_to_srgb(mi.ScalarColor3f(*xyz)))\n"
            "print(json.dumps(out))")
    proc = subprocess.run([sys.executable, "-c", code], input=json.dumps([wl.tolist(), {k: v.tolist() for k, v in tests.items()}]),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    mitsuba = json.loads(proc.stdout.strip().splitlines()[-1])
    for k, v in tests.items():
        model = colorimetry.xyz_to_srgb(colorimetry.xyz(v, "mitsuba3"))
        scale = np.abs(model).max()
        np.testing.assert_allclose(mitsuba[k], model, rtol=0, atol=2e-6 * scale, err_msg=k)
        if k == "d65":  # the ground truth differs by Mitsuba's deviation, far beyond that tolerance
            assert np.abs(colorimetry.xyz_to_srgb(colorimetry.xyz(v)) - model).max() > 5e-4 * scale


def test_white_patch_under_d65_is_neutral_in_the_probe():
    env = {"type": "named", "name": "cie_d65", "scale": 1.0}
    white = colorimetry.spectrum_xyz(env)
    rgb = colorimetry.xyz_to_srgb(white)
    assert rgb == pytest.approx([rgb[1]] * 3, rel=2e-3)  # sRGB's white point is D65


CASE_SPP = 16  # a quarter of the charts' 64 (issue 31: their default settings are the main command's)
SEES = 0.01  # each chart's run must see a 1 % uniform error (its own detectable at 16 spp: about 0.07 %)


@pytest.fixture(scope="module")
def chart_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("charts") / "out"
    proc = run_batch("-r", "mitsuba", "-c", "spectral_accuracy", "--no-flip", "--spp", CASE_SPP, "-o", out)
    return proc, out, {r["scene"]: r for r in metrics(out)["runs"]}


@pytest.mark.slow
def test_rendered_charts_meet_the_probes_and_their_references(chart_run):
    """At full resolution and 16 spp, with the power to see a 1 % error: every patch and the
    chart's luminance scale are judged on the render's own noise; Mitsuba's film deviates from the CIE 1931 observer (its 5 nm tables and
    normalisation: known_deviations.toml), so a chart may be 'known' but never 'failed'."""
    proc, out, runs = chart_run
    assert sorted(runs) == sorted(CHARTS)
    for name, run in runs.items():
        assert run["status"] in ("ok", "known"), (name, run["reason"])
        assert run["spp"] == CASE_SPP and run["resolution"] == [620, 420], run
        assert_sees(run, SEES, "a uniform error this test claims to see")
        patches = [p for p in run["probes"] if p["name"].startswith("lambert patch_")]
        assert len(patches) == 24 and all(p["pass"] is not None for p in patches), name
        assert all(p["error"] < 0.5 for p in patches), name  # information: dE00 of every patch
        scale = next(p for p in run["probes"] if p["name"] == "lambert chart luminance scale")
        assert abs(scale["measured"] - 1) < 0.003, scale
        assert not any(p["name"] == "lambert chart_board" for p in run["probes"])  # patches shade it
        # against references in the IR's colour Mitsuba's film fails plainly where the test has the power,
        # and passes against their mitsuba3 observer layer (batch/verdict/observer_layers.py)
        assert run["test"]["pass"] or "mitsuba-cie-y-normalisation" in run["known"], (name, run["test"], run["known"])
    assert proc.returncode == 0


def _chart(golden, tmp_path, change_rendered, name="macbeth_chart_D65"):
    """Render the chart changed by ``change_rendered`` at the default settings and probe it as
    the unchanged scene; the verdict as the runner decides it (known deviations included)."""
    from spectral_bench.batch.verdict import known, status
    rendered = copy.deepcopy(golden[name])
    change_rendered(rendered)
    spp = rendered["render"]["spp"]
    _, names, img, se = render_with_noise(rendered, tmp_path, spp)
    judged = copy.deepcopy(golden[name])
    entry = {"scene": name, "backend": "mitsuba", "mode": "llvm_ad_spectral",
             "versions": {"mitsuba": "3.9.1"}, "sanity": {}}
    devs = known.applicable(known.load(), entry)
    entry["probes"] = probes.evaluate(judged, names, img, stderr=se, passes=2,
                                      observers=[d.observer for d in devs if d.observer])
    return status.decide(entry, known.load())


@pytest.mark.slow
def test_unchanged_chart_is_ok_or_known(golden, tmp_path):
    assert _chart(golden, tmp_path, lambda sc: None)["status"] in ("ok", "known")


@pytest.mark.slow
def test_one_percent_brighter_illuminant_fails(golden, tmp_path):
    def brighter(sc):
        sc["environment"]["radiance"]["scale"] *= 1.01
    entry = _chart(golden, tmp_path, brighter)
    assert entry["status"] == "failed", entry["reason"]
    scale = next(p for p in entry["probes"] if p["name"] == "lambert chart luminance scale")
    assert scale["pass"] is False and scale["measured"] == pytest.approx(1.011, abs=0.002)


@pytest.mark.slow
def test_a_0_3_de00_shift_of_one_patch_fails(golden, tmp_path):
    """Scale one patch's reflectance until its colour moves by 0.3 dE00 (computed, not guessed):
    that patch's probe must fail, the others must not."""
    patch = "patch_orange"
    base = next(o for o in golden["macbeth_chart_D65"]["objects"] if o["name"] == patch)
    env = golden["macbeth_chart_D65"]["environment"]["radiance"]
    white = colorimetry.spectrum_xyz(env)

    def de_for(k):
        def lab(f):
            return colorimetry.lab(colorimetry.spectrum_xyz(base["bsdf"]["reflectance"],
                                                            lambda wl: f * spectra.evaluate(env, wl)), white)
        return colorimetry.delta_e_2000(lab(1.0), lab(k))
    k = 1.0
    while de_for(k) < 0.3:
        k += 0.0005

    def shifted(sc):
        obj = next(o for o in sc["objects"] if o["name"] == patch)
        obj["bsdf"]["reflectance"]["scale"] = k
    entry = _chart(golden, tmp_path, shifted)
    failed = [p["name"] for p in entry["probes"] if p["pass"] is False]
    assert f"lambert {patch}" in failed and entry["status"] == "failed", (k, entry["reason"])


@pytest.mark.slow
def test_d50_rendered_as_d65_fails(golden, tmp_path):
    """The D65 chart's probes and reference must reject a render lit by D50."""
    def d50(sc):
        sc["environment"]["radiance"]["name"] = "cie_d50"
    entry = _chart(golden, tmp_path, d50)
    assert entry["status"] == "failed"
    failed = [p for p in entry["probes"] if p["name"].startswith("lambert patch_") and p["pass"] is False]
    assert len(failed) >= 20 and np.mean([p["error"] for p in failed]) > 2.0
    _, names, img, se = render_with_noise({**golden["macbeth_chart_D50"], "name": "d50"}, tmp_path / "ref", 64)
    assert not noise_test("macbeth_chart_D65", img, se, 64).passed
