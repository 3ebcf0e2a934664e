"""The diagnosis's fitting (batch/verdict/diagnosis/) on synthetic images, plain numpy: a smooth
reference, a render drawn from it with Gaussian noise of a known standard error (the render's own,
from its passes), one error planted. Each planted model must be ranked first with its parameter
within two standard errors, a render with an error outside the catalogue must get "no model
explains it", and noise alone gives no model that improves on none by much. The real renders are
tests/diagnosis/test_diagnosis.py's."""
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
from spectral_bench.batch.verdict import compare, diagnosis  # noqa: E402

H = W = 64
SPP = 64
SE = 0.004  # the render's per-pixel standard error


def reference(stokes=False, seed=1):
    """A smooth image with structure in x and y (a tilted gradient, a bright blob), R, G, B and,
    with ``stokes``, S0..S3 per colour."""
    y, x = np.mgrid[0:H, 0:W] / H
    base = 0.3 + 0.4 * x + 0.2 * y ** 2 + 0.8 * np.exp(-((x - 0.3) ** 2 + (y - 0.6) ** 2) / 0.02)
    rgb = np.stack([base, 0.8 * base + 0.1 * x, 0.6 * base + 0.2 * y], axis=-1)
    names = ["R", "G", "B"]
    if not stokes:
        return names, rgb
    s1 = 0.3 * rgb * np.cos(4 * x)[..., None]
    s2 = 0.3 * rgb * np.sin(3 * y + 1)[..., None]
    s3 = 0.05 * rgb * (x - 0.5)[..., None]
    names += [f"S{k}.{c}" for k in range(4) for c in "RGB"]
    return names, np.concatenate([rgb, rgb, s1, s2, s3], axis=-1)


PASSES = 16


def evidence(render_mean, ref, names, noise_scale=1.0, seed=0, per_pass=None):
    """The Evidence of a render (``render_mean`` plus noise noise_scale times the reported SE)
    judged against ``ref`` as the verdict judges it (compare.z_test). ``per_pass``: the render is
    instead PASSES passes of ``ref`` plus noise, each put through ``per_pass`` (as a renderer that
    encodes what it writes), their mean and its standard error from their spread."""
    rng = np.random.default_rng(seed)
    ref_se = SE / 8  # a reference of 64 times the samples
    at = compare.ReferenceAt(ref + rng.normal(0, ref_se, ref.shape), np.full(ref.shape, ref_se ** 2),
                             np.full(ref.shape, ref_se ** 2 * SPP * 64), 7.0)
    if per_pass is None:
        image = render_mean + rng.normal(0, SE * noise_scale, ref.shape)
        stderr = np.full(ref.shape, SE)
    else:
        passes = per_pass(ref + rng.normal(0, SE * np.sqrt(PASSES), (PASSES,) + ref.shape))
        image, stderr = passes.mean(axis=0), passes.std(axis=0, ddof=1) / np.sqrt(PASSES)
    zt = compare.z_test(image, at, SPP, own_var_of_mean=stderr ** 2, own_passes=PASSES, alpha=0.01, block=4)
    entry = {"scene": "synthetic", "backend": "test", "mode": "rgb", "passes": PASSES,
             "test": {"pass": bool(zt.passed)}, "probes": []}
    scene = {"camera": {}, "objects": [], "render": {"spp": SPP}}
    return diagnosis.Evidence(entry, scene, names, image, stderr, PASSES, at, zt, (names, image, stderr)), zt


def first(found):
    assert found["models"], found
    return found["models"][0]


def within_two_se(record, name, planted):
    value, se = record["params"][name]
    assert abs(value - planted) <= 2 * se, (record, planted)


def test_uniform_scale_ranked_first_within_two_se():
    names, ref = reference()
    ev, zt = evidence(ref * 1.01, ref, names)
    assert not zt.passed
    found = diagnosis.diagnose(ev)
    top = first(found)
    assert top["model"] == "uniform scale" and top["fully_explains"], found["models"]
    within_two_se(top, "scale", 1.01)
    assert found["likely"] == "uniform scale" and found["text"].startswith("likely: uniform scale 1.0")
    assert "scale = 1.0" in found["known_deviation"] and 'checks = ["noise test"]' in found["known_deviation"]


