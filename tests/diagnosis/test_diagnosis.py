"""Issue 34's done-when on real renders: a declared renderer wrapping Mitsuba (tests/plant_renderer.py,
declared in tests/data/plant_renderers.toml) plants one catalogue error per renderer; the batch
judges and diagnoses it. Each planted model must be ranked first, fully explaining the failure,
with its parameter within two standard errors of the planted value; a stain outside the
catalogue gets "no model explains it"; a correct render gets no diagnosis. Every run asserts its
own power (``detectable``: the smallest uniform scale error it sees with 90 % power) below 1 %,
far below each planted effect, so a render too small to see them fails here loudly.

The renders are shared by every test of the module (one fixture: the copper scene with seven
planted renderers in one batch run, and one run for each of the three scenes the polarisation
and observer plants need), at a quarter of the resolution (the polariser and observer runs
at an eighth). The plants whose parameter is compared with the planted value (scale, alpha,
emitter) render through the references' CMF film (tests/data/plant_renderers.toml ``--film cmf``):
through Mitsuba's RGB film, 0.1 % bright against the references, the scale and the emitter factor
came out 2 standard errors high on average (+2.9 se on seeds 2 and 3; with the CMF film seeds 0-3
give -1.5 to +1.1 se). The fitting itself on synthetic images: tests/diagnosis/test_diagnosis_fit.py.
"""
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
from spectral_bench.batch import records  # noqa: E402

sys.path.insert(0, str(ROOT / "tests"))
import render_cache  # noqa: E402
from spectral_bench.batch.verdict import known  # noqa: E402

RUN = ROOT / "batch" / "run.py"
PLANTS = ROOT / "tests" / "data" / "plant_renderers.toml"
COPPER = ("plant_scale", "plant_srgb", "plant_flip", "plant_alpha", "plant_emitter", "plant_stain", "plant_none")
# (scene, renderer, scale, spp): the runs besides the copper one. The polariser and observer
# runs at an eighth of the resolution (issue 45: measured on seeds 0, 1 and 2, detectable 0.24 %
# and 0.43 %, the polariser's angle within 0.7 se); the Stokes run stays at a quarter, 64 spp (at
# an eighth its angle's standard error either grew 85-fold at 64 spp or came out 2.3 se off at
# 256). The copper run stays at a quarter, 256 spp: its time is the diagnosis's GGX alpha fits,
# which do not shrink with the image, and at an eighth with 1024 spp two of three seeds failed.
OTHERS = (("polarizing_plane_0", "plant_polariser", "0.125", 256), ("polarizing_spheres", "plant_stokes", "0.25", 64),
          ("macbeth_chart_D65", "plant_observer", "0.125", 256))


def batch(out, *args, cache=None):
    """A batch run of the planted renderers; with ``cache`` (a folder), renderers that plant on the
    output of the same scene, samples and seed share one render (tests/render_cache.py: the same
    image, bit for bit, that each would have rendered)."""
    env = dict(os.environ, **{render_cache.ENV: str(cache)}) if cache else None
    proc = subprocess.run([sys.executable, str(RUN), "--renderers", str(PLANTS), "--scale", "0.25", *args,
                           "-o", str(out)], capture_output=True, text=True, timeout=1800, cwd=ROOT, env=env)
    data = json.loads((out / "metrics.json").read_text())
    return proc, data


@pytest.fixture(scope="module")
def shared_renders(tmp_path_factory):
    """The module's render cache: the copper run's seven renderers render three images a pass (the
    CMF film's scale and emitter plants one, Mitsuba's film's sRGB, flip, stain and none one, the
    alpha plant its own), and the 16 spp sRGB and black runs one (issue 45)."""
    return tmp_path_factory.mktemp("render_cache")


@pytest.fixture(scope="module")
def runs(tmp_path_factory, shared_renders):
    base = tmp_path_factory.mktemp("diagnosis")
    out = {}
    copper = [a for r in COPPER for a in ("-r", r)]
    proc, data = batch(base / "copper", *copper, "-s", "ggx_copper_50", "--spp", "256", "--junit", str(base / "junit.xml"),
                       cache=shared_renders)
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]  # failures, and one ok
    problems = records.validate(data)
    assert not problems, problems
    out.update({r["backend"]: r for r in data["runs"]})
    out["_copper"] = base / "copper"
    out["_junit"] = base / "junit.xml"
    for scene, renderer, scale, spp in OTHERS:
        proc, data = batch(base / renderer, "-r", renderer, "-s", scene, "--scale", scale, "--spp", str(spp),
                           cache=shared_renders)
        assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
        assert not records.validate(data)
        out.update({r["backend"]: r for r in data["runs"]})
    return out


def top(run):
    assert run["status"] == "failed", run["reason"]  # the diagnosis never changes a status
    assert run["detectable"]["scale"] < 0.01, run["detectable"]  # the run's own power
    diag = run["diagnosis"]
    assert diag["models"], diag
    return diag, diag["models"][0]


