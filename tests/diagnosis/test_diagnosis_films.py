"""Material models of the diagnosis (issue 34) for what the probes judge by closed form: the lone
fluorescent sphere rendered without its re-radiation, the smooth filmed sphere rendered with
another film thickness, and the prism's glass rendered with one IOR (no dispersion). Real renders (Mitsuba through the scene format's own colour, the CMF film,
so that the film's colour route is not what the probes see), planted in the scene rendered and
judged as the scene declared."""
import copy

import pytest

from conftest import GOLDEN

PASSES = 4


def _diagnosed(name, change, tmp_path, spp, size=None, film="cmf"):
    from spectral_bench.batch import backends, exr
    from spectral_bench.batch.verdict import diagnosis, probes
    from spectral_bench.exporters import ir, ir_json
    scene = ir_json.load(GOLDEN / f"{name}.json")
    if size:
        scene["render"]["width"], scene["render"]["height"] = size
    scene["render"]["spp"] = spp
    rendered = copy.deepcopy(scene)
    change(rendered)
    rendered["needs"] = ir.derived_needs({k: v for k, v in rendered.items() if k != "needs"})
    b = backends.get("mitsuba", film=film) if film else backends.get("mitsuba")
    path = b.export(rendered, tmp_path / "export")
    b.render(path, b.mode_for(rendered)[0], spp, tmp_path / "render.exr", passes=PASSES, seed=5)
    names, img, se = exr.read_image_and_stderr(tmp_path / "render.exr")
    records = probes.evaluate(scene, names, img, stderr=se, passes=PASSES)
    entry = {"scene": name, "backend": "mitsuba", "mode": "llvm_ad_spectral", "passes": PASSES, "probes": records}
    ev = diagnosis.Evidence(entry, scene, names, img, se, PASSES)
    return records, diagnosis.diagnose(ev)


def test_fluorescence_dropped_is_named(tmp_path):
    def drop(sc):
        del sc["objects"][0]["bsdf"]["fluorescence"]
    records, found = _diagnosed("fluorescent_sphere_lone", drop, tmp_path, 64)
    lone = next(r for r in records if r["name"].startswith("lone fluorescent"))
    assert lone["pass"] is False and lone["z"] > 10, lone  # the probe sees it (its power)
    assert found["likely"] == "fluorescence dropped", found["models"][:3]
    assert found["models"][0]["fully_explains"] is True


@pytest.mark.slow
def test_film_thickness_fitted(tmp_path):
    declared = {}

    def thicker(sc):
        film = next(o for o in sc["objects"] if (o.get("bsdf") or {}).get("thin_film"))["bsdf"]["thin_film"]
        declared["nm"] = film["thickness"]
        film["thickness"] = film["thickness"] * 1.05
    # 64x64 at 256 spp: the samples on the sphere of 128x128 at 64 spp (the thickness's standard
    # error 0.031-0.039 nm against 0.029) at 2.5 times less fitting (each trial thickness traces
    # the expected image's sub-rays per pixel); issue 45
    records, found = _diagnosed("iridescent_sphere_smooth", thicker, tmp_path, 256, size=(64, 64))
    airy = next(r for r in records if r["name"].startswith("airy film"))
    assert airy["pass"] is False, airy  # the probe sees a 5 % thicker film (its power)
    best = found["models"][0]
    assert best["model"] == "thin film thickness", found["models"][:3]
    value, se = best["params"]["thickness nm"]
    # measured (seed 5, 2026-12-02, 128x128 at 64 spp): 577.560 +- 0.029 nm for the 577.5 planted, 2.1 se and 1e-4 of the
    # film off: whether the Airy probe or Mitsuba's film plugin carries that much is not established
    # (issue 34's note); 3 se here, and the planted 27.5 nm change recovered to within 0.5 % of itself.
    # At 64x64, 256 spp (2026-12-04), seeds 5, 1, 2, 3: -0.27, +1.02, -1.63, -0.50 se, at most 0.45 of
    # the 0.5 % (0.43 at 128x128); the Airy probe fails at z 81-102 (80)
    assert abs(value - declared["nm"] * 1.05) <= 3 * se, (value, se, declared)
    assert abs(value - declared["nm"] * 1.05) < 0.005 * declared["nm"] * 0.05, (value, declared)
    assert not any(m["model"] == "thin film missing" and m["fully_explains"] for m in found["models"])


@pytest.mark.slow
def test_dispersion_missing_is_named(tmp_path):
    """The prism's N-BK7 rendered as a plain dielectric of its n at the d line (587.6 nm): the fan
    collapses to one spot; the positions probe fails (its power: the channels' centroids tens of
    standard errors apart) and "dispersion missing" is ranked first, its IOR within two standard
    errors of the one rendered."""
    from spectral_bench.exporters import dispersion
    planted = {}

    def one_ior(sc):
        glass = next(o for o in sc["objects"] if dispersion.is_dispersive((o.get("bsdf") or {}).get("int_ior")))
        planted["n"] = float(dispersion.ior(glass["bsdf"]["int_ior"], [dispersion.FRAUNHOFER_NM["d"]])[0])
        glass["bsdf"]["int_ior"] = planted["n"]
    # light-traced: Mitsuba's own film (the CMF film loses the particle tracer's flux; the
    # centroids the probe measures do not depend on the film's scale)
    records, found = _diagnosed("dispersion_prism", one_ior, tmp_path, 32, size=(128, 64), film=None)
    pos = next(r for r in records if r["name"].startswith("prism band positions"))
    assert pos["pass"] is False and pos["error"] > 10, pos  # error: the largest |z| over the channels
    best = found["models"][0]
    assert best["model"] == "dispersion missing" and found["likely"] == "dispersion missing", found["models"][:3]
    value, se = best["params"]["ior"]
    assert abs(value - planted["n"]) <= 2 * se, (value, se, planted)
