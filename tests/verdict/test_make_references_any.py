"""References from any renderer (issue 19, deliverable 5): ``batch/make_references.py -r NAME``
renders a reference with any backend, built-in or declared in TOML; ``--replace`` judges the new
reference against the old on both noises, prints the verdict and both provenances, keeps the old
one in <out>/history/ and refuses a replacement that differs beyond noise unless ``--accept``.

Real renders throughout: the example renderer of examples/your_renderer/ (a stand-alone script run
as a command), real EXR files, the real command lines in child processes."""
import hashlib
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, metrics, run_batch
from spectral_bench.batch.verdict import references

TOY = ROOT / "examples" / "your_renderer" / "toy.toml"
BRIGHTER = ROOT / "examples" / "your_renderer" / "toy_brighter.toml"
SCENE = "ggx_copper_50"
# 512x512 scenes at 128x128; one 128-pixel block pools the whole image, so that the block test of new
# against old can see the planted 1 % (it would refuse +-0.4 % here: measured, printed by the tool)
SMALL = ["-s", SCENE, "--scale", "0.25", "--spp", "128", "--passes", "4", "--block", "128"]


def maker(*args, timeout=600):
    return subprocess.run([sys.executable, str(ROOT / "batch" / "make_references.py"), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)


def sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def history(out):
    return sorted((out / "history" / SCENE).iterdir()) if (out / "history" / SCENE).is_dir() else []


# -- usage errors: exit 2 naming the option --------------------------------------------------------
@pytest.mark.parametrize("args, named", [
    (["-r", "nosuch"], "-r nosuch: unknown backend or declared renderer"),
    (["-r", "spectral"], "-r spectral: a group"),
    (["--renderers", TOY, "-e", "nosuch=/bin/true", "-r", "toy"], "-e nosuch=/bin/true: 'nosuch' is no backend"),
    (["--renderers", TOY, "-e", "mitsuba=/bin/true", "-r", "toy"], "-e mitsuba=/bin/true: the references are rendered by -r toy"),
    (["--renderers", TOY, "-r", "toy", "--variant", "scalar_rgb"], "--variant scalar_rgb: a Mitsuba variant"),
    (["--accept"], "--accept: only with --replace"),
    (["--scale", "0"], "argument --scale: '0'"),
    (["-r", "toy"], "-r toy: unknown backend or declared renderer"),  # declared nowhere
])
def test_bad_options_are_usage_errors_naming_the_option(tmp_path, monkeypatch, capsys, args, named):
    """batch/make_references.py's main() in this process (a child costs a Python start each; the
    real children of a usage error: the two tests below)."""
    from spectral_bench.batch import make_references
    monkeypatch.chdir(ROOT)
    nothing = tmp_path / "no_scene.json"  # were an option let through, nothing would render in this process
    try:
        code = make_references.main([*map(str, args), "-i", str(nothing), "--out", str(tmp_path / "refs")])
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    proc = subprocess.CompletedProcess(args, code, *capsys.readouterr())
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert named in proc.stderr
    assert not (tmp_path / "refs").exists() or not any((tmp_path / "refs").glob("*.exr"))


def test_a_bad_declaration_is_a_usage_error_naming_file_renderer_and_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(TOY.read_text().replace('reads = "mitsuba"\nwrites = "rgb"', 'reads = "mitsuba"\nwrites = "rgb"\ncolour = 1', 1))
    proc = maker("--renderers", bad, "-r", "toy", "-s", SCENE, "--out", tmp_path / "refs", timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"--renderers: {bad}: renderer 'toy': unknown key 'colour'" in proc.stderr


def test_an_executable_that_is_not_there_is_named(tmp_path):
    proc = maker("--renderers", TOY, "-r", "toy", "-e", f"toy={tmp_path / 'missing'}", "-s", SCENE,
                 "--out", tmp_path / "refs", timeout=120)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "-e toy: cannot render here" in proc.stderr and str(tmp_path / "missing") in proc.stderr


# -- history and the replacement's verdict, on real files without rendering ----------------------------
def _noisy(rng, level, shape=(64, 64), rel=0.05):
    """A reference-like image: a smooth level with per-pixel noise of relative standard error ``rel``."""
    truth = level * (1.0 + 0.3 * np.linspace(0, 1, shape[0] * shape[1]).reshape(shape + (1,))) * np.ones(shape + (3,))
    stderr = rel * truth
    return truth + rng.standard_normal(truth.shape) * stderr, stderr


def test_a_replaced_reference_is_kept_in_history_and_never_read_as_current(tmp_path, golden):
    scene = golden[SCENE]
    out = tmp_path / "refs"
    rng = np.random.default_rng(1)
    old_mean, old_se = _noisy(rng, 0.5)
    references.save(scene, ["R", "G", "B"], old_mean, old_se, {"backend": "toy", "mode": "rgb", "spp": 64, "passes": 4}, out)
    old_sha = (sha(out / f"{SCENE}.exr"), sha(out / f"{SCENE}.json"))
    new_mean, new_se = _noisy(rng, 0.5)
    path, kept = references.replace(scene, ["R", "G", "B"], new_mean, new_se,
                                    {"backend": "mitsuba", "mode": "m", "spp": 64, "passes": 4}, out,
                                    {"why": "test"}, "20260101T000000Z")
    assert kept == out / "history" / SCENE / "20260101T000000Z-toy"
    assert (sha(kept / f"{SCENE}.exr"), sha(kept / f"{SCENE}.json")) == old_sha
    assert json.loads((kept / references.HISTORY_RECORD).read_text()) == {"why": "test"}
    found = references.search(SCENE, out, scene=scene)
    assert found.ref.path == path and found.ref.provenance["backend"] == "mitsuba" and found.problems == []
    # named directly (e.g. --references pointing into history), it is refused, with its reason
    found = references.search(SCENE, [kept, out], scene=scene)
    assert found.ref.path == path
    assert found.problems == [{"file": str(kept / references.HISTORY_RECORD), "problem": found.problems[0]["problem"]}]
    assert "keeps a replaced reference" in found.problems[0]["problem"]
    # a second replacement in the same second gets its own folder
    _p, again = references.replace(scene, ["R", "G", "B"], old_mean, old_se, {"backend": "x y", "spp": 1}, out, {}, "20260101T000000Z")
    assert again == out / "history" / SCENE / "20260101T000000Z-mitsuba"
    _p, third = references.replace(scene, ["R", "G", "B"], old_mean, old_se, {"backend": "m", "spp": 1}, out, {}, "20260101T000000Z")
    assert third == out / "history" / SCENE / "20260101T000000Z-unknown"  # the old record's "x y" is no name


def test_a_failed_save_leaves_the_old_reference_current_and_no_history(tmp_path, golden):
    scene = golden[SCENE]
    out = tmp_path / "refs"
    mean, se = _noisy(np.random.default_rng(2), 0.5)
    references.save(scene, ["R", "G", "B"], mean, se, {"backend": "toy", "spp": 64, "passes": 4}, out)
    before = (sha(out / f"{SCENE}.exr"), sha(out / f"{SCENE}.json"))
    with pytest.raises(ValueError):  # no R, G, B: the EXR writer refuses
        references.replace(scene, ["X", "Y", "Z"], mean, se, {"backend": "toy", "spp": 64}, out, {}, "20260101T000000Z")
    assert (sha(out / f"{SCENE}.exr"), sha(out / f"{SCENE}.json")) == before
    assert list((out / "history" / SCENE).iterdir()) == []


def _ref(mean, se, spp=64, passes=4):
    return references.Reference(["R", "G", "B"], mean, se, {"spp": spp, "passes": passes}, None)


def test_the_verdict_of_new_against_old_is_the_block_test_on_both_noises():
    rng = np.random.default_rng(3)
    old = _ref(*_noisy(rng, 0.5))
    same = references.judge_replacement(old, _ref(*_noisy(rng, 0.5)), block=64)
    assert same["comparable"] and same["same"] and same["test"]["p_min"] >= same["test"]["threshold"]
    assert same["test"]["name"] == "block test, Sidak-corrected" and same["test"]["noise"] == "own"
    # the whole image's mean: relative standard error 0.05 / 64 per reference; the ratio's is sqrt(2) times that
    for c in "RGB":
        r, se = same["ratio"][c]
        assert abs(r - 1) < 4 * se and se == pytest.approx(0.05 / 64 * np.sqrt(2), rel=0.1)
    assert same["detectable"] == pytest.approx(same["ratio"]["R"][1] * 2.9, rel=0.15)  # the Sidak z of 3 tests
    mean, se = _noisy(rng, 0.5)
    brighter = references.judge_replacement(old, _ref(mean * 1.01, se * 1.01), block=64)
    assert brighter["comparable"] and not brighter["same"] and brighter["test"]["p_min"] < brighter["test"]["threshold"]
    assert abs(brighter["ratio"]["G"][0] - 1.01) < 4 * brighter["ratio"]["G"][1]
    # the runner's default blocks pool 65536 samples: 32 px at 64 spp; smaller blocks alone cannot see 1 % at
    # this noise, but the noise test's scale test (issue 20) pools every block, whatever their size
    assert references.judge_replacement(old, _ref(mean * 1.01, se * 1.01))["test"]["block"] == 32
    small = references.judge_replacement(old, _ref(mean * 1.01, se * 1.01), block=8)
    assert small["detectable"] < 0.01 and not small["same"] and not small["test"]["scale_test"]["pass"]


def test_references_of_other_sizes_or_channels_are_judged_or_refused_plainly():
    rng = np.random.default_rng(4)
    old = _ref(*_noisy(rng, 0.5))
    half_mean, half_se = _noisy(rng, 0.5, shape=(32, 32))
    v = references.judge_replacement(old, _ref(half_mean, half_se / 2))  # a quarter of the pixels, 4x samples each
    assert v["comparable"] and v["judged_at"] == [32, 32]
    v = references.judge_replacement(_ref(half_mean, half_se / 2), old)  # the finer one is the old one
    assert v["comparable"] and v["judged_at"] == [32, 32]
    odd = _noisy(rng, 0.5, shape=(48, 48))
    v = references.judge_replacement(old, _ref(*odd))
    assert not v["comparable"] and not v["same"] and "64x64 (old) and 48x48 (new)" in v["reason"]
    stokes = references.Reference(["R", "G", "B", "S0.R"], np.zeros((64, 64, 4)), np.ones((64, 64, 4)), {"spp": 1}, None)
    v = references.judge_replacement(old, stokes)
    assert not v["comparable"] and "channels differ" in v["reason"]


# -- end to end: the example renderer declared in TOML ----------------------------------------------
@pytest.fixture(scope="module")
def toy_made(tmp_path_factory):
    """A reference by the declared renderer `toy`, then replaced by another of `toy` (other seeds)."""
    out = tmp_path_factory.mktemp("toy") / "refs"
    first = maker("--renderers", TOY, "-r", "toy", *SMALL, "--out", out)
    old = (sha(out / f"{SCENE}.exr"), sha(out / f"{SCENE}.json")) if first.returncode == 0 else None
    second = maker("--renderers", TOY, "-r", "toy", *SMALL, "--seed", 7000, "--out", out, "--replace")
    return out, first, old, second


@pytest.mark.slow
def test_a_declared_renderer_makes_a_reference_with_its_provenance(toy_made, golden):
    out, first, _old, _second = toy_made
    assert first.returncode == 0, first.stdout + first.stderr
    hist = history(out)
    assert len(hist) == 1
    meta = json.loads((hist[0] / f"{SCENE}.json").read_text())  # the first one, kept
    assert meta["backend"] == "toy" and meta["mode"] == "rgb" and meta["versions"] == {"toy": "toy_renderer 1.0"}
    assert meta["declaration"]["command"][1] == "{here}/toy_renderer.py" and meta["declaration"]["source"].endswith("toy.toml")
    assert meta["resolution"] == [128, 128] and meta["scale"] == 0.25 and meta["spp"] == 128 and meta["passes"] == 4
    assert meta["fingerprint"] == references.fingerprint(golden[SCENE])  # the scene as authored, not as scaled


@pytest.mark.slow
def test_replacing_with_the_same_renderer_judges_prints_and_keeps_the_old(toy_made):
    out, _first, old, second = toy_made
    text = second.stdout
    assert second.returncode == 0, text + second.stderr
    assert f"{SCENE}: the old reference (usable) against the new one" in text
    assert "  backend     toy" in text and "  versions    toy toy_renderer 1.0" in text
    assert "  date        " in text and "  spp         128" in text
    assert "new against old on both noises (block test, Sidak-corrected, alpha 0.01, 3 tests of 128x128 px blocks" in text
    assert "the same within noise" in text and "mean ratio new/old (+- standard error): R " in text
    assert "the test would have refused a uniform change of the whole image of +-" in text
    (kept,) = history(out)
    assert f"{SCENE}: replaced; the old reference is kept in {kept}" in text
    assert (sha(kept / f"{SCENE}.exr"), sha(kept / f"{SCENE}.json")) == old
    record = json.loads((kept / "replaced.json").read_text())
    assert record["why"]["old"] == "usable" and record["why"]["verdict"]["same"] is True
    assert not record["why"]["accepted_despite_verdict"] and "--replace" in record["command"] and "@" in record["by"]
    assert record["old"]["exr_sha256"] == old[0] and record["new"]["backend"] == "toy"
    new = json.loads((out / f"{SCENE}.json").read_text())
    assert new["seed"] == 7000 and new["exr_sha256"] == sha(out / f"{SCENE}.exr")
    assert not (out / ".work" / SCENE).exists()  # the passes are merged and removed


@pytest.mark.slow
def test_the_runner_judges_a_render_against_the_declared_renderers_reference(toy_made, tmp_path):
    out = toy_made[0]
    proc = run_batch("--renderers", TOY, "-r", "toy", "-s", SCENE, "--scale", "0.25", "--references", out,
                     "-o", tmp_path / "run")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (run,) = metrics(tmp_path / "run")["runs"]
    assert run["status"] == "ok" and run["test"]["pass"] and run["test"]["noise"] == "own"
    assert run["reference"]["path"] == str(out / f"{SCENE}.exr") and run["reference"]["backend"] == "toy"
    assert run["reference_problems"] == []


@pytest.mark.slow
def test_a_reference_one_percent_brighter_is_refused_unless_accepted(toy_made, tmp_path):
    out = tmp_path / "refs"
    shutil.copytree(toy_made[0], out)
    before = (sha(out / f"{SCENE}.exr"), sha(out / f"{SCENE}.json"))
    args = ["--renderers", BRIGHTER, "-r", "toy_brighter", *SMALL, "--seed", 3000, "--out", out, "--replace"]
    refused = maker(*args)
    assert refused.returncode == 1, refused.stdout + refused.stderr
    assert "they DIFFER beyond noise" in refused.stdout
    assert (f"{SCENE}: NOT replaced: the new reference differs from the old beyond noise; the old one is left as it is"
            in refused.stdout) and "--accept" in refused.stdout
    assert "  backend     toy" in refused.stdout and "toy_brighter" in refused.stdout  # old and new side by side
    assert (sha(out / f"{SCENE}.exr"), sha(out / f"{SCENE}.json")) == before
    assert len(history(out)) == 1  # only the earlier replacement's
    accepted = maker(*args, "--accept")
    assert accepted.returncode == 0, accepted.stdout + accepted.stderr
    assert f"{SCENE}: resuming, 4 of 4 passes already rendered" in accepted.stdout  # nothing rendered again
    assert "they DIFFER beyond noise" in accepted.stdout and "replaced (--accept: despite the verdict)" in accepted.stdout
    kept = [h for h in history(out) if h.name.endswith("-toy") and json.loads((h / "replaced.json").read_text())["why"]
            ["accepted_despite_verdict"]]
    assert len(kept) == 1 and (sha(kept[0] / f"{SCENE}.exr"), sha(kept[0] / f"{SCENE}.json")) == before
    assert json.loads((out / f"{SCENE}.json").read_text())["backend"] == "toy_brighter"


def test_the_extension_build_leaves_history_out():
    import importlib.util
    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    assert "history" in build.IGNORE(str(ROOT / "references"), ["history", f"{SCENE}.exr", ".work"])
    assert f"{SCENE}.exr" not in build.IGNORE(str(ROOT / "references"), ["history", f"{SCENE}.exr"])
    assert "history" not in build.IGNORE(str(ROOT / "docs"), ["history"])  # only the references' history


@pytest.mark.slow
def test_the_mitsuba_executable_route_makes_a_reference_that_records_it(tmp_path):
    exe = shutil.which("mitsuba", path=str(ROOT / ".venv" / "bin")) or shutil.which("mitsuba")
    if exe is None:
        pytest.skip("no mitsuba executable in this environment")
    out = tmp_path / "refs"
    proc = maker("-e", f"mitsuba={exe}", "-s", SCENE, "--scale", "0.0625", "--spp", "4", "--passes", "2", "--out", out)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    meta = json.loads((out / f"{SCENE}.json").read_text())
    assert meta["backend"] == "mitsuba" and meta["executable"] == exe and meta["versions"]["route"] == "executable"
    assert meta["resolution"] == [32, 32] and "declaration" not in meta