def within_two_se(model, name, planted):
    value, se = model["params"][name]
    assert se is not None and math.isfinite(se) and se > 0, model
    assert abs(value - planted) <= 2 * se, (model, planted)


@pytest.mark.slow
@pytest.mark.parametrize("renderer, model, param, planted", [
    ("plant_scale", "uniform scale", "scale", 1.03),
    ("plant_srgb", "sRGB transfer applied", None, None),
    ("plant_flip", "flipped vertically", None, None),
    ("plant_alpha", "GGX alpha", "alpha", 0.22),
    ("plant_emitter", "emitter radiance x pi", "factor", math.pi),
    ("plant_polariser", "polariser angle", "angle deg", 90.0),
    ("plant_stokes", "Stokes frame rotated", "angle deg", 90.0),
    ("plant_observer", "observer CIE 1964", None, None),
])
def test_planted_error_is_ranked_first(runs, renderer, model, param, planted):
    diag, first = top(runs[renderer])
    assert first["model"] == model and first["fully_explains"], diag["models"][:3]
    assert diag["likely"] == model and f"likely: {model}" in runs[renderer]["reason"]
    if param:
        within_two_se(first, param, planted)


@pytest.mark.slow
def test_stain_outside_the_catalogue_is_explained_by_no_model(runs):
    diag, _ = top(runs["plant_stain"])
    assert diag["likely"] is None and "no model explains it" in runs["plant_stain"]["reason"], diag["models"][:2]
    assert "known_deviation" not in diag


@pytest.mark.slow
def test_correct_render_gets_no_diagnosis(runs):
    ok = runs["plant_none"]
    assert ok["status"] == "ok" and "diagnosis" not in ok and ok["detectable"]["scale"] < 0.01


@pytest.mark.slow
def test_diagnosis_is_shown_where_the_failure_is(runs):
    """The JUnit failure message, the summary, the report's "why" box, and a ready
    known_deviations.toml entry for a model known.py can re-judge (a scale)."""
    cases = {c.get("name").split("/")[0]: c for c in ET.parse(runs["_junit"]).getroot().iter("testcase")}
    assert "likely: uniform scale 1.0" in cases["plant_scale"].find("failure").get("message")
    assert "no model explains it" in cases["plant_stain"].find("failure").get("message")
    assert cases["plant_none"].find("failure") is None
    summary = (runs["_copper"] / "summary.md").read_text()
    assert "likely: flipped vertically" in summary
    report = (runs["_copper"] / "report.html").read_text()
    assert "<b>why</b>: likely: sRGB transfer applied" in report
    entry = runs["plant_scale"]["diagnosis"]["known_deviation"]
    assert entry.startswith("[[deviation]]") and 'checks = ["noise test"]' in entry and "scale = 1.0" in entry
    toml = runs["_copper"] / "proposed.toml"
    toml.write_text(entry)
    (dev,) = known.load(toml)  # ready to add: known.py reads it as it is
    assert dev.backend == "plant_scale" and abs(dev.scale - 1.03) < 0.002 and dev.explains("noise test")
    assert runs["plant_observer"]["diagnosis"]["known_deviation"].count('observer = "cie1964"') == 1
    model_image = runs["plant_flip"]["diagnosis"]["image"]
    assert (runs["_copper"] / model_image).is_file()


def _params_text(text):
    """Every 'value +- se' a diagnosis text prints, as (value, se) strings."""
    import re
    return re.findall(r"(-?[\d.]+(?:e[+-]?\d+)?) \+- (-?[\d.]+(?:e[+-]?\d+)?)", text)


@pytest.mark.slow  # renders (or builds .blend files) through the real entry point: the full suite, not the fast subset
def test_no_confident_diagnosis_from_one_block(tmp_path, shared_renders):
    """Issue 40: ggx_copper_50 at 32x32 and 32 spp is one noise-test block, 3 residuals (R, G, B,
    one cluster). A constant grey render was 'likely: per-channel scale ... +- 0.000000, explains
    100 %', a black one got a proposed known deviation of scale 0, and the per-pass sRGB curve at 4
    spp (128x128, again one block) a per-channel scale: models fitted on no more residuals (or
    blocks) than parameters, whose sandwich standard errors are 0 by construction. Now such a model
    is not fitted and the diagnosis says so; no standard error of 0 is printed; nothing is
    proposed for known_deviations.toml."""
    runs = {}
    for scale, spp, renderers in (("0.0625", "32", ("plant_grey", "plant_black")), ("0.25", "4", ("plant_srgb",))):
        proc, data = batch(tmp_path / f"out{spp}", *[a for r in renderers for a in ("-r", r)], "-s", "ggx_copper_50",
                           "--scale", scale, "--spp", spp, "--no-flip", cache=shared_renders)
        assert proc.returncode == 1 and not records.validate(data), proc.stdout[-3000:] + proc.stderr[-3000:]
        runs.update({r["backend"]: r for r in data["runs"]})
    for name in ("plant_grey", "plant_black", "plant_srgb"):
        run = runs[name]
        assert run["status"] == "failed" and run["test"]["pass"] is False, run["reason"]
        diag = run["diagnosis"]
        assert diag["likely"] is None and "known_deviation" not in diag, (name, diag["text"])
        thin = {t["model"]: t["why"] for t in diag["not_fitted"]}
        assert "per-channel scale" in thin and "uniform scale" in thin, (name, thin)
        assert thin["per-channel scale"] == "3 residuals for 3 parameters", thin
        assert thin["uniform scale"] == "3 residuals in 1 block (independent clusters) for 1 parameter", thin
        assert "too little evidence" in diag["text"] and "too little evidence" in run["reason"], diag["text"]
        for m in diag["models"]:  # what was fitted: every parameter on more residuals than parameters
            assert m["n"] > m["k"], m
            for p, (value, se) in m["params"].items():
                assert se is None or se > 0, (name, m["model"], p, se)
        for value, se in _params_text(run["reason"]):
            assert float(se) > 0, (name, run["reason"])


