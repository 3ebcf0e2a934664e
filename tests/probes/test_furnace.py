"""Spectral furnaces (issue 41): the camera inside a closed diffuse sphere that emits Le(l) and
reflects rho(l), L = Le (1 - rho^d) / (1 - rho) per wavelength (batch/verdict/probes/furnace.py).

Fast: the closed form, its colour integral, the enclosure's checks, the probe's verdict and power
on synthetic images (seeded), the RGB prediction and the diagnosis that names it. Slow: Mitsuba
renders both canonical furnaces through the runner (ok or known: its film's recorded deviation),
each run's own power below the 0.5 % the issue asks for, and a depth of 3 meets the truncated
series (and misses the whole one)."""
import copy
import json
import types

import numpy as np
import pytest

from conftest import GOLDEN, metrics, run_batch
from installed import needs_pbrt  # pbrt-v4 as the runner finds it (.pbrt/env.json, SPECTRAL_BENCH_PBRT_ENV, PATH)
from spectral_bench.batch.verdict import probes, stats
from spectral_bench.batch.verdict.diagnosis import materials
from spectral_bench.batch.verdict.probes import furnace
from spectral_bench.exporters import colorimetry, spectra

FURNACES = ["furnace_colorchecker_yellow", "furnace_spiky"]
CUBE_V = [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1], [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]]
# counter-clockwise seen from outside (normals outwards)
CUBE_OUT = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
            [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]
CUBE_IN = [[a, c, b] for a, b, c in CUBE_OUT]


def golden(name):
    return json.loads((GOLDEN / f"{name}.json").read_text())


def test_winding_number_and_closedness_of_a_cube():
    assert furnace.closed(CUBE_OUT) and furnace.closed(CUBE_IN)
    assert not furnace.closed(CUBE_OUT[:-1])  # one triangle missing: open
    assert not furnace.closed(CUBE_OUT[:-1] + [CUBE_IN[-1]])  # one triangle wound the other way
    assert furnace.winding_number(CUBE_V, CUBE_OUT, [0.2, -0.3, 0.5]) == pytest.approx(1.0)
    assert furnace.winding_number(CUBE_V, CUBE_IN, [0.2, -0.3, 0.5]) == pytest.approx(-1.0)
    assert furnace.winding_number(CUBE_V, CUBE_IN, [3.0, 0.0, 0.0]) == pytest.approx(0.0, abs=1e-12)


def test_series_is_the_truncated_neumann_sum():
    rho = np.array([0.0, 0.3, 0.9])
    for d in (1, 2, 3, 64):
        assert furnace.series(rho, d) == pytest.approx(sum(rho ** k for k in range(d)), rel=1e-12)
    assert furnace.series(rho, -1) == pytest.approx(1.0 / (1.0 - rho))
    assert furnace.series(np.array([1.0]), 5) == pytest.approx([5.0])


def test_grey_furnace_is_pbrts_analytic_case():
    """pbrt-v4's own furnace: rho = Le = 0.5 (flat), no depth limit: L = 1, a flat spectrum of 1."""
    flat = {"type": "constant", "value": 1.0}
    got = furnace.expected_rgb({"type": "constant", "value": 0.5}, {"type": "constant", "value": 0.5}, -1)
    assert got == pytest.approx(colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(flat)), rel=1e-9)


def test_fine_colour_integral_agrees_with_the_pipeline_and_resolves_the_peaks():
    """For a smooth spectrum the probe's 0.05 nm rule is the pipeline's 1 nm rule (colorimetry.xyz);
    on furnace_spiky's peaks the 1 nm rule reads 1.0-1.5 % bright (the series is convex between
    grid points), which a correct Mitsuba render resolves (measured: 1.0-1.6 % dark against it)."""
    wl = spectra.cie_1931_cmfs()[0]
    yellow = golden("furnace_colorchecker_yellow")["objects"][0]
    rho, le = yellow["bsdf"]["reflectance"], yellow["emitter"]["radiance"]
    coarse = colorimetry.xyz_to_srgb(colorimetry.xyz(furnace.spectrum(rho, le, 64, wl)))
    assert np.asarray(furnace.expected_rgb(rho, le, 64)) == pytest.approx(coarse, rel=5e-5)
    spiky = golden("furnace_spiky")["objects"][0]
    rho, le = spiky["bsdf"]["reflectance"], spiky["emitter"]["radiance"]
    coarse = colorimetry.xyz_to_srgb(colorimetry.xyz(furnace.spectrum(rho, le, 64, wl)))
    ratio = coarse / np.asarray(furnace.expected_rgb(rho, le, 64))
    assert np.all(ratio > 1.009) and np.all(ratio < 1.02), ratio


