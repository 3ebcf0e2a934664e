"""--device cpu|gpu|auto: Mitsuba's cuda_ad_* variants (batch/backends/mitsuba/cuda.py, mitsuba/backend.py).

On a machine without CUDA the selection is tested through the documented test hook
SPECTRAL_BENCH_TEST_CUDA=1 (the probe answers "usable" without rendering), and ``--device gpu`` is
tested to be refused with the real probe's reason. The tests that render on the GPU skip, naming
the probe's message, where there is no CUDA device.
"""
import json
import os
import subprocess
import sys

import pytest

from conftest import ALL_SCENES, GOLDEN, ROOT, metrics, run_batch

from spectral_bench.batch import cli
from spectral_bench.batch.backends.mitsuba import cuda, llvm
from spectral_bench.batch.backends.mitsuba.backend import MitsubaBackend
from spectral_bench.batch.jobs import runner


@pytest.fixture
def probe(monkeypatch):
    """Set the CUDA test hook (None: the real probe) and forget the cached answer, before and after."""
    def set_hook(value):
        if value is None:
            monkeypatch.delenv(cuda.TEST_HOOK, raising=False)
        else:
            monkeypatch.setenv(cuda.TEST_HOOK, value)
        cuda.find.cache_clear()
    yield set_hook
    cuda.find.cache_clear()


def real_cuda():
    """(usable, message) of the real probe, in a child process (so this process's cache and the
    test hook are left alone)."""
    env = {k: v for k, v in os.environ.items() if k != cuda.TEST_HOOK}
    code = ("import sys; sys.path.insert(0, %r); import pkg_bootstrap; pkg_bootstrap.package(); "
            "import json; from spectral_bench.batch.backends.mitsuba import cuda; print(json.dumps(cuda.find()))" % str(ROOT))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return tuple(json.loads(proc.stdout.strip().splitlines()[-1]))


def golden_scenes():
    from spectral_bench.exporters import ir_json
    return {name: ir_json.load(GOLDEN / f"{name}.json") for name in ALL_SCENES}


def test_auto_picks_the_cuda_twin_of_every_cpu_choice(probe):
    """With CUDA usable (test hook), auto and gpu choose for every canonical scene the cuda_ad_*
    variant of the same kind the CPU rule chooses among llvm_ad_* (or the same reason it is
    unsupported); cpu never chooses a cuda variant."""
    scenes = golden_scenes()
    probe("0")
    cpu = {n: MitsubaBackend(device="auto").mode_for(sc) for n, sc in scenes.items()}
    probe("1")
    auto = {n: MitsubaBackend(device="auto").mode_for(sc) for n, sc in scenes.items()}
    gpu = {n: MitsubaBackend(device="gpu").mode_for(sc) for n, sc in scenes.items()}
    forced_cpu = {n: MitsubaBackend(device="cpu").mode_for(sc) for n, sc in scenes.items()}
    assert forced_cpu == cpu
    assert auto == gpu
    kinds = set()
    for name, (mode, why) in cpu.items():
        if mode is None:
            assert auto[name] == (None, why), name
            continue
        assert auto[name][0].startswith("cuda_ad_"), (name, auto[name])
        if llvm.find()[0] is not None:
            assert auto[name][0] == "cuda_ad_" + mode.removeprefix("llvm_ad_"), (name, mode, auto[name])
        kinds.add(auto[name][0])
    # the canonical scenes exercise the spectral and both polarised variants (cuda_ad_rgb: below)
    assert kinds == {"cuda_ad_spectral", "cuda_ad_mono_polarized", "cuda_ad_spectral_polarized"}


def test_cheapest_cuda_variant_by_needs(probe):
    probe("1")
    backend = MitsubaBackend(device="gpu")
    cases = {(): "cuda_ad_rgb", ("spectral",): "cuda_ad_spectral", ("dispersion",): "cuda_ad_spectral",
             ("thin_film",): "cuda_ad_rgb", ("thin_film", "spectral"): "cuda_ad_spectral",
             ("fluorescence", "spectral"): "cuda_ad_spectral", ("fluorescence",): "cuda_ad_spectral",
             ("polarization",): "cuda_ad_mono_polarized",
             ("polarization", "spectral"): "cuda_ad_spectral_polarized"}
    for needs, variant in cases.items():
        assert backend.mode_for({"needs": list(needs)}) == (variant, None), needs
    # --variant still wins over the device
    assert MitsubaBackend(device="gpu", force_variant="llvm_ad_rgb").mode_for({"needs": []}) == ("llvm_ad_rgb", None)