@pytest.fixture(scope="module")
def copper_16spp(tmp_path_factory, shared_renders):
    """ggx_copper_50 at 128x128 and 16 spp through the per-pass sRGB curve and the black render, in
    one batch run (the two tests below; the black plant scales the same render by 0)."""
    out = tmp_path_factory.mktemp("copper_16spp") / "out"
    proc, data = batch(out, "-r", "plant_srgb", "-r", "plant_black", "-s", "ggx_copper_50", "--spp", "16", "--no-flip",
                       cache=shared_renders)
    assert proc.returncode == 1 and not records.validate(data), proc.stdout[-3000:] + proc.stderr[-3000:]
    assert sorted(r["backend"] for r in data["runs"]) == ["plant_black", "plant_srgb"]
    return {r["backend"]: r for r in data["runs"]}


@pytest.mark.slow
def test_a_model_that_does_not_fully_explain_says_what_it_leaves(copper_16spp):
    """Issue 40: the per-pass sRGB curve at 128x128 and 16 spp read 'no model explains it (best:
    sRGB transfer applied, explains 100.0 %)'. The curve of each noisy pass is not the curve of
    their mean, so something is left; the text now gives the share to the digit that differs from
    100 % and the residual's chi-square against what noise alone gives, with its p."""
    import re
    run = copper_16spp["plant_srgb"]
    diag = run["diagnosis"]
    best = diag["models"][0]
    assert run["status"] == "failed" and diag["likely"] is None and not best["fully_explains"], diag["text"]
    assert best["model"] == "sRGB transfer applied", diag["models"][:2]
    shown = re.search(r"best: sRGB transfer applied, explains ([\d.]+) %", diag["text"])
    assert shown and float(shown.group(1)) < 100, diag["text"]  # never "100.0 %" for a model that leaves some
    assert abs(float(shown.group(1)) - 100 * best["explains"]) < 10 ** -(len(shown.group(1).split(".")[1])), (shown, best)
    left = re.search(r"left: chi-square ([\d.e+]+) where noise alone gives (\d+) \+- [\d.]+, p ([\d.e+-]+)", diag["text"])
    assert left, diag["text"]
    assert float(left.group(1)) == pytest.approx(best["chi2"], rel=1e-3) and int(left.group(2)) == best["n"]
    assert float(left.group(3)) < 0.01 and best["chi2"] > best["n"], (left.group(0), best)  # beyond the noise
    assert diag["text"] in run["reason"]


@pytest.mark.slow  # renders (or builds .blend files) through the real entry point: the full suite, not the fast subset
def test_a_black_render_gets_no_proposed_known_deviation(copper_16spp):
    """Issue 40: a black render (every pixel 0) at 128x128 and 16 spp, many blocks: a uniform scale
    of about 1e-16 fits it exactly and was printed "scale 0.000000 +- 0.000000" with a ready
    known_deviations.toml entry of that scale. A proposed entry needs a finite, physically
    plausible scale (diagnosis PLAUSIBLE_SCALE); and the printed figures keep their digits."""
    from spectral_bench.batch.verdict import diagnosis
    run = copper_16spp["plant_black"]
    diag = run["diagnosis"]
    assert run["status"] == "failed" and "known_deviation" not in diag, diag.get("known_deviation")
    for m in diag["models"]:
        for p, (value, se) in m["params"].items():
            assert se is None or se > 0, (m["model"], p, se)
    assert "+- 0.000000" not in run["reason"] and not any(float(se) == 0 for _, se in _params_text(run["reason"]))
    assert not diagnosis.plausible({"scale": 1.1e-16, "scale_se": 6.4e-17})
    assert diagnosis.plausible({"scale": 1.03, "scale_se": 0.0005}) and diagnosis.plausible({"scale": 3.14159, "scale_se": 0.0})