@pytest.mark.parametrize("plant, model", [
    (lambda m: np.flip(m, axis=0), "flipped vertically"),
    (lambda m: np.flip(m, axis=1), "flipped horizontally"),
    (lambda m: np.swapaxes(m, 0, 1), "transposed"),
    (lambda m: m[..., ::-1], "channel order BGR"),
])
def test_discrete_image_models(plant, model):
    names, ref = reference()
    ev, _ = evidence(plant(ref), ref, names)
    found = diagnosis.diagnose(ev)
    assert first(found)["model"] == model and found["likely"] == model, found["models"][:2]


def test_srgb_applied_per_pass_beats_gamma():
    """The curve applied to each pass (Jensen's gap included in the model's prediction), ranked
    before the gamma that approximates it with a parameter."""
    from spectral_bench.batch.verdict.diagnosis import image
    names, ref = reference()
    ev, _ = evidence(None, ref, names, per_pass=image.srgb_encode)
    found = diagnosis.diagnose(ev)
    assert found["likely"] == "sRGB transfer applied", found["models"][:3]


@pytest.mark.parametrize("level", [0.9, 0.6])
def test_clamp_per_pass_fitted(level):
    """Each pass cut at a ceiling that the blob's peak (1.5) crosses, with passes noisy enough to
    straddle it (per-pass sd 0.016): the clamp is ranked first, its value within two standard
    errors (the model's mean of a cut Gaussian; the plain min(m, c) left such a clamp unexplained)."""
    names, ref = reference()
    ev, zt = evidence(None, ref, names, per_pass=lambda p: np.minimum(p, level))
    assert not zt.passed
    found = diagnosis.diagnose(ev)
    top = first(found)
    assert top["model"] == "clamped highlights" and found["likely"] == top["model"], found["models"][:2]
    within_two_se(top, "clamp", level)


def test_subpixel_shift_fitted():
    from scipy import ndimage
    names, ref = reference()
    ev, _ = evidence(ndimage.shift(ref, (0.3, -0.5, 0), order=1, mode="nearest"), ref, names)
    top = first(diagnosis.diagnose(ev))
    assert top["model"] == "shift"
    within_two_se(top, "dx px", -0.5)
    within_two_se(top, "dy px", 0.3)


@pytest.mark.slow
def test_stokes_frame_rotation_fitted():
    names, ref = reference(stokes=True)
    rotated = ref.copy()
    c, s = np.cos(np.radians(60)), np.sin(np.radians(60))
    for colour in range(3):
        i1, i2 = names.index(f"S1.{'RGB'[colour]}"), names.index(f"S2.{'RGB'[colour]}")
        rotated[..., i1], rotated[..., i2] = c * ref[..., i1] + s * ref[..., i2], -s * ref[..., i1] + c * ref[..., i2]
    found = diagnosis.diagnose(evidence(rotated, ref, names)[0])
    top = first(found)
    assert top["model"] == "Stokes frame rotated" and found["likely"] == top["model"], found["models"][:2]
    within_two_se(top, "angle deg", 30.0)


@pytest.mark.slow
def test_s3_sign_and_depolarised():
    names, ref = reference(stokes=True)
    for scale, model in (((1, 1, -1), "S3 sign"), ((0, 0, 0), "depolarised")):
        planted = ref.copy()
        for k in (1, 2, 3):
            for c in "RGB":
                planted[..., names.index(f"S{k}.{c}")] *= scale[k - 1]
        assert diagnosis.diagnose(evidence(planted, ref, names)[0])["likely"] == model


def test_misreported_noise():
    names, ref = reference()
    ev, zt = evidence(ref, ref, names, noise_scale=3.0)
    assert not zt.passed
    found = diagnosis.diagnose(ev)
    top = first(found)
    assert top["model"] == "standard error misreported" and found["likely"] == top["model"], found["models"][:2]
    within_two_se(top, "factor", 3.0)


