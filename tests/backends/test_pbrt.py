"""pbrt-v4: scripts/build_pbrt.sh's second run (its refusals: test_build_scripts.py) and its env
file, the backend's reading of pbrt's spectral film, and, where pbrt is built, renders judged like
any other backend's (issue 43).

The render tests need pbrt-v4 (not in any package registry): scripts/build_pbrt.sh SRC builds it
from its source into .pbrt/ (.ci/run does when ../shared/pbrt/ holds the source) and writes
.pbrt/env.json, which the runner reads (SPECTRAL_BENCH_PBRT_ENV names another: .ci/run's
.pbrt/ci-env.json); a ``pbrt`` on PATH also serves. Without one they skip with a visible reason.

pbrt's renders are taken as random from machine to machine (its build is -march=native, its film
sums in threads): every judgement here takes its share of the suite's false-alarm budget
(tests/conftest.py RANDOM_TEST_ALPHA)."""
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import build_scripts
from conftest import ROOT, metrics, run_batch, write_scene
from installed import PBRT, needs_pbrt
from spectral_bench.batch import exr, spectral_exr
from spectral_bench.batch.backends.pbrt import backend as pbrt_backend



@pytest.mark.skipif(not (pbrt_backend.built_pbrt() and pbrt_backend.ENV_FILE.is_file()),
                    reason=f"pbrt not built with scripts/build_pbrt.sh here ({pbrt_backend.ENV_FILE}): nothing to rebuild")
def test_build_pbrt_second_run_over_a_finished_build_does_no_work():
    """Idempotent: rerun on the source the env file records, ninja has nothing to compile, the
    executable is not rewritten, and the env file names the same pbrt."""
    record = json.loads(pbrt_backend.ENV_FILE.read_text())
    if not os.path.exists(record["source"]):
        pytest.skip(f"the source pbrt was built from ({record['source']}) is gone")
    exe = record["pbrt"]
    prefix = os.path.dirname(os.path.dirname(exe))
    before = os.stat(exe).st_mtime_ns
    proc = build_scripts.run(build_scripts.PBRT, record["source"], prefix, env=dict(os.environ, SPECTRAL_BENCH_PBRT_ENV=str(pbrt_backend.ENV_FILE)))
    assert proc.returncode == 0, proc.stderr
    assert "no work to do" in open(os.path.join(prefix, ".build", "build.log")).read()
    assert os.stat(exe).st_mtime_ns == before
    assert json.loads(pbrt_backend.ENV_FILE.read_text()) == record


def test_env_file_gives_the_pbrt_to_run(tmp_path, monkeypatch):
    """The env file scripts/build_pbrt.sh writes: its pbrt is found without -e or PATH; one given
    with -e wins; a missing pbrt or a broken file is as if there were none (PATH is searched), and
    the backend then says how to build it."""
    exe = tmp_path / "prefix" / "bin" / "pbrt"
    exe.parent.mkdir(parents=True)
    exe.write_text("#!/bin/sh\nexit 0\n")
    exe.chmod(0o755)
    env_file = tmp_path / "env.json"
    env_file.write_text(json.dumps({"pbrt": str(exe), "source": "x"}))
    monkeypatch.setattr(pbrt_backend, "ENV_FILE", env_file)
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    assert pbrt_backend.find_pbrt() == exe and pbrt_backend.PbrtBackend().availability() == (True, "")
    other = tmp_path / "other-pbrt"
    shutil.copy(exe, other)
    assert pbrt_backend.find_pbrt(str(other)) == other
    exe.unlink()
    assert pbrt_backend.find_pbrt() is None
    ok, why = pbrt_backend.PbrtBackend().availability()
    assert not ok and "scripts/build_pbrt.sh" in why and "env.json" in why
    env_file.write_text("{not json")
    assert pbrt_backend.built_pbrt() is None