def test_the_backend_options_carry_the_device():
    """Jobs are data: the options rebuild a backend with the same device (on any worker)."""
    from spectral_bench.batch import backends
    opts = dict(cli.DEFAULTS, renderer=["mitsuba"], exec={}, device="gpu")
    made = runner.make_backend("mitsuba", opts)
    assert made.options["device"] == "gpu"
    assert backends.get("mitsuba", **made.options).device == "gpu"
    assert runner.make_backend("mitsuba", dict(opts, device="cpu")).options["device"] == "cpu"
    with pytest.raises(ValueError, match="device 'tpu'"):
        MitsubaBackend(device="tpu")


def test_device_is_a_checked_option(tmp_path):
    assert cli.parse(["--device", "cpu"])["device"] == "cpu"
    assert cli.parse([])["device"] == "auto"
    settings = tmp_path / "s.toml"
    settings.write_text('device = "gpu"\n')
    assert cli.parse(["--settings", str(settings)])["device"] == "gpu"
    settings.write_text('device = "tpu"\n')
    with pytest.raises(cli.UsageError, match="device"):
        cli.parse(["--settings", str(settings)])
    with pytest.raises(cli.UsageError, match="device"):
        cli.check_option("device", "tpu")
    proc = run_batch("--device", "tpu", "--list", timeout=120)
    assert proc.returncode == 2 and "--device" in proc.stderr and "one of cpu, gpu, auto" in proc.stderr


@pytest.mark.slow
def test_device_gpu_without_cuda_is_a_usage_error(tmp_path, probe, capsys):
    """Where the real probe fails, --device gpu exits 2 naming why, and makes no output folder;
    the reference maker alike (called in this process: its main is the command)."""
    from spectral_bench.batch import make_references
    probe(None)
    usable, message = cuda.find()
    if usable:
        pytest.skip("this machine has a CUDA device: --device gpu is honoured here")
    out = tmp_path / "out"
    proc = run_batch("-r", "mitsuba", "-s", "ggx_copper_50", "--device", "gpu", "-o", out, timeout=300)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert f"--device gpu: no CUDA device: {message}" in proc.stderr, proc.stderr[-2000:]
    assert not out.exists()
    assert make_references.main(["-s", "ggx_copper_50", "--device", "gpu", "--out", str(tmp_path / "refs")]) == 2
    assert f"--device gpu: no CUDA device: {message}" in capsys.readouterr().err
    assert not (tmp_path / "refs").exists() or not any((tmp_path / "refs").glob("*.exr"))


# -- on a GPU ------------------------------------------------------------------------------------
PLUGIN_AND_NATIVE = ["iridescent_sphere_smooth", "dispersion_prism", "fluorescent_sphere_lone",
                     "polarizing_plane_0", "macbeth_chart_D65", "ggx_copper_50"]


@pytest.fixture(scope="module")
def gpu():
    usable, message = real_cuda()
    if not usable:
        pytest.skip(f"no CUDA device: {message}")
    return message


@pytest.mark.slow
def test_gpu_renders_are_judged_against_the_cpu_references(gpu, tmp_path):
    """Every plugin (thin film, dispersion, fluorescence) and a native polarised, spectral and RGB
    scene render on cuda_ad_* and pass the noise test against the references the CPU made."""
    out = tmp_path / "out"
    args = ["-r", "mitsuba", "--device", "gpu", "--scale", "0.5", "-o", out]
    for name in PLUGIN_AND_NATIVE:
        args += ["-s", name]
    proc = run_batch(*args, timeout=900)
    jobs = {e["scene"]: e for e in metrics(out)["runs"]}
    assert set(jobs) == set(PLUGIN_AND_NATIVE)
    for name, entry in jobs.items():
        assert entry["mode"].startswith("cuda_ad_"), (name, entry["mode"])
        assert entry["status"] in ("ok", "known"), (name, entry["status"], entry.get("reason"))
    assert proc.returncode == 0, proc.stderr[-3000:]


@pytest.mark.slow
def test_gpu_reference_maker(gpu, tmp_path):
    proc = subprocess.run([sys.executable, str(ROOT / "batch" / "make_references.py"), "-s", "dispersion_prism",
                           "--device", "gpu", "--spp", "64", "--passes", "2", "--scale", "0.25",
                           "--out", str(tmp_path / "refs")], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    record = json.loads((tmp_path / "refs" / "dispersion_prism.json").read_text())
    assert "cuda_ad_spectral" in json.dumps(record)
