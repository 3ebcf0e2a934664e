"""pbrt-v4 backend: runs the user's ``pbrt`` (built from pbrt-v4's source by scripts/build_pbrt.sh)
on the exported .pbrt scene (exporters/pbrt_writer.py), one run per pass.

Where pbrt comes from, first found: ``-e pbrt=PATH`` (or the settings file's exec), the env file
``.pbrt/env.json`` that scripts/build_pbrt.sh writes (SPECTRAL_BENCH_PBRT_ENV names another),
``pbrt`` on PATH. Options used: ``--seed`` (each pass its own; the writer writes no seed into the
sampler, which would override it), ``--spp`` (the pass's share), ``--nthreads``, ``--outfile``
(the pass's EXR). pbrt reads the scene's meshes and spectra relative to the scene file and writes
nothing else, so it runs on the exported folder as it is, in the pass's own working folder.

The image is pbrt's spectral film (``Film "spectral"``): the Fichet 2021 layout, R, G, B (pbrt's
sensor, not used) and one channel per bucket, ``S0.<centre>nm`` with a comma for the decimal point
(``S0.365,000nm``), read by batch/spectral_exr.py. The writer asks for full floats (``savefp16``
false; half floats round to 11 bits and clamp at 65504: a pass holding them is refused) and the
buckets the band checks judge (exporters/pbrt_writer.py's film). A bucket is the mean radiance of
the wavelengths that fell in it (film.h SpectralFilm::AddSample: every sample's radiance times the
CIE Y integral, summed per bucket with the filter weights and divided by their sum), so the
buckets are read as the box bands they are ("box": batch/spectral_exr.py, through their
histospline) and integrated to R, G, B with the CIE 1931 CMFs as the IR defines colour, like the
CMF references and like ART's bands; they are also kept for the band checks.

One correction, exact in expectation, makes a pass's bucket an unbiased mean: a bucket in which no
wavelength of the pixel's samples fell reads 0 (film.cpp SpectralFilm::GetImage: ``weightSums > 0``
or 0). With the independent sampler (which the IR's convention of independent pixels asks for, and
which the backend checks the scene asks for), each sample draws its first wavelength uniformly over
the film's range and three more a quarter of the range apart (spectrum.h SampleUniform,
NSpectrumSamples 4), so with N buckets (N >= 4) a sample lands in a given bucket with probability
4 / N, the n samples of a pixel independently: a bucket is empty with probability
(1 - 4 / N)^n, and its expected value is the band mean times 1 - (1 - 4 / N)^n. The backend divides
every bucket of a pass by that factor (47 buckets at 32 samples per pixel: 5.8 % low uncorrected;
at 256, 1e-10). A scene whose sampler is not ``independent`` is refused with the reason: the factor
of a stratified sampler is not known.
"""
import json
import os
import re
import shutil
from pathlib import Path

import numpy as np

from ....exporters import pbrt_writer
from ... import exr, spectral_exr
from .. import builds, passes as passes_mod
from ..passes import BackendFailure

# written by scripts/build_pbrt.sh; SPECTRAL_BENCH_PBRT_ENV names another (.ci/run: one for the tests only)
ENV_FILE = Path(os.environ.get("SPECTRAL_BENCH_PBRT_ENV") or Path(__file__).resolve().parents[3] / ".pbrt" / "env.json")
WAVELENGTHS_PER_SAMPLE = 4  # pbrt-v4 src/pbrt/util/spectrum.h NSpectrumSamples (a compile-time constant)
SAMPLER = pbrt_writer.SAMPLER  # "independent": the sampler whose bucket occupancy is known (module docstring)
BANNER = re.compile(r"pbrt version ([^\n]*?)\s*(?:\n|$)")  # "pbrt version 4 (built Dec  4 2026 at 18:20:00)"
SAMPLER_LINE = re.compile(r'^\s*Sampler\s+"([^"]*)"', re.M)
SIZE_FILE = ".render_size.json"  # written beside the export: the resolution the pass must have


def built_pbrt(env_file=None):
    """The pbrt executable from scripts/build_pbrt.sh's env file (default ENV_FILE), or None when
    there is none, it is unreadable or its pbrt is gone (a build deleted since): then PATH is searched."""
    found = builds.built_program(env_file or ENV_FILE, "pbrt")
    return found and found[0]


def find_pbrt(executable=None):
    """The pbrt to run: ``executable`` when given, else the built one (env file), else PATH."""
    return builds.find_program(executable, None if executable else built_pbrt(), "pbrt")


def occupancy(buckets, spp):
    """The expected fraction of a pass's pixels in which a bucket received a sample: 1 - (1 - 4 /
    N)^n for N buckets and n samples per pixel of the independent sampler (module docstring)."""
    if buckets < WAVELENGTHS_PER_SAMPLE:
        raise BackendFailure(f"pbrt's film has {buckets} buckets: fewer than the {WAVELENGTHS_PER_SAMPLE} wavelengths "
                             "of a sample, whose buckets then coincide (no known occupancy)")
    return 1.0 - (1.0 - WAVELENGTHS_PER_SAMPLE / buckets) ** spp


def bucket_width(wavelengths):
    """The width of pbrt's equal buckets from their centres (written to 3 decimals: the spacing)."""
    c = np.asarray(wavelengths, dtype=np.float64)
    width = (c[-1] - c[0]) / (c.size - 1)
    if not np.allclose(np.diff(c), width, atol=2e-3, rtol=0):
        raise BackendFailure(f"pbrt's spectral film wrote unequal buckets ({c[:4]} ... nm): not its film")
    return float(width)