def test_the_env_file_path_comes_from_the_environment(tmp_path):
    """SPECTRAL_BENCH_PBRT_ENV names the env file the backend reads (.ci/run names its own to the
    tests only), read when the backend is imported."""
    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); import pkg_bootstrap; pkg_bootstrap.package(); "
            "from spectral_bench.batch.backends.pbrt import backend as b; print(b.ENV_FILE)")
    proc = subprocess.run([sys.executable, "-c", code],
                          capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, SPECTRAL_BENCH_PBRT_ENV=str(tmp_path / "x.json")))
    assert proc.returncode == 0 and proc.stdout.strip() == str(tmp_path / "x.json"), proc.stderr


def test_missing_pbrt_gives_skipped_jobs_never_passed(golden, tmp_path):
    """No pbrt where it is looked for: the job is `skipped` with the reason (how to build it), the
    run renders nothing (exit 4) and the summary lists it; the spectral group, the default, holds pbrt."""
    from spectral_bench.batch import backends
    assert "pbrt" in backends.GROUPS["spectral"] and "pbrt" in backends.DEFAULT
    out = tmp_path / "o"
    proc = run_batch("-i", write_scene(tmp_path, golden["macbeth_chart_D65"]), "-r", "pbrt",
                     "-e", f"pbrt={tmp_path / 'no_pbrt'}", "-o", out)
    runs = metrics(out)["runs"]
    assert [r["status"] for r in runs] == ["skipped"] and "scripts/build_pbrt.sh" in runs[0]["reason"], runs
    assert proc.returncode == 4
    assert "skipped" in (out / "summary.md").read_text()

# -- the spectral film as the backend reads it (a hand-written scene: pbrt's own format) ----------------------------
def plate_scene(folder, spp=8, size=48, savefp16=False, sampler="independent", reflectance=0.5):
    """A diffuse plate of constant reflectance filling the view under a uniform environment of
    radiance 1 at every wavelength: every pixel's radiance is ``reflectance`` at every wavelength
    (nothing but the environment above the plate; pbrt's light normalisation divides the flat
    spectrum by its luminance, 1, and the film multiplies the CIE Y integral back)."""
    folder.mkdir(parents=True, exist_ok=True)
    text = f"""LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" [ 20 ]
Sampler "{sampler}" "integer pixelsamples" [ {spp} ]
Integrator "path" "integer maxdepth" [ 5 ]
PixelFilter "box" "float xradius" [ 0.5 ] "float yradius" [ 0.5 ]
Film "spectral" "integer xresolution" [ {size} ] "integer yresolution" [ {size} ] "string filename" "scene.exr"
    "bool savefp16" {"true" if savefp16 else "false"} "integer nbuckets" [ 47 ] "float lambdamin" [ 360 ] "float lambdamax" [ 830 ]
WorldBegin
LightSource "infinite" "spectrum L" [ 360 1 830 1 ]
Material "diffuse" "spectrum reflectance" [ 360 {reflectance} 830 {reflectance} ]
Shape "trianglemesh" "point3 P" [ -10 -10 0 10 -10 0 10 10 0 -10 10 0 ] "integer indices" [ 0 1 2 0 2 3 ]
"""
    (folder / "scene.pbrt").write_text(text)
    (folder / pbrt_backend.SIZE_FILE).write_text(json.dumps({"width": size, "height": size}))
    return folder / "scene.pbrt"


