"""Mitsuba 3 backend: renders the exported scene.xml in a child process.

Default route: batch/backends/mitsuba/worker.py with the mitsuba Python package, one warm process
per render that loads the scene once and renders one pass per request (render time measured
inside). With ``-e mitsuba=PATH`` the user's ``mitsuba`` executable renders each pass instead
(``mitsuba -m VARIANT -Dspp=N -Dseed=S -o pass.exr scene.xml``). Both routes go through the one
pass loop (batch/backends/passes.py) and the same conversion of the film's channels
(``film_to_ir``: monochrome variants, the camera polariser); the executable's version is read from
its banner, so the known deviations of that Mitsuba version apply to it. Scenes that need this
project's Python plugins are unsupported on the executable route, with the reason.

Device (``--device cpu|gpu|auto``, batch/backends/mitsuba/cuda.py): on the GPU the same "cheapest variant
that models the scene" rule picks from Mitsuba's cuda_ad_* variants instead of llvm_ad_*/scalar_*;
auto uses the GPU where the CUDA probe renders. The executable route (-e mitsuba=PATH) is asked for
the cuda_ad_* variant the same way (the probe is the Python package's; an executable built without
CUDA fails the job with its own message).
"""
import atexit
import importlib.util
import os
import queue
import subprocess
import sys
import threading
import time
from functools import lru_cache
from pathlib import Path

import numpy as np

from ....exporters import camera_filter, colorimetry, mitsuba_writer
from ... import exr
from .. import warm
from . import cuda, llvm, spectral as spectral_film
from .. import passes as passes_mod
from ..passes import BackendFailure

WORKER = Path(__file__).resolve().parent / "worker.py"
NATIVE = {"spectral", "polarization"}
# phenomena this project's Python plugins add (exporters/mitsuba_plugins): they load through the
# Python API only, not through the mitsuba executable
PLUGIN_NEEDS = {"thin_film", "dispersion", "fluorescence"}  # sb_thin_film_conductor; sb_dispersive_dielectric
# (unpolarised); sb_fluorescent_diffuse + sb_fluorescent_path (unpolarised spectral variants)
INTEGRATORS = ("path", "ptracer")  # the IR's render.integrator values Mitsuba renders
# the film the exported scene renders through: Mitsuba's hdrfilm (its 5 nm CIE tables and rounded
# matrix: known_deviations.toml mitsuba-cie-y-normalisation) or the IR's colour (spectral.py cmf_xml)
FILMS = ("rgb", "cmf")


def scalar_twin(variant):
    """The scalar variant that models the same as an llvm_ad_* or cuda_ad_* one (Mitsuba ships no
    scalar_mono*: its spectral twin is exact for the constant spectra a mono variant is chosen for)."""
    kind = variant.split("_ad_", 1)[-1] if "_ad_" in variant else variant.split("_", 1)[-1]
    return "scalar_" + kind.replace("mono", "spectral")