def read_pass(path, spp, expect=None):
    """(names, image, bands) of one pass's EXR: R, G, B from the buckets, read as box bands after
    the occupancy correction (module docstring), and the corrected buckets for the band checks."""
    try:
        info = exr.header_info(path)
        half = sorted(n for n, ptype, _xs, _ys in info["channels"] if n.startswith("S0.") and exr.PIXEL_TYPES.get(ptype) != "FLOAT")
        if half:
            raise BackendFailure(f"pbrt wrote {len(half)} buckets ({half[0]}, ...) as other than full floats: the scene's "
                                 'Film "spectral" must say "bool savefp16" false (half floats round and clamp at 65504)')
        image = spectral_exr.read(path, expect)
    except (exr.EXRLimitError, spectral_exr.SpectralEXRError, OSError) as exc:
        raise BackendFailure(f"pbrt's spectral EXR: {exc}") from exc
    if image.polarised:
        raise BackendFailure(f"{path}: pbrt wrote Stokes components: not pbrt-v4's spectral film")
    image.stokes[0] = image.stokes[0] / occupancy(image.wavelengths_nm.size, spp)
    width = bucket_width(image.wavelengths_nm)
    names, img = spectral_exr.to_rgb(image, bands="box", band_width_nm=width)
    return names, img, dict(spectral_exr.pass_bands(image, "box", width), source="recorded")


def scene_sampler(path):
    """The sampler the exported scene names (its last Sampler directive: pbrt keeps the last), or None."""
    found = SAMPLER_LINE.findall(Path(path).read_text(encoding="utf-8", errors="replace"))
    return found[-1] if found else None


class PbrtBackend:
    name = "pbrt"
    formats = ("pbrt",)

    def __init__(self, executable=None):
        self.executable = executable
        self.options = {"executable": executable}  # what rebuilds this backend (jobs are data)
        self.pbrt = find_pbrt(executable)

    def availability(self):
        if self.pbrt is None:
            return False, builds.not_found("pbrt", "pbrt-v4", self.executable, ENV_FILE, "scripts/build_pbrt.sh", "pbrt")
        return True, ""

    def mode_for(self, scene):
        problems = pbrt_writer.unsupported(scene)  # per object and field
        if problems:
            return None, "pbrt-v4 cannot express: " + "; ".join(f"{o}.{f}: {m}" for o, f, m in problems)
        return f"spectral{pbrt_writer.FILM['nbuckets']}", None

    def export(self, scene, out_dir):
        path = Path(pbrt_writer.write(scene, out_dir))
        r = scene["render"]
        (path.parent / SIZE_FILE).write_text(json.dumps({
            "width": int(r["width"]), "height": int(r["height"]),
            # what the writer expressed by a stated modelling: the job's record lists it (``approximated``)
            "approximated": [f"{o}.{f}: {m}" for o, f, m in pbrt_writer.approximations(scene)]}))
        return path

    def render(self, path, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render in independent passes (batch/backends/passes.py); returns the render record."""
        return passes_mod.render(self, path, mode, spp, out_exr, passes, seed, timeout, log_path)

    def session(self, path, mode, log):
        """One pbrt run per pass, on the exported scene as it is."""
        path = Path(path).resolve()
        sampler = scene_sampler(path)
        if sampler != SAMPLER:
            raise BackendFailure(f'{path.name} asks for Sampler "{sampler}"; the pbrt backend reads the spectral film '
                                 f'only after the "{SAMPLER}" sampler (its empty buckets\' rate is known: '
                                 "batch/backends/pbrt/backend.py)")
        try:
            size = json.loads((path.parent / SIZE_FILE).read_text())
            expect = (int(size["width"]), int(size["height"]))
            approximated = [str(a) for a in size.get("approximated") or []]
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            expect, approximated = None, []
        versions = {"pbrt_exe": str(self.pbrt)}
        return passes_mod.OneProcessPerPass(
            lambda spp, seed, out, timeout, log: self._pass(path, spp, seed, out, timeout, log, expect, versions),
            log, {"versions": versions, "approximated": approximated})

    def _pass(self, scene, spp, seed, out, timeout, log, expect, versions):
        out = Path(out).resolve()
        work = out.parent / f"{out.stem}.pbrt"
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        exr_path = work / "film.exr"
        cmd = [str(self.pbrt), "--seed", str(seed), "--spp", str(spp), "--nthreads", str(os.cpu_count() or 1),
               "--outfile", str(exr_path), str(scene)]
        before = log.tell() if hasattr(log, "tell") and log.seekable() else None
        wall = passes_mod.run_command(cmd, timeout, log, "pbrt", cwd=work)
        if not exr_path.is_file():
            raise BackendFailure(f"pbrt exited with 0 but wrote no {exr_path.name} (its --outfile)")
        names, img, bands = read_pass(exr_path, spp, expect)
        version = _banner(log, before)
        if version:
            versions["pbrt"] = version
        versions.setdefault("pbrt", "unknown (no banner read: the render had no log)")
        shutil.rmtree(work, ignore_errors=True)
        return {"names": names, "image": img.astype(np.float64), "time_s": wall, "spectral": bands,
                "info": {"versions": dict(versions)}}


def _banner(log, before):
    """pbrt's version as its banner states it ("4 (built Dec  4 2026 at 18:20:00)"), read back from
    what this pass appended to the log, or None."""
    if before is None or not getattr(log, "name", None) or log.name == os.devnull:
        return None
    try:
        with open(log.name, encoding="utf-8", errors="replace") as f:
            f.seek(before)
            m = BANNER.search(f.read(1 << 16))
    except OSError:
        return None
    return m.group(1) if m else None