def _pbrt_pass(scene, out, spp, seed=1):
    proc = subprocess.run([str(PBRT), "--seed", str(seed), "--spp", str(spp), "--outfile", str(out), str(scene)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return out


def test_occupancy_is_the_chance_that_a_bucket_gets_a_wavelength():
    """1 - (1 - 4/N)^n: 47 buckets at 8 samples per pixel 0.509, at 32 0.942 (5.8 % low unread), at
    256 1 - 1e-10; fewer buckets than a sample's wavelengths have no such rate (refused)."""
    assert pbrt_backend.occupancy(47, 8) == pytest.approx(1 - (43 / 47) ** 8) == pytest.approx(0.5091, abs=1e-4)
    assert 1 - pbrt_backend.occupancy(47, 32) == pytest.approx(0.0580, abs=1e-4)
    assert 1 - pbrt_backend.occupancy(47, 256) < 1e-9
    with pytest.raises(pbrt_backend.BackendFailure, match="fewer than"):
        pbrt_backend.occupancy(3, 8)


@needs_pbrt
def test_film_buckets_are_box_means_once_their_empty_rate_is_divided_out(tmp_path):
    """pbrt's film writes 0 in a bucket no wavelength of the pixel fell in: at 8 samples per pixel
    and 47 buckets, half the buckets of a pixel are empty and the raw buckets of a plate of
    radiance 0.5 average 0.5 x 0.509. Divided by that occupancy (the backend's reading), every
    bucket averages 0.5 over the image, and R, G, B are the plate's colour (the flat spectrum
    read as box bands through their histospline: exact). Each bucket's mean over the 2304
    pixels is judged against its standard error from the pixels' spread; the raw buckets fail the
    same test (its power), the corrected ones pass."""
    from conftest import RANDOM_TEST_ALPHA
    from spectral_bench.batch.verdict import stats
    from spectral_bench.exporters import colorimetry
    scene = plate_scene(tmp_path / "plate", spp=8)
    out = _pbrt_pass(scene, tmp_path / "pass.exr", 8)
    raw = spectral_exr.read(out)
    assert raw.wavelengths_nm.size == 47 and raw.channels[0][0] == "S0.365,000nm", raw.channels[0][:3]
    assert pbrt_backend.bucket_width(raw.wavelengths_nm) == pytest.approx(10.0, abs=1e-6)
    cube = raw.stokes[0].reshape(-1, 47)
    empty = float(np.mean(cube == 0))
    assert empty == pytest.approx((43 / 47) ** 8, abs=0.02), empty  # the film's empty buckets, as modelled
    names, img, bands = pbrt_backend.read_pass(out, 8, (48, 48))
    corrected = bands["cube"].reshape(-1, 47)
    n = corrected.shape[0]

    def judge(values):
        return stats.compare_means(values.mean(axis=0), np.full(47, 0.5), values.std(axis=0, ddof=1) / np.sqrt(n),
                                   dof=n - 1, alpha=RANDOM_TEST_ALPHA, tests=47)
    assert not judge(cube)["pass"] and judge(cube)["z"] > 20  # the raw film: 49 % low, seen
    assert judge(corrected)["pass"], judge(corrected)
    assert bands["bands"] == "box" and bands["band_width_nm"] == pytest.approx(10.0, abs=1e-6)
    wl, xb, yb, zb, norm = colorimetry.observer("cie1931")
    flat = colorimetry.xyz_to_srgb(np.array([np.trapz(c, wl) for c in (xb, yb, zb)]) / norm)
    rgb = img.reshape(-1, 3)
    se = rgb.std(axis=0, ddof=1) / np.sqrt(n)
    assert names == ["R", "G", "B"]
    verdict = stats.compare_means(rgb.mean(axis=0), 0.5 * flat, se, dof=n - 1, alpha=RANDOM_TEST_ALPHA, tests=3)
    assert verdict["pass"], verdict


@needs_pbrt
def test_a_half_float_film_is_refused_naming_savefp16(tmp_path):
    """pbrt's default film writes half floats (rounded to 11 bits, clamped at 65504): a pass that
    holds them is a failure naming the setting, never read."""
    out = _pbrt_pass(plate_scene(tmp_path / "plate", spp=1, size=8, savefp16=True), tmp_path / "pass.exr", 1)
    with pytest.raises(pbrt_backend.BackendFailure, match="savefp16"):
        pbrt_backend.read_pass(out, 1, (8, 8))


def test_a_sampler_other_than_independent_is_refused_before_rendering(tmp_path):
    """The occupancy correction holds for the independent sampler: a scene asking for another
    (pbrt's default zsobol stratifies the wavelengths) fails naming it, before pbrt runs."""
    exe = tmp_path / "pbrt"
    exe.write_text("#!/bin/sh\nexit 1\n")
    exe.chmod(0o755)
    scene = plate_scene(tmp_path / "plate", sampler="zsobol")
    with pytest.raises(pbrt_backend.BackendFailure, match='"zsobol".*"independent"'):
        pbrt_backend.PbrtBackend(executable=str(exe)).render(scene, "spectral47", 8, tmp_path / "out.exr")


@needs_pbrt
@pytest.mark.slow
def test_passes_have_their_own_seeds_and_a_time_out_ends_pbrt(tmp_path):
    """Through the one pass loop: two passes with their own seeds (their spread is the standard
    error: nonzero), the record names pbrt's version from its banner; a pass past its time limit
    fails saying so and leaves no pbrt running (its process group is ended)."""
    scene = plate_scene(tmp_path / "plate", spp=4, size=16)
    backend = pbrt_backend.PbrtBackend()
    record = backend.render(scene, "spectral47", 8, tmp_path / "r" / "render.exr", passes=2, seed=3,
                            log_path=tmp_path / "r" / "render.log")
    assert record["passes"] == 2 and record["spp"] == 8 and record["resolution"] == [16, 16]
    assert record["versions"]["pbrt"].startswith("4 ") and record["versions"]["pbrt_exe"] == str(PBRT)
    log = (tmp_path / "r" / "render.log").read_text()
    assert "--seed 3 " in log and "--seed 1003 " in log
    names, img, se = exr.read_image_and_stderr(tmp_path / "r" / "render.exr")
    assert names == ["R", "G", "B"] and se is not None and np.all(se > 0)
    assert record["spectral"]["bands"] == "box" and len(record["spectral"]["wavelengths_nm"]) == 47
    slow = plate_scene(tmp_path / "slow", spp=4, size=256)
    with pytest.raises(pbrt_backend.BackendFailure, match="timed out"):
        backend.render(slow, "spectral47", 1 << 20, tmp_path / "s" / "render.exr", timeout=3)
    left = []
    for entry in os.scandir("/proc"):
        try:
            cmdline = open(f"/proc/{entry.name}/cmdline", "rb").read().decode(errors="replace")
        except OSError:
            continue
        if str(tmp_path / "slow") in cmdline:
            left.append((entry.name, cmdline))
    assert not left, left


# -- pbrt renders, judged like any other backend's (one batch run per condition, shared) ----------------------------
JUDGED = ["macbeth_chart_D65", "ggx_copper_50_isolated"]  # the ColorChecker (lambert, bands), a GGX plate (its probe)
SCENES = [*JUDGED, "polarizing_plane_0"]  # pbrt-v4 has no polariser: unsupported, naming object and field
# 32 spp in 2 passes at full resolution: the chart's patches have the pixels its band checks need at
# the suite's alpha (at half resolution none is judged: too few pixels for the skew of 16 samples per
# pass); the planted run at half resolution, whose power is enough (each run detects 0.3-0.4 %,
# 2026-12-04: far below the planted 2 %)
REDUCED = ["--spp", "32"]
PLANTED_SETTINGS = ["--scale", "0.5"]
PLANTED = 1.02  # every light 2 % brighter (the writer's test hook): every judged scene must fail


def _pbrt_batch(out, scenes, *extra):
    from conftest import RANDOM_TEST_ALPHA, random_run_env
    proc = run_batch("-r", "pbrt", *[a for s in scenes for a in ("-s", s)], *REDUCED, "--alpha", RANDOM_TEST_ALPHA,
                     *extra, "-o", out, timeout=1200, env=random_run_env())
    assert (out / "metrics.json").is_file(), proc.stderr[-3000:]
    return proc, {r["scene"]: r for r in metrics(out)["runs"]}


@pytest.fixture(scope="module")
def pbrt_runs(tmp_path_factory):
    """The scenes rendered with pbrt at reduced settings, as a user runs the command."""
    if not PBRT:
        pytest.skip(needs_pbrt.kwargs["reason"])
    out = tmp_path_factory.mktemp("pbrt") / "out"
    proc, runs = _pbrt_batch(out, SCENES)
    return proc, out, runs


@pytest.fixture(scope="module")
def planted_runs(tmp_path_factory):
    """The judged scenes again, every light of the .pbrt 2 % brighter (the writer's hook)."""
    if not PBRT:
        pytest.skip(needs_pbrt.kwargs["reason"])
    from spectral_bench.exporters import pbrt_writer
    out = tmp_path_factory.mktemp("pbrt_planted") / "out"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(pbrt_writer.TEST_HOOK, str(PLANTED))
        proc, runs = _pbrt_batch(out, JUDGED, *PLANTED_SETTINGS)
    return proc, out, runs


def _has_power(run):
    """The run could see the planted error: its own detectable scale (90 % power) is below it."""
    from conftest import assert_sees
    assert_sees(run, PLANTED - 1, "every light 2 % brighter")


@pytest.mark.slow
@needs_pbrt
def test_pbrt_renders_the_scenes_and_judges_them(pbrt_runs):
    """macbeth_chart_D65 and ggx_copper_50_isolated `ok` against the CMF references and their probes
    (every ColorChecker patch, the GGX plate's closed form), with the power to see 2 %, band checks
    run on pbrt's buckets read as 10 nm boxes (those with enough samples judged, and passing);
    polarizing_plane_0 `unsupported`, naming the camera's polariser; pbrt's version recorded."""
    proc, out, runs = pbrt_runs
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in JUDGED:
        run = runs[name]
        assert (run["status"], run["mode"]) == ("ok", "spectral47"), (name, run["status"], run["reason"])
        assert run["versions"]["pbrt"].startswith("4 ") and run["versions"]["pbrt_exe"] == str(PBRT)
        assert run["passes"] == 2 and run["test"]["pass"], (name, run["test"])
        assert run["probes"] and all(p["pass"] is not False for p in run["probes"]), run["probes"]
        _has_power(run)
    chart = {p["name"]: p for p in runs["macbeth_chart_D65"]["probes"]}
    patches = [p for n, p in chart.items() if n.startswith("lambert patch_")]
    assert len(patches) == 24 and all(p["pass"] for p in patches)
    bands = [p for n, p in chart.items() if n.startswith("bands ")]
    assert len(bands) == 25 and all(p["pass"] is True for p in bands), [(p["name"], p["pass"]) for p in bands]
    ggx = [p for p in runs["ggx_copper_50_isolated"]["probes"] if p["name"].startswith("ggx copper_plate_50")]
    assert len(ggx) == 2 and all(p["pass"] is True for p in ggx), ggx
    polariser = runs["polarizing_plane_0"]
    assert polariser["status"] == "unsupported" and "plane_camera_0.polarizer" in polariser["reason"]


@pytest.mark.slow
@needs_pbrt
def test_planted_light_error_in_the_pbrt_route_fails_every_judged_scene(pbrt_runs, planted_runs):
    """The .pbrt writer's lights 2 % too bright (nothing else changed): every judged scene fails its
    noise test against the references, with the power to see it, and the run exits 1. The written
    scene differs from the unplanted run's by that factor on every light's scale."""
    import re
    proc, out, runs = planted_runs
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    scale = re.compile(r'"float scale" \[ ([0-9.e+-]+) \]')
    for name in JUDGED:
        run = runs[name]
        assert run["status"] == "failed" and "noise test" in run["reason"], (name, run["status"], run["reason"])
        _has_power(run)
        plain = (pbrt_runs[1] / name / "pbrt" / "scene.pbrt").read_text()
        planted = (out / name / "pbrt" / "scene.pbrt").read_text()
        a, b = (np.array([float(x) for x in scale.findall(t)]) for t in (plain, planted))
        assert len(a) == len(b) > 0 and np.allclose(b / a, PLANTED), (name, a, b)
