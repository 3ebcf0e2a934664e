"""How render.exr stores a render's mean and standard error (batch/exr.py ``stored_render``): half
floats, the mean rounded stochastically with its rounding variance in the standard error, so that
the noise test judges the stored file as it would judge the float64 mean (issue 21: a run folder of
reasonable size). Judged with the project's own noise test (batch/verdict/compare.py ``z_test``)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from spectral_bench.batch import exr
from spectral_bench.batch.verdict import compare

SHAPE = (64, 64, 3)


def _judge(stored_mean, stored_se, ref, passes=8):
    return compare.z_test(stored_mean.astype(np.float64), ref, 64, own_var_of_mean=stored_se.astype(np.float64) ** 2,
                          own_passes=passes, alpha=0.01)


def _light(value):
    """A black image with a light seen directly (a 16 x 16 patch of ``value``): no variance at all."""
    img = np.zeros(SHAPE)
    img[8:24, 8:24] = value
    return img


@pytest.mark.parametrize("base,frac", [(0.8, 0.3), (3.1, 0.5), (3.3e-4, 0.4), (0.05, 0.35)])
def test_a_noise_free_light_stored_as_half_passes_where_rounding_to_nearest_fails(base, frac):
    """A light seen directly: every pass gives the same value, the standard error is 0. Rounded to
    the nearest half the stored mean is off by ``frac`` of a step that no variance explains (the
    noise test fails); rounded stochastically, with the rounding variance in the standard error,
    it is judged as the exact value would be."""
    value = float(np.float16(base)) + frac * float(exr.half_ulp(base))
    mean, se = _light(value), np.zeros(SHAPE)
    ref = compare.reference_at(mean, np.zeros(SHAPE), 4096, SHAPE, 8)
    assert _judge(mean, se, ref).passed  # the exact value passes (the test itself is sound)
    nearest = _judge(mean.astype(np.float16), se, ref)
    assert not nearest.passed, nearest.as_dict()
    m, s = exr.stored_render(mean, se, seed=11)
    assert m.dtype == np.float16 and s.dtype == np.float16
    assert _judge(m, s, ref).passed


def test_a_real_error_in_a_noise_free_region_is_still_detected():
    """Storage must not hide an error: a 0.5 % brighter noise-free region fails after storage."""
    ref = compare.reference_at(_light(0.8), np.zeros(SHAPE), 4096, SHAPE, 8)
    m, s = exr.stored_render(_light(0.8 * 1.005), np.zeros(SHAPE), seed=3)
    assert not _judge(m, s, ref).passed


def test_the_noise_test_on_noisy_renders_keeps_its_false_alarm_rate():
    """Noisy renders of the exact reference (8 passes' spread, 5 % relative): stored or not, the
    noise test at alpha 0.01 passes 40 of 40 (a stored image may not false-alarm more; 40 draws of
    a test at 1 % fail at all with probability 0.33, so this is not a weak bound but it must not
    fail for every draw either way: both variants are judged on the same draws)."""
    rng = np.random.default_rng(5)
    ref_value = rng.uniform(0.05, 2.0, SHAPE)
    ref = compare.reference_at(ref_value, np.zeros(SHAPE), 4096, SHAPE, 8)
    fails_float = fails_stored = 0
    for k in range(40):
        se = 0.05 * ref_value
        mean = ref_value + rng.normal(0.0, 1.0, SHAPE) * se
        fails_float += not _judge(mean, se, ref).passed
        m, s = exr.stored_render(mean, se, seed=k)
        fails_stored += not _judge(m, s, ref).passed
    assert fails_stored <= fails_float + 1, (fails_float, fails_stored)
    assert fails_stored <= 3


@settings(max_examples=200, deadline=None)
@given(st.floats(-3e4, 3e4, allow_nan=False), st.floats(0.0, 1e3, allow_nan=False), st.integers(0, 2**31))
def test_the_stored_standard_error_covers_the_rounding(x, se, seed):
    """Per pixel: the stored mean is one of the two neighbours of the value on its grid, and the
    stored standard error is at least sqrt(se^2 + (x - lo)(hi - x)) (never less conservative)."""
    mean, stderr = np.full((2, 3), x), np.full((2, 3), se)
    m, s = exr.stored_render(mean, stderr, seed)
    m64, s64 = m.astype(np.float64), s.astype(np.float64)
    if m.dtype == np.float32:  # did not fit: kept as it was
        assert np.all(m64 == np.float32(x))
        return
    err = np.abs(m64 - x)
    step = np.maximum(exr.half_ulp(x), 2.0 ** np.floor(np.log2(se / exr.NOISE_STEPS)) if se > 0 else 0.0)
    assert np.all(err <= step * (1 + 1e-9)), (x, se, m64, step)
    assert np.all(s64 ** 2 >= se ** 2 + err * (step - err) - 1e-12 * (1 + x * x)), (x, se, m64, s64)
    # rounded up to 5 significant bits: at most 1/16 above (and one subnormal step)
    assert np.all(s64 <= (1 + 1 / 16) * np.sqrt(se ** 2 + step ** 2 / 4) * (1 + 1e-3) + 2 ** -24)


def test_what_does_not_fit_stays_float32_and_a_seed_reproduces():
    big = np.array([[7e4, 1.0, 2.0]])
    m, s = exr.stored_render(big, np.ones_like(big), seed=1)
    assert m.dtype == np.float32 and s.dtype == np.float32 and m[0, 0] == np.float32(7e4)
    nan = np.array([[np.nan, 1.0, 2.0]])
    assert exr.stored_render(nan, np.ones_like(nan), seed=1)[0].dtype == np.float32
    m1, _ = exr.stored_render(np.full((4, 4, 3), 0.3), np.full((4, 4, 3), 0.01), seed=9)
    m2, _ = exr.stored_render(np.full((4, 4, 3), 0.3), np.full((4, 4, 3), 0.01), seed=9)
    assert np.array_equal(m1.view(np.uint16), m2.view(np.uint16))
    one_pass, none = exr.stored_render(np.full((2, 2, 3), 0.3), None, seed=1)
    assert one_pass.dtype == np.float32 and none is None  # no standard error to carry the rounding: float32


def test_written_and_read_back_unchanged(tmp_path):
    m, s = exr.stored_render(np.random.default_rng(2).uniform(0, 4, (8, 8, 3)), np.full((8, 8, 3), 0.02), seed=4)
    path = exr.write_image(tmp_path / "r.exr", ["R", "G", "B"], m, {f"stderr.{c}": s[..., i] for i, c in enumerate("RGB")})
    names, img, se = exr.read_image_and_stderr(path)
    assert names == ["R", "G", "B"] and np.array_equal(img, m.astype(np.float32)) and np.array_equal(se, s.astype(np.float32))


def test_the_block_standard_error_map_is_what_z_divides_by():
    """block_stderr.exr holds, per pixel, the standard error of its block's difference: the noise
    test's block difference over it is the block's z (batch/verdict/compare.py z_test)."""
    rng = np.random.default_rng(8)
    ref_value = rng.uniform(0.1, 1.0, SHAPE)
    ref = compare.reference_at(ref_value, np.full(SHAPE, 0.001), 4096, SHAPE, 8)
    se = np.full(SHAPE, 0.02)
    zt = _judge(ref_value + rng.normal(0, 0.02, SHAPE), se, ref)
    assert zt.semap.shape == SHAPE
    # z * its standard error is the block's mean difference, the same for every pixel of the block
    d = zt.zmap * zt.semap
    b = zt.block
    blk = d[:b, :b, 0]
    assert np.allclose(blk, blk[0, 0]) and np.isclose(blk[0, 0], zt.diff[0, 0, 0])
    assert np.isclose(zt.semap[0, 0, 0], np.sqrt(zt.var[0, 0, 0]))