@pytest.mark.parametrize("name", FURNACES)
def test_canonical_furnaces_apply_and_flipped_ones_do_not(name):
    scene = golden(name)
    assert furnace.applies(scene) is scene["objects"][0]
    flipped = copy.deepcopy(scene)
    shape = flipped["objects"][0]["shape"]
    shape["faces"] = [[a, c, b] for a, b, c in shape["faces"]]
    assert furnace.applies(flipped) is None  # the faces' fronts outwards: the camera sees their backs
    opened = copy.deepcopy(scene)
    opened["objects"][0]["shape"]["faces"].pop()
    assert furnace.applies(opened) is None
    away = copy.deepcopy(scene)
    away["camera"]["to_world"][0][3] = 10.0
    assert furnace.applies(away) is None


def _synthetic(scene, scale=1.0, sigma=0.01, seed=1):
    """An image of the scene's resolution whose pixels are independent draws about ``scale`` times
    the truth (relative noise ``sigma``)."""
    o = scene["objects"][0]
    e = np.asarray(furnace.expected_rgb(o["bsdf"]["reflectance"], o["emitter"]["radiance"],
                                        furnace.depth(scene)))
    r = scene["render"]
    rng = np.random.default_rng(seed)
    return (e * scale * (1 + sigma * rng.standard_normal((r["height"], r["width"], 3)))).astype(np.float32), e


def _records(scene, image):
    recs = [p for p in probes.evaluate(scene, ["R", "G", "B"], image) if p["name"].startswith("furnace ")]
    assert len(recs) == 2, recs
    return recs


@pytest.mark.parametrize("name", FURNACES)
def test_probe_passes_the_truth_and_fails_a_planted_error_it_can_detect(name):
    scene = golden(name)
    img, _e = _synthetic(scene)
    mean, block = _records(scene, img)
    assert mean["pass"] and block["pass"], (mean, block)
    det = stats.detectable_scale(mean["stat"])
    assert det < 0.002  # 4096 pixels of 1 % noise: the planted 0.5 % below is seen
    bright, _ = _synthetic(scene, scale=1.005)
    assert _records(scene, bright)[0]["pass"] is False
    # a local error: one 4 x 4 block 5 % bright fails the block test, not the mean
    local = img.copy()
    local[8:12, 8:12] *= 1.05
    mean, block = _records(scene, local)
    assert block["detectable"] < 0.05 and mean["pass"] and block["pass"] is False


def test_rgb_prediction_reads_the_spiky_furnace_dark():
    """Jensen: rho reduced to a channel average before the convex series. furnace_spiky's peaks
    (0.9) are mostly lost: RGB predicts 18-24 % less than the truth in every channel."""
    o = golden("furnace_spiky")["objects"][0]
    truth = np.asarray(furnace.expected_rgb(o["bsdf"]["reflectance"], o["emitter"]["radiance"], 64))
    rgb = np.asarray(furnace.rgb_prediction(o["bsdf"]["reflectance"], o["emitter"]["radiance"], 64))
    assert np.all(rgb / truth - 1 < -0.18) and np.all(rgb / truth - 1 > -0.25)


@pytest.mark.parametrize("name", FURNACES)
def test_a_render_at_the_rgb_prediction_fails_and_the_diagnosis_names_rgb_transport(name):
    scene = golden(name)
    o = scene["objects"][0]
    img, e = _synthetic(scene, sigma=0.001)
    rgb = np.asarray(furnace.rgb_prediction(o["bsdf"]["reflectance"], o["emitter"]["radiance"], 64))
    img = (img * (rgb / e)).astype(np.float32)
    recs = _records(scene, img)
    assert recs[0]["pass"] is False and recs[1]["pass"] is False
    assert recs[0]["rgb"]["stat"]["pass"] is True
    fit = materials._rgb_transport(types.SimpleNamespace(entry={"probes": recs}))
    assert fit.fully and fit.chi2 < 0.01 * fit.chi2_none
    assert fit.values == pytest.approx((100 * (rgb / e - 1)).tolist(), abs=0.01)
    # the truth itself is not RGB transport
    right, _ = _synthetic(scene, sigma=0.001)
    fit = materials._rgb_transport(types.SimpleNamespace(entry={"probes": _records(scene, right)}))
    assert not fit.fully


