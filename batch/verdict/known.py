"""Known deviations: a reviewed list (known_deviations.toml at the repository root) of where a
renderer differs from the ground truth, each with its evidence and explanation.

A deviation names where it applies (scene, backend and mode patterns, renderer versions), which
checks it explains (patterns over check names: probe names, or "noise test"), and a model of the
deviation: the renderer's value is ``scale`` times the expected one (with the uncertainty
``scale_se`` of that factor), the expected one computed, if ``observer`` is given, with that
observer (exporters/colorimetry.py: how the renderer's film integrates spectra) instead of the CIE
1931 ground truth. For the noise test, "expected" is the reference as that observer's film would
have seen it: the reference plus its observer layer (batch/verdict/observer_layers.py, rendered from
the same paths as the CMF-film reference; the reference's own observer needs none); a reference
without a layer for the observer cannot re-judge the noise test, which then keeps its verdict. A
check is re-judged under the model:

  plain check fails, check under the model passes  -> known   (fails exactly as recorded)
  plain check passes, check under the model fails  -> fixed   (the recorded deviation would have
                                                               been seen, and is gone)
  both pass                                        -> ok      (too little power to tell)
  both fail                                        -> failed  (a new failure)

so a deviation that grows, shrinks or changes form is a failure, not a known one.
"""
import fnmatch
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

DEFAULT_FILE = Path(__file__).resolve().parents[2] / "known_deviations.toml"
REQUIRED = ("id", "backend", "checks", "evidence", "explanation", "date")


class KnownDeviationsError(ValueError):
    pass


@dataclass
class Deviation:
    id: str
    backend: str
    checks: list
    evidence: str
    explanation: str
    date: str
    scenes: list = field(default_factory=lambda: ["*"])
    modes: list = field(default_factory=lambda: ["*"])
    versions: list = field(default_factory=lambda: ["*"])
    films: list = field(default_factory=lambda: ["*"])  # the render's film (Mitsuba: rgb or cmf; "" for others)
    scale: float = 1.0
    scale_se: float = 0.0
    observer: str = None

    def applies(self, scene, backend, mode, version, film=None):
        def any_match(value, patterns):
            return any(fnmatch.fnmatchcase(str(value or ""), p) for p in patterns)
        return (fnmatch.fnmatchcase(backend, self.backend) and any_match(scene, self.scenes)
                and any_match(mode, self.modes) and any_match(version, self.versions)
                and any_match(film, self.films))

    def explains(self, check_name):
        return any(fnmatch.fnmatchcase(check_name, p) for p in self.checks)


def load(path=None):
    """The deviations of ``path`` (default: the repository's file); [] if there is no file."""
    path = Path(path or DEFAULT_FILE)
    if not path.is_file():
        return []
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise KnownDeviationsError(f"{path}: {exc}") from exc
    out = []
    for k, entry in enumerate(data.get("deviation", [])):
        missing = [f for f in REQUIRED if f not in entry]
        if missing:
            raise KnownDeviationsError(f"{path}: deviation {entry.get('id', k)} lacks {', '.join(missing)}")
        unknown = set(entry) - set(Deviation.__dataclass_fields__)
        if unknown:
            raise KnownDeviationsError(f"{path}: deviation {entry['id']} has unknown fields {sorted(unknown)}")
        dev = Deviation(**entry)
        if dev.observer is not None:
            from ...exporters import colorimetry
            if dev.observer not in colorimetry.OBSERVERS:
                raise KnownDeviationsError(f"{path}: deviation {dev.id}: unknown observer {dev.observer!r} "
                                           f"(known: {', '.join(colorimetry.OBSERVERS)})")
        out.append(dev)
    return out


def applicable(deviations, entry):
    """The deviations that apply to one job record (scene, backend, mode, renderer version)."""
    version = " ".join(f"{k} {v}" for k, v in sorted((entry.get("versions") or {}).items()))
    film = entry.get("film") or ("rgb" if entry["backend"] == "mitsuba" else "")  # a record from before films
    return [d for d in deviations if d.applies(entry["scene"], entry["backend"], entry.get("mode"), version, film)]