class MitsubaBackend:
    name = "mitsuba"
    formats = ("mitsuba",)

    def __init__(self, executable=None, force_variant=None, device="auto", film="rgb", layers=()):
        if film not in FILMS:
            raise ValueError(f"film {film!r}: one of {', '.join(FILMS)}")
        if device not in cuda.DEVICES:
            raise ValueError(f"device {device!r}: one of {', '.join(cuda.DEVICES)}")
        self.executable = executable
        self.force_variant = force_variant
        self.device = device
        # what rebuilds this backend (jobs are data; a job rebuilt elsewhere probes its own CUDA)
        self.film = film
        # with the CMF film: observers whose difference layers every pass also renders (spectral.py)
        self.layers = tuple(layers)
        if self.layers and film != "cmf":
            raise ValueError("observer layers need the CMF film")
        self.options = {"executable": executable, "force_variant": force_variant, "device": device, "film": film}
        if self.layers:
            self.options["layers"] = list(self.layers)

    def availability(self):
        """(available, reason)."""
        if self.executable:
            return (Path(self.executable).exists(), f"mitsuba executable not found: {self.executable}")
        if importlib.util.find_spec("mitsuba") is None:
            return False, "the mitsuba Python package is not installed (pip install mitsuba==3.9.1)"
        return True, ""

    def llvm_message(self):
        """The log line of where the variants render: the device, and LLVM's state on the CPU."""
        if cuda.use_gpu(self.device):
            return cuda.message(self.device)
        return f"{llvm.find()[1]}; {cuda.message(self.device)}"

    def device_problem(self):
        """None, or why this backend's --device cannot be honoured here (a usage error)."""
        return cuda.refusal(self.device)

    def mode_for(self, scene):
        """(variant, None) or (None, reason the scene is unsupported). With the CMF film, a spectral
        variant always (specfilm integrates spectra) and never a polarised scene."""
        mode, why = self._mode_for(scene)
        if mode is None or self.film == "rgb":
            return mode, why
        if scene.get("render", {}).get("integrator") == "ptracer":
            return None, ("the CMF film (specfilm) under the particle tracer: measured 1.2 % of the expected flux on "
                          "dispersion_prism's screen (prism energy probe), so light-traced scenes keep Mitsuba's RGB film")
        if "polarization" in scene.get("needs", []) or mode.endswith("_polarized"):
            return None, ("the CMF film (specfilm) records unpolarised radiance only (Film::prepare_sample takes an "
                          "UnpolarizedSpectrum): a polarised scene keeps Mitsuba's RGB film")
        return mode.replace("_mono", "_spectral").replace("_rgb", "_spectral"), None

    def _mode_for(self, scene):
        needs = set(scene.get("needs", []))
        missing = sorted(needs - NATIVE - PLUGIN_NEEDS)
        if missing:
            return None, (f"Mitsuba 3 has no native {', '.join(missing)} "
                          "(needs a plugin this backend does not have yet)")
        if self.executable and needs & PLUGIN_NEEDS:
            return None, (f"{', '.join(sorted(needs & PLUGIN_NEEDS))} needs this project's Python plugins, "
                          "which the mitsuba executable cannot load (use the Python route: no -e mitsuba=...)")
        if "dispersion" in needs and "polarization" in needs:
            return None, ("the dispersive dielectric plugin has no polarised (Mueller) form: "
                          "dispersion with polarisation is not supported")
        if scene.get("render", {}).get("integrator", "path") not in INTEGRATORS:
            return None, f"render.integrator {scene['render']['integrator']!r}: Mitsuba renders {', '.join(INTEGRATORS)}"
        if "fluorescence" in needs and "polarization" in needs:
            return None, ("fluorescence with polarisation: sb_fluorescent_path traces unpolarised spectral "
                          "radiance only")
        if self.force_variant:
            if "fluorescence" in needs and not (self.force_variant.endswith("_spectral")
                                                and not self.force_variant.startswith("scalar_")):
                return None, ("fluorescence needs an unpolarised spectral JIT variant (llvm_ad_spectral), "
                              f"not {self.force_variant}")
            return self.force_variant, None
        if cuda.use_gpu(self.device):
            return self._cheapest(needs, "cuda_ad_", True), None
        llvm_ok = llvm.find()[0] is not None
        if "fluorescence" in needs and not llvm_ok:
            return None, ("fluorescence: sb_fluorescent_path is a Python integrator that Mitsuba's scalar "
                          "variants would call once per sample; it needs llvm_ad_spectral: "
                          + llvm.find()[1])
        return self._cheapest(needs, "llvm_ad_" if llvm_ok else "scalar_", llvm_ok), None

    @staticmethod
    def _cheapest(needs, prefix, has_mono):
        """The cheapest variant of ``prefix`` (llvm_ad_, cuda_ad_, scalar_) that models ``needs``;
        ``has_mono``: the family ships *_mono_polarized (the JIT ones do, scalar does not)."""
        if "polarization" in needs:
            if "spectral" in needs or not has_mono:  # Mitsuba ships no scalar_mono_polarized
                return prefix + "spectral_polarized"
            return prefix + "mono_polarized"  # every spectrum is constant: one wavelength is exact
        if "spectral" in needs or "dispersion" in needs or "fluorescence" in needs:
            return prefix + "spectral"
        return prefix + "rgb"

    def export(self, scene, out_dir):
        path = mitsuba_writer.write(scene, out_dir)
        if self.film == "cmf":  # the IR's own colour: X, Y, Z against the 1 nm CMFs (spectral.py)
            path = Path(path)
            path.write_text(spectral_film.observers_xml(path.read_text(), self.layers, str(path)))
        return path

    def render(self, xml_path, variant, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render in independent passes (batch/backends/passes.py); returns the render record."""
        return passes_mod.render(self, xml_path, variant, spp, out_exr, passes, seed, timeout, log_path)

    def session(self, xml_path, variant, log):
        """Passes of one scene: a warm worker process (Python route) or one run of the mitsuba
        executable per pass."""
        if self.executable:
            return passes_mod.OneProcessPerPass(
                lambda spp, seed, out, timeout, log: self._pass_cli(xml_path, variant, spp, seed, out, timeout, log),
                log, {"versions": {"mitsuba": executable_version(self.executable), "route": "executable"}})
        return WarmWorker(xml_path, variant, log)

    def prestart(self, variants, timeout):
        """Warm workers of ``variants`` started in the background (the Python route only)."""
        if not self.executable:
            prestart(sorted(set(variants)), timeout)

    def _pass_cli(self, xml_path, variant, spp, seed, out, timeout, log):
        cmd = [self.executable, "-m", variant, f"-Dspp={spp}", f"-Dseed={seed}", "-o", str(out), str(xml_path)]
        wall = passes_mod.run_command(cmd, timeout, log, "mitsuba", env=llvm.env())
        if not Path(out).is_file():
            raise BackendFailure(f"mitsuba wrote no image {out}")
        ch = exr.read(out)
        names = [n for n in _film_order(ch) if n not in ("A", "W")]
        names, img = film_to_ir(names, np.stack([ch[n] for n in names], axis=-1), Path(xml_path).parent)
        return {"names": names, "image": img, "time_s": wall}


def _film_order(channels):
    """Mitsuba's film channels in their order: R, G, B (or Y) first, then the Stokes ones."""
    return exr._order(list(channels))


def film_to_ir(names, img, export_dir):
    """A Mitsuba film's channels as the IR's linear sRGB: a monochrome variant's Y (chosen only
    when every spectrum is constant, so each pixel is a flat spectrum times its luminance) becomes
    Y times the RGB of the flat spectrum of Y = 1 (equal-energy white is not D65 white), Stokes
    channels alike; then the IR's ideal camera polariser (exporters/camera_filter.py), applied to
    every pass so that the noise is the filtered image's."""
    img = np.asarray(img, dtype=np.float64)
    if list(names[:3]) == list(spectral_film.CMF_CHANNELS):  # the CMF film: the IR's colour
        img = np.concatenate([spectral_film.cmf_to_srgb(img[..., :3]), img[..., 3:]], axis=-1)
        names = ["R", "G", "B"] + list(names[3:])
        names, img = spectral_film.layers_to_ir(names, img)
    if names and names[0] == "Y":
        tint = _flat_spectrum_rgb()
        img = np.concatenate([img[..., :1] * tint, img[..., 1:]], axis=-1)
        names = ["R", "G", "B"] + list(names[1:])
        for i, n in enumerate(names):
            if "." in n and n[-1] in "RGB":
                img[..., i] *= tint["RGB".index(n[-1])]
    camera = camera_filter.read(Path(export_dir))
    if camera:
        names, img = camera_filter.apply(camera, names, img[None])
        img = img[0]
    return list(names), img


@lru_cache(maxsize=1)
def _flat_spectrum_rgb():
    """Linear sRGB of the flat spectrum whose luminance is 1."""
    xyz = colorimetry.spectrum_xyz({"type": "constant", "value": 1.0})
    return colorimetry.xyz_to_srgb(xyz) / xyz[1]


@lru_cache(maxsize=None)
def executable_version(executable):
    """The version a mitsuba executable states in its banner ("Mitsuba version 3.9.1 (...)"), or
    "unknown" (recorded, so that the known deviations of that version apply to its renders)."""
    import re
    try:
        proc = subprocess.run([str(executable), "-h"], capture_output=True, text=True, timeout=60, env=llvm.env(),
                              stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    m = re.search(r"Mitsuba version ([0-9][0-9A-Za-z.+-]*)", proc.stdout + proc.stderr)
    return m.group(1) if m else "unknown"


class WorkerProcess(warm.Worker):
    """One batch/backends/mitsuba/worker.py process of one variant: started once, then kept warm
    (``_POOL``) across passes and jobs, so a job pays neither the Python start, the Mitsuba import
    nor the JIT compilation of kernels another job of that variant already compiled. Its replies
    are its own (no ``ok``: a failure ends the worker), so a request is an ``exchange``."""
    log_hint = "render.log"

    def __init__(self, variant, timeout):
        super().__init__(variant, [sys.executable, WORKER, "--variant", variant], "mitsuba", timeout, env=llvm.env())
        self.variant = variant
        self.versions = self.ready["versions"]

    def ask(self, request, timeout, what):
        return self.exchange(request, timeout, what)


_POOL = {}  # variant -> idle WorkerProcess (a local run renders one job at a time)
_POOL_LOCK = threading.Lock()


_STARTING = {}  # variant -> Event set once its worker started by ``prestart`` is in the pool (or failed)
_STARTER = queue.Queue()  # (variant, timeout, Event) for the one thread that starts them
_STARTER_THREAD = []


def prestart(variants, timeout):
    """Start an idle worker of each of ``variants`` that the pool lacks, one after another in a
    thread of their own, and return at once: a run knows its variants once planned, so the second
    and third variants' Python start and Mitsuba import (about half a second each) overlap the
    first jobs instead of holding up the render thread when their first job comes (issue 23). The
    thread lives as long as this process: a child started with PR_SET_PDEATHSIG dies with the
    *thread* that started it (batch/backends/child.py). A worker that fails to start is dropped:
    its first job starts one itself and reports why."""
    for variant in variants:
        with _POOL_LOCK:
            if variant in _POOL or variant in _STARTING:
                continue
            _STARTING[variant] = started = threading.Event()
            if not _STARTER_THREAD:
                _STARTER_THREAD.append(threading.Thread(target=_starter, daemon=True, name="mitsuba-workers"))
                _STARTER_THREAD[0].start()
        _STARTER.put((variant, timeout, started))


def _starter():
    while True:
        variant, timeout, started = _STARTER.get()
        try:
            worker = WorkerProcess(variant, timeout)
        except Exception:  # noqa: BLE001 - the job that needs it starts one and reports the error
            worker = None
        with _POOL_LOCK:
            _STARTING.pop(variant, None)
            if worker is not None and variant not in _POOL:
                _POOL[variant], worker = worker, None
        started.set()
        if worker is not None:  # a worker of this variant came back to the pool meanwhile
            worker.close()


def _take(variant, timeout):
    with _POOL_LOCK:
        starting = _STARTING.get(variant)
    if starting is not None:  # started by prestart: wait for it rather than start a second one
        starting.wait(timeout)
    with _POOL_LOCK:
        worker = _POOL.pop(variant, None)
    if worker is not None and worker.alive():
        return worker
    return WorkerProcess(variant, timeout)


def _give(worker):
    with _POOL_LOCK:
        old = _POOL.pop(worker.variant, None)
        _POOL[worker.variant] = worker
    if old is not None:
        old.close()


@atexit.register
def close_pool():
    """Stop the idle workers (they also die with this process: child.popen_kwargs). An idle
    worker has nothing left to write (each reply follows its image and log; Dr.Jit writes a
    kernel to its cache when it compiles it), so it is killed rather than asked to shut down
    Mitsuba (0.1-0.2 s each, at the end of every run)."""
    with _POOL_LOCK:
        workers = list(_POOL.values())
        _POOL.clear()
    for w in workers:  # every worker signalled at once, then reaped
        try:
            w.proc.kill()
        except (OSError, AttributeError):
            pass
    for w in workers:
        w.kill()


class WarmWorker:
    """The Python route's session: a warm worker of the variant (from the pool, or a new one)
    loads the scene, then renders one pass per request within the pass's time limit. A worker that
    fails or overruns is killed and never returned to the pool; a retried pass gets a fresh one."""

    def __init__(self, xml_path, variant, log):
        self.xml, self.variant, self.log = str(xml_path), variant, log
        self.worker, self.info = None, {}

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        if self.worker is not None:
            if exc_type is None and self.worker.alive():
                _give(self.worker)
            else:
                self.worker.kill()
            self.worker = None
        return False

    def _ready(self, timeout):
        t0 = time.perf_counter()
        if self.worker is None or not self.worker.alive():
            self.worker = _take(self.variant, timeout)
            self.log.flush()
            log_name = getattr(self.log, "name", None)
            reply = self.worker.ask({"load": self.xml, "log": log_name if isinstance(log_name, str) else os.devnull},
                                    max(1.0, timeout - (time.perf_counter() - t0)), "loading the scene")
            self.info = {"versions": self.worker.versions, "load_s": reply.get("load_s")}
        return max(1.0, timeout - (time.perf_counter() - t0))

    def render_pass(self, spp, seed, out, timeout):
        try:
            left = self._ready(timeout)
            done = self.worker.ask({"spp": spp, "seed": seed, "out": str(out)}, left,
                                   f"rendering {spp} spp with seed {seed}")
        except BackendFailure:
            if self.worker is not None:
                self.worker.kill()
                self.worker = None
            raise
        ch = exr.read(out)
        names, img = film_to_ir(done["names"], np.stack([ch[n] for n in done["names"]], axis=-1), Path(self.xml).parent)
        info = dict(self.info, chunks_per_pass=done.get("chunks", 1))
        return {"names": names, "image": img, "time_s": done["time_s"], "info": info}
