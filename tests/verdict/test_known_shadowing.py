"""A known deviation whose model is a renderer's Smith shadowing form (known_deviations.toml
``shadowing``; batch/verdict/known.py): pbrt-v4 has only the height-correlated G2 where the IR's
GGX is the separable G1 G1. The GGX probe judges each plate with the other form too; a deviation
naming the form re-judges the probe's checks with it, and never the noise test (whose reference
was rendered with the IR's form)."""
import copy

import numpy as np
import pytest

from spectral_bench.batch.verdict import known, status
from spectral_bench.batch.verdict.probes import Measurement, ggx
from spectral_bench.exporters import colorimetry

ENTRY = {"id": "hc", "backend": "pbrt", "checks": ["ggx *", "noise test"], "evidence": "measured",
         "explanation": "explained", "date": "2026-12-04", "scenes": ["ggx_copper_grazing"],
         "shadowing": "height-correlated"}


def _toml(entry):
    def value(v):
        return "[" + ", ".join(f'"{x}"' for x in v) + "]" if isinstance(v, list) else f'"{v}"'
    return "[[deviation]]\n" + "".join(f"{k} = {value(v)}\n" for k, v in entry.items())


def test_the_forms_are_the_probes_and_a_bad_one_is_named(tmp_path):
    assert known.SHADOWING_FORMS == ggx.SHADOWING_FORMS
    path = tmp_path / "known.toml"
    path.write_text(_toml(ENTRY))
    (dev,) = known.load(path)
    assert dev.shadowing == "height-correlated" and dev.observer is None
    for bad, why in (({"shadowing": "smooth"}, "unknown Smith form"),
                     ({"observer": "mitsuba3"}, "not both")):
        path.write_text(_toml({**ENTRY, **bad}))
        with pytest.raises(known.KnownDeviationsError, match=f"field shadowing: .*{why}"):
            known.load(path)


def _measured(golden, form, size=128, rel_se=0.005, seed=3):
    """ggx_copper_grazing as a renderer with the Smith form ``form`` would show it: the GGX probe's
    own closed form with that form, with Gaussian noise of the stated standard error per pixel."""
    sc = copy.deepcopy(golden["ggx_copper_grazing"])
    sc["render"].update(width=size, height=size)
    plate, lights = ggx._applies(sc)
    mask, images = ggx.expected_images(sc, plate[0], lights, size, size, [colorimetry.GROUND_TRUTH], form)
    truth = images[colorimetry.GROUND_TRUTH]
    se = np.where(mask[..., None], rel_se * truth, 1e-6) + 1e-9
    img = truth + np.random.default_rng(seed).normal(size=truth.shape) * se
    return sc, mask, Measurement(sc, ["R", "G", "B"], img, se, None, 2, ())


def test_a_height_correlated_renderer_is_known_only_under_the_deviation(golden):
    """The probe's separable verdict fails (G2 / (G1 G1) is 1.04 at 80 degrees), its
    height-correlated alternative passes; the job is failed without the deviation and known with
    it. A separable renderer passes plainly and the deviation's alternative then fails: fixed."""
    sc, mask, m = _measured(golden, "height-correlated")
    assert mask.sum() > 500  # the plate is judged, not skipped for want of pixels
    probes = ggx.plates(m)
    assert [p["pass"] for p in probes] == [False, False], [(p["name"], p.get("z")) for p in probes]
    key = ggx.shadowing_key("height-correlated")
    assert [p["alternatives"][key]["pass"] for p in probes] == [True, True]
    entry = {"scene": "ggx_copper_grazing", "backend": "pbrt", "mode": "spectral47", "versions": {}, "probes": probes}
    assert status.decide(copy.deepcopy(entry), [])["status"] == "failed"
    (dev,) = [known.Deviation(**ENTRY)]
    decided = status.decide(copy.deepcopy(entry), [dev])
    assert decided["status"] == "known" and decided["known"] == ["hc"], decided
    _sc, _mask, m_sep = _measured(golden, "separable")
    sep = ggx.plates(m_sep)
    assert [p["pass"] for p in sep] == [True, True]
    assert status.decide({**entry, "probes": sep}, [dev])["status"] == "fixed"


def test_the_noise_test_is_not_rejudged_with_a_shadowing_form():
    """The reference carries the IR's form: a failing noise test stays failing under the deviation."""
    class NoiseTest:
        def rejudge(self, *args):
            raise AssertionError("a shadowing form cannot re-judge the reference")
    entry = {"scene": "ggx_copper_grazing", "backend": "pbrt", "mode": "spectral47", "versions": {},
             "test": {"pass": False}}
    assert status.decide(entry, [known.Deviation(**ENTRY)], ztest=NoiseTest())["status"] == "failed"