def one_pass_evidence(noise_scale, seed=0):
    """A render of one pass judged, as the verdict judges its reference's own backend, on the noise
    the reference predicts for the declared SPP (no stderr of its own), ``noise_scale`` times that
    noise: a renderer that took SPP / noise_scale^2 samples."""
    names, ref = reference()
    rng = np.random.default_rng(seed)
    ref_se = SE / 8
    at = compare.ReferenceAt(ref + rng.normal(0, ref_se, ref.shape), np.full(ref.shape, ref_se ** 2),
                             np.full(ref.shape, SE ** 2 * SPP), 7.0)
    image = ref + rng.normal(0, SE * noise_scale, ref.shape)
    zt = compare.z_test(image, at, SPP, alpha=0.01, block=4)
    entry = {"scene": "synthetic", "backend": "test", "mode": "rgb", "passes": 1, "spp": SPP,
             "test": {"pass": bool(zt.passed)}, "probes": []}
    scene = {"camera": {}, "objects": [], "render": {"spp": SPP}}
    return diagnosis.Evidence(entry, scene, names, image, None, 1, at, zt, (names, image, None)), zt


def test_too_few_samples_names_the_effective_count():
    """A quarter of the declared samples (noise twice the prediction): ranked first, the effective
    spp within two standard errors of SPP / 4; "standard error misreported" does not apply (the
    render reported no standard error)."""
    ev, zt = one_pass_evidence(2.0)
    assert zt.noise == "reference" and not zt.passed
    found = diagnosis.diagnose(ev)
    top = first(found)
    assert top["model"] == "too few samples" and found["likely"] == top["model"], found["models"][:2]
    within_two_se(top, "effective spp", SPP / 4)
    assert "standard error misreported" not in [m["model"] for m in found["models"]]


def test_too_few_samples_not_fitted_on_own_noise():
    """With its own noise measured, a noisier render is judged on it: the sample-count model does
    not apply, the misreported standard error does."""
    names, ref = reference()
    ev, zt = evidence(ref, ref, names, noise_scale=3.0)
    found = diagnosis.diagnose(ev)
    assert "too few samples" not in [m["model"] for m in found["models"]]


def test_checkerboard_stain_explained_by_no_model():
    names, ref = reference()
    yy, xx = np.mgrid[0:H, 0:W]
    board = ((yy // 4 + xx // 4) % 2 == 0) & (abs(yy - H / 2) < H / 4) & (abs(xx - W / 2) < W / 4)
    ev, zt = evidence(ref + 0.05 * board[..., None], ref, names)
    assert not zt.passed
    found = diagnosis.diagnose(ev)
    assert found["likely"] is None and found["text"].startswith("no model explains it"), found["models"][:2]


def test_a_model_that_breaks_is_recorded_not_raised():
    names, ref = reference()
    ev, _ = evidence(ref * 1.01, ref, names)
    boom = diagnosis.Model("boom", "test", (), "reference", "always fails", lambda ev: 1 / 0)
    found = diagnosis.diagnose(ev, [boom, *diagnosis.registry()])
    assert found["errors"] == [{"model": "boom", "error": "ZeroDivisionError: division by zero"}]
    assert found["likely"] == "uniform scale"


def test_illuminant_normalisation_beats_a_free_scale():
    """A scene lit by a flat spectrum of 2: a renderer normalising it (to Y = 1, at 560 nm or to
    its peak: all halve it) is named, with no parameter, before the uniform scale that fits as
    well with one; its ready entry carries the factor."""
    names, ref = reference()
    ev, _ = evidence(ref * 0.5, ref, names)
    ev.scene["environment"] = {"radiance": {"type": "constant", "value": 2.0}}
    found = diagnosis.diagnose(ev)
    assert found["likely"] == "illuminant normalised", found["models"][:3]
    assert "scale = 0.5" in found["known_deviation"]
    within_two_se(first(found), "factor", 0.5)


def test_known_deviation_entry_is_valid_toml_for_any_name():
    """The printed entry quotes anyone's text (scene, backend, mode): it parses back to the same
    values, however hostile (quotes, backslashes, newlines, DEL, emoji, a lone surrogate)."""
    import tomllib
    names, ref = reference()
    ev, _ = evidence(ref * 1.01, ref, names)
    hostile = 'a"b\\c\nd\x7fe\U0001F600f\ud800g'
    ev.entry.update(scene=hostile, backend=hostile, mode=hostile)
    found = diagnosis.diagnose(ev)
    (dev,) = tomllib.loads(found["known_deviation"])["deviation"]
    assert dev["backend"] == hostile.replace("\ud800", "\ufffd") and dev["scenes"] == [dev["backend"]]
    assert dev["checks"] == ["noise test"] and abs(dev["scale"] - 1.01) < 0.002
