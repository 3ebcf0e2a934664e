"""ART backend: runs the user's ``artist`` (ART 2.1.2) on a copy of the exported folder.

artist compiles the .arm with gcc at render time, edits it in place and writes its outputs
beside it, so every render works on a copy. Where artist comes from, first found: ``-e art=PATH``
(or the settings file's exec), the env file ``.art/env.json`` that scripts/build_art.sh writes
(its artist and the environment its child gets), ``artist`` on PATH. It needs ART_RESOURCE_PATH
and ART_LIBRARY_PATH (and the library on LD_LIBRARY_PATH): the env file's, else, when unset,
derived from the executable's install prefix (<prefix>/bin/artist, <prefix>/lib); always
LC_NUMERIC=C (ART parses and prints decimal points) and ART_VIEWER=true (headless). Options used:
``-b`` (no viewer), ``-wp d65``, ``-s46e`` (46 spectral bands of 10 nm, 320-780 nm, instead of
the default 8), ``-seed`` (reproducible passes), ``-p`` when the scene needs polarisation. Every
scene is written out as ART's spectral EXR (S0, or S0..S3 with signs kept, per band; the band
labels are their centres: the Fichet 2021 layout), read and integrated with the CIE 1931 CMFs to
linear sRGB by batch/spectral_exr.py as the IR defines colour (exporters/colorimetry.py): R, G, B
and, for Stokes output, S0.R ... S3.B.
ART's own sRGB EXR is not used: it maps out-of-gamut colours into the gamut.
"""
import os
import re
import shutil
import subprocess
from functools import lru_cache
from pathlib import Path

import numpy as np

from ....exporters import art_writer
from ....exporters.colorimetry import ART_BANDS_NM as ART_BANDS  # (first centre - width / 2, width, count)
from ... import spectral_exr
from .. import builds, passes as passes_mod
from ..passes import BackendFailure

NATIVE = {"spectral", "polarization", "dispersion", "fluorescence"}  # dispersion: CONST_SELLMEIER_DISPERSION_6;
# fluorescence: CONST_FLUORESCENT_COLOUR (art_writer)


# written by scripts/build_art.sh; SPECTRAL_BENCH_ART_ENV names another (.ci/run: one for the tests only)
ENV_FILE = Path(os.environ.get("SPECTRAL_BENCH_ART_ENV") or Path(__file__).resolve().parents[3] / ".art" / "env.json")
PREPENDED = ("PATH", "LD_LIBRARY_PATH")  # the env file's entries go before the inherited ones
FIXED = {"LC_NUMERIC": "C", "ART_VIEWER": "true"}  # every artist child: decimal points, no viewer


def built_art(env_file=None):
    """(artist, {variable: value}) from scripts/build_art.sh's env file (default ENV_FILE), or None
    when there is none, it is unreadable or its artist is gone (a build deleted since): then PATH
    is searched."""
    found = builds.built_program(env_file or ENV_FILE, "artist")
    if found is None or not isinstance(found[1].get("env"), dict):
        return None
    return found[0], {str(k): str(v) for k, v in found[1]["env"].items()}


def find_artist(executable=None):
    """The artist to run: ``executable`` when given, else the built one (env file), else PATH."""
    built = None if executable else built_art()
    return builds.find_program(executable, built and built[0], "artist")


def artist_env(artist):
    """The environment of an artist child (this process's own is left as it is)."""
    env = dict(os.environ)
    built = built_art()
    if built and built[0].resolve() == Path(artist).resolve():
        for k, v in built[1].items():
            env[k] = os.pathsep.join(p for p in (v, env.get(k)) if p) if k in PREPENDED else v
    prefix = Path(artist).resolve().parent.parent
    env.setdefault("ART_LIBRARY_PATH", str(prefix / "lib"))
    env.setdefault("ART_RESOURCE_PATH", str(prefix / "lib" / "ART_Resources"))
    if env["ART_LIBRARY_PATH"] not in env.get("LD_LIBRARY_PATH", "").split(os.pathsep):
        env["LD_LIBRARY_PATH"] = os.pathsep.join(p for p in (env["ART_LIBRARY_PATH"], env.get("LD_LIBRARY_PATH")) if p)
    env.update(FIXED)
    return env