@pytest.mark.slow
def test_mitsuba_renders_the_furnaces_within_their_noise(tmp_path):
    """The default run's settings: Mitsuba ok (or known: its film's recorded 0.1 %, resolved by the
    yellow furnace) with each run's power below the issue's 0.5 %."""
    out = tmp_path / "run"
    proc = run_batch("-r", "mitsuba", *sum((["-s", n] for n in FURNACES), []), "-o", out, "--references", tmp_path)
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert set(runs) == set(FURNACES), proc.stderr[-2000:]
    for name, run in runs.items():
        assert run["status"] in ("ok", "known"), (name, run.get("reason"))
        assert run["detectable"]["scale"] <= 0.005, run["detectable"]
        assert [p["pass"] for p in run["probes"] if p["name"].startswith("furnace ")] != []


@pytest.mark.slow
def test_mitsuba_at_depth_three_meets_the_truncated_series(tmp_path):
    """max_depth 3 (docs/scene-format.md: segments): Le (1 + rho + rho^2), not Le / (1 - rho)."""
    from spectral_bench.batch import backends, exr
    scene = golden("furnace_colorchecker_yellow")
    scene["render"].update(max_depth=3, width=32, height=32)
    backend = backends.get("mitsuba")
    mode, why = backend.mode_for(scene)
    xml = backend.export(scene, tmp_path / "mitsuba")
    backend.render(xml, mode, 64, tmp_path / "render.exr", passes=2, seed=0)
    names, img, _se = exr.read_image_and_stderr(tmp_path / "render.exr")
    recs = [p for p in probes.evaluate(scene, names, img, observers=("mitsuba3",)) if p["name"].startswith("furnace ")]
    mean = recs[0]
    assert "d = 3" in mean["name"] and mean["alternatives"]["mitsuba3"]["pass"], mean
    assert stats.detectable_scale(mean["stat"]) < 0.01
    o = scene["objects"][0]
    whole = np.asarray(furnace.expected_rgb(o["bsdf"]["reflectance"], o["emitter"]["radiance"], -1))
    assert np.max(np.abs(np.asarray(mean["measured"]) / whole - 1)) > 0.1  # the depth limit is seen


@pytest.mark.slow
def test_cycles_fails_the_furnaces_by_the_predicted_rgb_gap(tmp_path):
    """-r rgb (Cycles): both furnaces fail against the spectral truth, the render meets the RGB
    prediction within its standard error, and the reason names the diagnosis "RGB transport"
    (reduced settings: 32 x 32 at 64 spp still resolves the gap, 3-45 %, to 0.1 %: asserted)."""
    out = tmp_path / "run"
    proc = run_batch("-r", "cycles", *sum((["-s", n] for n in FURNACES), []), "--scale", "0.5", "--spp", "64",
                     "--no-flip", "-o", out, "--references", tmp_path)
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert set(runs) == set(FURNACES), proc.stderr[-2000:]
    for name, run in runs.items():
        assert run["status"] == "failed", (name, run.get("reason"))
        mean = next(p for p in run["probes"] if p.get("rgb"))
        gap = np.abs(np.asarray(mean["rgb"]["gap"]))
        assert run["detectable"]["scale"] < 0.1 * gap.min()  # the run sees a tenth of the smallest gap
        assert mean["rgb"]["stat"]["pass"], mean["rgb"]
        assert "likely: RGB transport" in run["reason"], run["reason"]


@pytest.mark.slow
@needs_pbrt
def test_pbrt_meets_the_furnaces_truth(tmp_path):
    """pbrt-v4 (the writer's maxdepth = d - 1; its two-sided diffuse never seen inside the closed
    mesh) passes both furnace probes at the scenes' resolution and 128 spp, each run seeing 2 %
    (measured at 128 spp: spiky 1.0 %; at the scenes' spp: 0.08 % and 0.47 %)."""
    out = tmp_path / "run"
    proc = run_batch("-r", "pbrt", *sum((["-s", n] for n in FURNACES), []), "--spp", "128", "--no-flip",
                     "-o", out, "--references", tmp_path)
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert set(runs) == set(FURNACES), proc.stderr[-2000:]
    for name, run in runs.items():
        assert run["status"] == "ok", (name, run.get("reason"))
        assert run["detectable"]["scale"] < 0.02, run["detectable"]
