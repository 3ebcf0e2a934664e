"""The comparison's arithmetic and the calibration of its noise test, on synthetic images
whose statistics are known exactly."""
import numpy as np
import pytest

from spectral_bench.batch.verdict import compare, flip_isolated
from spectral_bench.batch import exr


def test_metrics_on_known_values():
    ref = np.full((2, 2, 3), 1.0)
    test = ref.copy()
    test[0, 0, 0] = 2.0
    m = compare.metrics(test, ref)
    assert m["rmse"] == pytest.approx(np.sqrt(1 / 12))
    assert m["relmse"] == pytest.approx((1 / 1.01) / 12)
    assert m["mape"] == pytest.approx((1 / 1.01) / 12)


def test_downsample_of_box_filtered_pixels_is_exact():
    img = np.arange(4 * 4 * 3, dtype=float).reshape(4, 4, 3)
    d = compare.downsample(img, 2)
    assert d.shape == (2, 2, 3)
    assert d[0, 0, 0] == pytest.approx(np.mean(img[:2, :2, 0]))


def test_reference_at_rejects_non_integer_factors():
    with pytest.raises(ValueError, match="integer"):
        compare.reference_at(np.ones((10, 10, 3)), np.ones((10, 10, 3)), 16, (3, 3, 3))


def _synthetic(rng, f=2, spp=16, shape=(32, 32), bias=0.0):
    """A reference of mean mu (with edges), and a render drawn with the per-sample variance."""
    H, W = shape[0] * f, shape[1] * f
    yy, xx = np.mgrid[0:H, 0:W]
    mu = 0.5 + 0.4 * (xx > W // 2)[..., None] * np.array([1.0, 0.5, 0.2]) + 0.1 * np.sin(yy / 5.0)[..., None]
    sigma2 = 0.3 * mu  # per-sample variance of each small pixel
    n_ref = 4096
    ref_stderr = np.sqrt(sigma2 / n_ref)
    ref_mean = mu + rng.normal(size=mu.shape) * ref_stderr
    # a big pixel sampled s times uniformly: variance = mean(sigma2) + spread of mu inside it
    big_mu = compare.downsample(mu, f)
    big_var = compare.downsample(sigma2, f) + compare.downsample(mu**2, f) - big_mu**2
    test = big_mu * (1 + bias) + rng.normal(size=big_mu.shape) * np.sqrt(big_var / spp)
    return test, ref_mean, ref_stderr, n_ref, spp


def test_noise_test_passes_unbiased_renders_at_its_nominal_rate():
    rng = np.random.default_rng(1)
    failures = 0
    for _ in range(40):
        test, rm, rs, n, spp = _synthetic(rng)
        ref = compare.reference_at(rm, rs, n, test.shape)
        failures += not compare.z_test(test, ref, spp, alpha=0.05, block=4).passed
    # each trial fails with probability <= 5 %: P(more than 8 of 40) < 0.001
    assert failures <= 8, failures


def _passes(rng, mu, var, spp, passes):
    """A render in ``passes`` independent passes: mean and per-pixel standard error."""
    per = [mu + rng.normal(size=mu.shape) * np.sqrt(var / (spp / passes)) for _ in range(passes)]
    stack = np.stack(per)
    return stack.mean(0), stack.std(0, ddof=1) / np.sqrt(passes)


def test_own_noise_from_two_passes_is_calibrated_with_student_t():
    """Two passes give each pixel a variance estimate of one degree of freedom: pooled over a
    small block, a normal z would false-alarm far above alpha; Student's t with Satterthwaite's
    degrees of freedom keeps the nominal rate."""
    rng = np.random.default_rng(5)
    failures, normal_failures = 0, 0
    for _ in range(60):
        test_mu, rm, rs, n, spp = _synthetic(rng, shape=(16, 16))
        big_var = compare.downsample(0.3 * (0.5 + 0 * rm), 2)  # any positive per-sample variance
        mean, se = _passes(rng, compare.downsample(rm, 2), big_var, spp, 2)
        ref = compare.reference_at(rm, rs, n, mean.shape)
        zt = compare.z_test(mean, ref, spp, own_var_of_mean=se**2, own_passes=2, alpha=0.05, block=2)
        failures += not zt.passed
        z = zt.diff / np.sqrt(zt.var)
        normal_failures += float(np.max(np.abs(z))) > 3.4  # ~Sidak at 0.05 over 192 normal tests
    assert failures <= 9, failures          # nominal 5 % of 60: P(> 9) < 0.01
    assert normal_failures >= 15, normal_failures  # the normal approximation would be badly off


def test_every_pixel_is_in_a_block():
    for n, b in ((64, 16), (63, 16), (17, 16), (15, 16), (100, 32)):
        edges = compare.block_edges(n, b)
        assert edges[0] == 0 and edges[-1] == n
        sizes = np.diff(edges)
        assert sizes.min() >= min(b, n) and sizes.max() <= max(2 * b - 1, n)


def test_a_bias_in_the_last_partial_block_is_detected():
    """The old test cut the image to whole blocks: a wrong strip at the edge went unseen."""
    rng = np.random.default_rng(6)
    test, rm, rs, n, spp = _synthetic(rng, spp=256, shape=(40, 40))
    test[:, -6:] *= 1.2  # 6 columns past the last whole 16-pixel block
    ref = compare.reference_at(rm, rs, n, test.shape)
    assert not compare.z_test(test, ref, spp, block=16).passed


def test_noise_test_fails_a_two_percent_bias():
    rng = np.random.default_rng(2)
    test, rm, rs, n, spp = _synthetic(rng, spp=256, bias=0.02)
    ref = compare.reference_at(rm, rs, n, test.shape)
    zt = compare.z_test(test, ref, spp, block=4)
    assert not zt.passed and zt.p_min < zt.threshold
    # re-judged as if the reference were 2 % brighter (a recorded deviation), it passes
    assert zt.rejudge(1.02, 0.002)
    assert not zt.rejudge(1.0)


def test_noise_test_fails_light_where_the_reference_is_black():
    zeros = np.zeros((16, 16, 3))
    test = zeros.copy()
    test[3, 3] = 0.5
    ref = compare.ReferenceAt(zeros, zeros, zeros, 7.0)
    assert not compare.z_test(test, ref, 16).passed


def test_noise_test_fails_nan():
    rng = np.random.default_rng(3)
    test, rm, rs, n, spp = _synthetic(rng)
    ref = compare.reference_at(rm, rs, n, test.shape)
    assert compare.z_test(test, ref, spp, block=4).passed
    test[0, 0, 0] = np.nan
    assert not compare.z_test(test, ref, spp, block=4).passed


def test_flip_runs_isolated_and_bad_input_cannot_exit_the_caller(tmp_path):
    rng = np.random.default_rng(4)
    a = rng.random((24, 24, 3)).astype(np.float32)
    exr.write(tmp_path / "a.exr", a)
    exr.write(tmp_path / "b.exr", a)
    exr.write(tmp_path / "c.exr", a * 2)
    same, err = flip_isolated.hdr_flip(tmp_path / "a.exr", tmp_path / "b.exr", tmp_path / "f.exr")
    assert err is None and same == pytest.approx(0.0, abs=1e-6)
    diff, err = flip_isolated.hdr_flip(tmp_path / "a.exr", tmp_path / "c.exr", tmp_path / "f.exr")
    assert err is None and diff > 0.01
    exr.write(tmp_path / "nan.exr", np.full((24, 24, 3), np.nan, dtype=np.float32))
    value, err = flip_isolated.hdr_flip(tmp_path / "a.exr", tmp_path / "nan.exr", tmp_path / "f.exr")
    assert value is None and "NaN" in err


def _lit_on_black(rng, shape, box, highlight=0.0):
    """A reference and a noisy test: 0 everywhere but inside ``box`` (rows, columns), where a
    smooth gradient with texture (and a small highlight ``highlight`` times brighter) lies."""
    ref = np.zeros(shape + (3,), np.float32)
    rows, cols = box
    h, w = rows.stop - rows.start, cols.stop - cols.start
    y, x = np.mgrid[0:h, 0:w]
    base = (0.2 + 0.5 * x / w)[..., None] * np.array([1.0, 0.6, 0.3]) * (1 + 0.2 * np.sin(y / 3.0))[..., None]
    if highlight:
        base[h // 2 - 2:h // 2 + 2, w // 2 - 2:w // 2 + 2] *= highlight
    ref[rows, cols] = base
    test = ref * (1 + 0.1 * rng.standard_normal(ref.shape)).astype(np.float32)
    return flip_isolated.prepare(ref), flip_isolated.prepare(test)


@pytest.mark.slow  # over ~1 s of CPU each (flip_evaluator, its threads; benchmarks/TESTS.md)
@pytest.mark.parametrize("shape, box, highlight", [
    ((160, 200), (slice(60, 100), slice(70, 130)), 1e5),  # a bright highlight: many exposures (as ggx_copper_grazing)
    ((160, 200), (slice(0, 40), slice(150, 200)), 0.0),  # touches two edges of the image
    ((120, 120), (slice(50, 51), slice(30, 31)), 3.0),  # one lit pixel
])
def test_flip_on_the_lit_box_is_flip_on_the_whole_image(shape, box, highlight):
    """hdr_flip_map evaluates HDR-FLIP on the box around what is not black (issue 45, item 1):
    the map and the mean are flip_evaluator's on the whole image, bit for bit."""
    import flip_evaluator
    ref, test = _lit_on_black(np.random.default_rng(7), shape, box, highlight)
    whole, mean, params = flip_evaluator.evaluate(ref.copy(), test.copy(), "HDR", inputsRGB=False, applyMagma=False,
                                                  computeMeanError=True)
    whole = np.asarray(whole, np.float32).reshape(shape + (-1,))[..., 0]
    got = flip_isolated.content_box(ref, test, flip_isolated.filter_radius(params["ppd"]))
    area = (got[0].stop - got[0].start) * (got[1].stop - got[1].start)
    assert area <= flip_isolated.CROP_MAX * shape[0] * shape[1]  # the box is what is evaluated, not the whole image
    assert np.count_nonzero(whole) > 0 and not np.any(whole[~_inside(shape, got)])  # FLIP's own map is 0 off the box
    fmap, value = flip_isolated.hdr_flip_map(flip_evaluator, ref, test)
    assert np.array_equal(fmap, whole)
    assert value == float(mean)


def _inside(shape, box):
    mask = np.zeros(shape, bool)
    mask[box] = True
    return mask


def test_flip_on_images_with_little_black_is_evaluated_whole():
    """No box to gain (an image lit almost everywhere): FLIP on the whole image, as it is."""
    import flip_evaluator
    ref, test = _lit_on_black(np.random.default_rng(8), (64, 64), (slice(2, 62), slice(1, 64)))
    whole, mean, _ = flip_evaluator.evaluate(ref.copy(), test.copy(), "HDR", inputsRGB=False, applyMagma=False,
                                             computeMeanError=True)
    fmap, value = flip_isolated.hdr_flip_map(flip_evaluator, ref, test)
    assert np.array_equal(fmap, np.asarray(whole, np.float32).reshape(64, 64, -1)[..., 0]) and value == float(mean)


def test_block_size_pools_enough_samples_for_heavy_tails():
    assert compare.block_size(64, (512, 512)) == 32  # 32^2 * 64 = 65536
    assert compare.block_size(256, (64, 64)) == 16
    assert compare.block_size(1, (8, 8)) == 8  # never larger than the image
    assert compare.block_size(1 << 20, (64, 64)) == 1