@lru_cache(maxsize=None)
def art_version(artist):
    """ART's version as its banner states it ("ART version 2.1.2"), or "unknown"."""
    try:
        proc = subprocess.run([str(artist), "-h"], capture_output=True, text=True, timeout=60,
                              env=artist_env(artist))
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    m = re.search(r"ART version ([0-9][0-9.]*)", proc.stdout + proc.stderr)
    return m.group(1) if m else "unknown"


def read_pass(path):
    """(names, image, bands) of one pass: stokes_to_rgb's channels and the S0 bands the band checks
    judge (batch/spectral_exr.py pass_bands: ART's 10 nm boxes, their model recorded here)."""
    try:
        image = spectral_exr.read(path)
        names, img = spectral_exr.to_rgb(image, bands="box", band_width_nm=ART_BANDS[1])
    except spectral_exr.SpectralEXRError as exc:
        raise BackendFailure(f"ART's spectral EXR: {exc}") from exc
    return names, img, dict(spectral_exr.pass_bands(image, "box", ART_BANDS[1]), source="recorded")


def stokes_to_rgb(path):
    """R, G, B and, for a polarised render, S0.R ... S3.B from ART's spectral EXR: the Fichet 2021
    layout (channels 'S<k>.<nm>,<frac>nm', the band centres) read and integrated with the CIE 1931
    CMFs by batch/spectral_exr.py (R, G, B alone when only S0 is there: an unpolarised render).
    ART's film holds each 10 nm band's box average (exporters/colorimetry.py ART_BANDS_NM): read
    with the "box" band model, each band weighted by the CMFs' integral over it."""
    return read_pass(path)[:2]


class ArtBackend:
    name = "art"
    formats = ("art",)

    def __init__(self, executable=None, ggx=False):
        self.executable, self.ggx = executable, ggx
        self.options = {"executable": executable, "ggx": ggx}  # what rebuilds this backend (jobs are data)
        self.artist = find_artist(executable)

    def availability(self):
        if self.artist is None:
            return False, builds.not_found("artist", "ART 2.1.2", self.executable, ENV_FILE, "scripts/build_art.sh", "art")
        return True, ""

    def mode_for(self, scene):
        problems = art_writer.unsupported(scene, ggx=self.ggx)  # per object and field, first
        if problems:
            return None, "ART cannot express: " + "; ".join(f"{o}.{f}: {m}" for o, f, m in problems)
        missing = sorted(set(scene.get("needs", [])) - NATIVE)
        if missing:
            return None, f"the ART writer does not map {', '.join(missing)} yet"
        return ("spectral46_polarized" if "polarization" in scene.get("needs", []) else "spectral46"), None

    def export(self, scene, out_dir):
        return art_writer.write(scene, out_dir, ggx=self.ggx)[0]

    def render(self, arm_path, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render in independent passes (batch/backends/passes.py); returns the render record."""
        return passes_mod.render(self, arm_path, mode, spp, out_exr, passes, seed, timeout, log_path)

    def session(self, arm_path, mode, log):
        """One artist run per pass, each on its own copy of the exported folder."""
        versions = {"art": art_version(self.artist), "artist": str(self.artist)}
        return passes_mod.OneProcessPerPass(
            lambda spp, seed, out, timeout, log: self._pass(Path(arm_path), mode, spp, seed, out, timeout, log),
            log, {"versions": versions})

    def _pass(self, arm, mode, spp, seed, out, timeout, log):
        run_dir = Path(out).parent / f"art_seed{seed}"
        shutil.rmtree(run_dir, ignore_errors=True)
        shutil.copytree(arm.parent, run_dir)
        cmd = [str(self.artist), "scene.arm", "-b", "-j", str(os.cpu_count() or 1), f"-DSAMPLES={spp}",
               "-wp", "d65", "-s46e", "-seed", str(seed + 1), "-f"]
        if mode.endswith("polarized"):
            cmd.append("-p")
        wall = passes_mod.run_command(cmd, timeout, log, "artist", env=artist_env(self.artist), cwd=run_dir)
        if not (run_dir / "scene.exr").is_file():
            raise BackendFailure(f"artist wrote no scene.exr in {run_dir}")
        names, img, bands = read_pass(run_dir / "scene.exr")  # always the spectral EXR (art_writer)
        shutil.rmtree(run_dir, ignore_errors=True)
        return {"names": names, "image": img.astype(np.float64), "time_s": wall, "spectral": bands}
