"""The pbrt writer's exports rendered by pbrt-v4 itself, judged by closed forms (tests/pbrt_checks.py):
the absolute radiance of a white Lambertian plate under a uniform D65 environment and under a D65
area light, and a GGX copper plate under an area light (the GGX probe with pbrt's height-correlated
shadowing). Each test shows its power: what it resolves is well below the 2 % of the writer's
planted light error (pbrt_writer.TEST_HOOK), and that planted error fails it. Skipped without pbrt,
saying so. pbrt gives one image per seed on one build, but CI builds it for each machine: each test's
judgement takes a share of the suite's false-alarm budget (tests/conftest.py RANDOM_JUDGEMENTS) and is
made at RANDOM_TEST_ALPHA, its power asserted at that alpha."""
import copy

import pytest

import pbrt_checks
from conftest import RANDOM_TEST_ALPHA
from spectral_bench.batch.verdict import stats

PLANTED = 1.02  # the writer's planted error: every light 2 % brighter
pytestmark = [pytest.mark.slow, pytest.mark.skipif(pbrt_checks.PBRT is None, reason=pbrt_checks.MISSING)]


@pytest.fixture(autouse=True)
def _suite_share(monkeypatch):
    """The probes' and region test's family alpha (stats.ALPHA, read when they are called)."""
    monkeypatch.setattr(stats, "ALPHA", RANDOM_TEST_ALPHA)


def test_white_plate_under_a_d65_environment_has_the_lambert_probes_radiance(tmp_path):
    """rho L(l) everywhere on the plate (nothing above it), judged by the Lambert probe on the
    render's own noise. D65 is not flat, so pbrt's division by its photometric value (and its film's
    CIE_Y_integral) shows unless the writer's scale undoes it; the planted 2 % fails."""
    ok = pbrt_checks.env_plate(tmp_path / "ok")
    assert ok["records"] and all(r["pass"] for r in ok["records"]), ok["records"]
    threshold = stats.sidak_threshold(RANDOM_TEST_ALPHA, 3)  # one patch: its three channels
    assert [r["stat"]["threshold"] for r in ok["records"]] == [pytest.approx(threshold)]
    # power: the relative shift of the patch's mean the test resolves at that threshold is far below 2 %
    assert stats.z_critical(threshold) * ok["rel_se"] < (PLANTED - 1) / 3, ok["rel_se"]
    planted = pbrt_checks.env_plate(tmp_path / "planted", planted=PLANTED)
    assert not all(r["pass"] for r in planted["records"]), planted["records"]


def test_white_plate_under_a_d65_area_light_has_lamberts_irradiance(tmp_path):
    """Every plate pixel is rho / pi E, E from Lambert's polygon formula over the pixel's footprint,
    judged per channel on the pixels' own spread; the planted 2 % fails."""
    ok = pbrt_checks.area_plate(tmp_path / "ok")
    assert ok["pixels"] > 500 and ok["variation"] > 1.5  # the irradiance varies over the judged plate
    assert ok["result"]["pass"], ok["result"]
    assert ok["resolved"] < (PLANTED - 1) / 3, ok["resolved"]
    assert not pbrt_checks.area_plate(tmp_path / "planted", planted=PLANTED)["result"]["pass"]


def test_ggx_copper_plate_under_an_area_light_matches_the_ggx_probe_with_pbrts_shadowing(golden, tmp_path):
    """ggx_copper_50_isolated at 64 x 64, 128 spp: the GGX probe's quadrature of the microfacet BRDF
    with the IR's eta, k and alpha and pbrt's height-correlated shadowing-masking judges the plate
    (blocks and luminance scale) on the render's own noise: alpha is alpha (remaproughness false),
    the light's radiance absolute. The planted 2 % fails the scale test."""
    sc = copy.deepcopy(golden["ggx_copper_50_isolated"])
    sc["render"].update(width=64, height=64, spp=128)
    form = "height-correlated"
    records = pbrt_checks.ggx_plate(sc, tmp_path / "ok", forms=(form,))[0][form]
    assert len(records) == 2 and all(r["pass"] for r in records), records
    scale = next(r for r in records if r["name"].endswith("luminance scale"))
    resolved = stats.z_critical(scale["stat"]["threshold"]) * scale["stat"]["se"][0]
    assert resolved < (PLANTED - 1) / 2, resolved
    planted = pbrt_checks.ggx_plate(sc, tmp_path / "planted", planted=PLANTED, forms=(form,))[0][form]
    assert not next(r for r in planted if r["name"].endswith("luminance scale"))["pass"], planted
