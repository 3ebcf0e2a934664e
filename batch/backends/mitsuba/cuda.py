"""Whether Mitsuba's CUDA variants (cuda_ad_*) can render here, once per process.

The probe mirrors batch/backends/mitsuba/llvm.py: a child process sets ``cuda_ad_rgb`` and renders a tiny
scene at 1 spp, so a missing driver, a GPU Dr.Jit cannot use or a crash in the CUDA back end costs
a failed probe, never the runner. The answer (usable, message) is cached for the process and
handed down to its children (llvm.py's module docstring).

Test hook (tests/backends/test_gpu.py, docs/developing.md): ``SPECTRAL_BENCH_TEST_CUDA=1`` in the
environment makes :func:`find` answer "usable" without probing (so the variant selection can be
tested on a machine without a GPU; a render with the chosen cuda_ad_* variant would then fail);
``SPECTRAL_BENCH_TEST_CUDA=0`` answers "not usable" (the refusal of ``--device gpu`` on a machine
with a GPU). Any other value, or none, runs the real probe.
"""
import os
import subprocess
import sys

from . import llvm

TEST_HOOK = "SPECTRAL_BENCH_TEST_CUDA"
DEVICES = ("cpu", "gpu", "auto")

_PROBE = ("import drjit as dr, mitsuba as mi; mi.set_variant('cuda_ad_rgb'); d = mi.cornell_box(); "
          "d['sensor']['film']['width'] = d['sensor']['film']['height'] = 8; "
          "img = mi.render(mi.load_dict(d), spp=1); dr.eval(img); dr.sync_thread(); print('ok')")


@llvm.probed_once("cuda", lambda: [sys.executable, os.environ.get(TEST_HOOK), llvm.find()[0]])
def find():
    """(usable, message): whether a cuda_ad_* variant renders in a child process here."""
    hook = os.environ.get(TEST_HOOK)
    if hook == "1":
        return True, f"{TEST_HOOK}=1: CUDA taken as usable (test hook; nothing was probed)"
    if hook == "0":
        return False, f"{TEST_HOOK}=0: CUDA taken as unusable (test hook; nothing was probed)"
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE], env=llvm.env(), capture_output=True, text=True,
                              timeout=180, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return False, "the CUDA probe (cuda_ad_rgb, 1 spp) timed out after 180 s"
    except OSError as exc:
        return False, f"the CUDA probe could not start: {exc}"
    if proc.returncode == 0 and proc.stdout.strip().endswith("ok"):
        return True, "Mitsuba's cuda_ad_* variants render on this machine's GPU"
    last = (proc.stderr.strip().splitlines() or [f"exit {proc.returncode}"])[-1][:300]
    return False, f"cuda_ad_rgb does not render here: {last}"


def use_gpu(device):
    """Whether ``device`` (cpu, gpu or auto) renders on the GPU here; gpu without CUDA is the
    caller's usage error (see :func:`refusal`), so it answers False then."""
    if device == "cpu":
        return False
    return find()[0]


def refusal(device):
    """None, or why ``--device gpu`` cannot be honoured here (the probe's message)."""
    if device != "gpu":
        return None
    ok, message = find()
    return None if ok else f"--device gpu: no CUDA device: {message}"


def message(device):
    """One log line: where Mitsuba's variants render and why."""
    if device == "cpu":
        return "Mitsuba renders on the CPU (--device cpu)"
    ok, why = find()
    if ok:
        return f"Mitsuba renders on the GPU (--device {device}): {why}"
    return f"Mitsuba renders on the CPU (--device {device}; no CUDA device: {why})"
