"""Renderer backends. Each one exports an IR scene to its format, picks the cheapest mode that
models what the scene needs (or says plainly that it cannot), and renders to EXR.

The interface every backend implements (plain objects; no base class needed):
    name, formats                      "mitsuba", ("mitsuba",): the export formats it renders
    options                            the constructor's keyword arguments (plain data: a job
                                       rebuilds the backend from its name and these on any worker)
    availability() -> (bool, reason)   whether it can run here, and why not
    mode_for(scene) -> (mode, None) | (None, reason)
                                       the cheapest mode that models the scene, or why it cannot
                                       (naming object and field where one is to blame)
    export(scene, out_dir) -> path     the file the renderer reads
    render(path, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None) -> info
        writes the mean image (R, G, B, then any further channels such as S0.R ... S3.B) and, with
        passes >= 2, the standard error of that mean per pixel as stderr.<channel> from the
        pass-to-pass spread; info holds variant/mode, spp, passes, seed, time_s (render only),
        wall_s, resolution, channels, versions (an RGB backend adds ``approximated``: what an
        ``rgb-approx`` mode rendered differently). Raises BackendFailure.
Rendering goes through one pass loop (batch/backends/passes.py): a backend's ``session(path, mode,
log)`` renders one pass at a time (``render`` above is that loop). Renderers declared in TOML
(batch/backends/command.py) are backends like these, built from their declaration.
Constructors take ``executable`` (and: Mitsuba ``force_variant``, ART ``ggx``, Cycles and LuxCore
``approximate``, from --approximate; pbrt-v4 takes nothing more).
"""
from .art.backend import ArtBackend
from .command import CommandBackend
from .cycles.backend import CyclesBackend
from .luxcore.backend import LuxCoreBackend
from .mitsuba.backend import MitsubaBackend
from .pbrt.backend import PbrtBackend
from .passes import BackendFailure  # noqa: F401 - BackendFailure is part of the interface

# spectral backends first; the RGB ones (Cycles, LuxCore) measure what reducing spectra to RGB costs
BACKENDS = {"mitsuba": MitsubaBackend, "art": ArtBackend, "pbrt": PbrtBackend, "cycles": CyclesBackend, "luxcore": LuxCoreBackend}
# Groups for -r: the spectral renderers are the default (the regression run against spectral ground
# truth); the RGB ones measure what RGB rendering gets wrong, so their verdicts against spectral
# references fail by design on spectral scenes (benchmarks/RGB.md) and they run when asked for.
GROUPS = {"spectral": ["mitsuba", "art", "pbrt"], "rgb": ["cycles", "luxcore"], "all": list(BACKENDS)}
DEFAULT = GROUPS["spectral"]


def groups(declared=None):
    """The groups of -r: the built-in ones, each declared renderer's ``groups``, and ``declared``
    (every declared renderer)."""
    out = {g: list(m) for g, m in GROUPS.items()}
    for name, decl in (declared or {}).items():
        for g in ["declared", *decl.get("groups", [])]:
            out.setdefault(g, [])
            if name not in out[g]:
                out[g].append(name)
    return out


def known_names(declared=None):
    """Every name -r accepts: backends, declared renderers and groups."""
    return [*BACKENDS, *(declared or {}), *groups(declared)]


def expand(names, declared=None):
    """Backend names from -r values (names or groups), in order, without repeats."""
    table = groups(declared)
    out = []
    for n in names or table["spectral"]:
        for b in table.get(n, [n]):
            if b not in out:
                out.append(b)
    return out


def get(name, **options):
    """The backend ``name`` rebuilt from its options (plain data: a job carries them); a declared
    renderer's options hold its declaration (batch/backends/command.py)."""
    if "declaration" in options:
        return CommandBackend(name, **options)
    if name not in BACKENDS:
        raise KeyError(f"unknown backend {name!r} (known: {', '.join(BACKENDS)})")
    return BACKENDS[name](**options)
