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
without a layer for the observer cannot re-judge the noise test, which then keeps its verdict.
``shadowing`` ("separable" or "height-correlated") models a renderer whose microfacets have another
Smith shadowing-masking than the IR's separable G1 G1 (pbrt-v4 has only the height-correlated G2):
the GGX probe judges every plate with the other form too (its ``alternatives``, key
probes/ggx.py ``shadowing_key``), and a deviation with ``shadowing`` re-judges that result; no other
check carries the form (the noise test's reference was rendered with the IR's), so such a deviation
explains the GGX probe's checks only, and may not name an observer as well. A check is re-judged
under the model:

  plain check fails, check under the model passes  -> known   (fails exactly as recorded)
  plain check passes, check under the model fails  -> fixed   (the recorded deviation would have
                                                               been seen, and is gone)
  both pass                                        -> ok      (too little power to tell)
  both fail                                        -> failed  (a new failure)

so a deviation that grows, shrinks or changes form is a failure, not a known one.
"""
import datetime
import fnmatch
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

DEFAULT_FILE = Path(__file__).resolve().parents[2] / "known_deviations.toml"
REQUIRED = ("id", "backend", "checks", "evidence", "explanation", "date")
SHADOWING_FORMS = ("separable", "height-correlated")  # as probes/ggx.py SHADOWING_FORMS (a test keeps them equal)


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
    shadowing: str = None  # the renderer's Smith form, judged by the GGX probe (module docstring)

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
    entries = data.get("deviation", [])
    if not isinstance(entries, list):
        raise KnownDeviationsError(f"{path}: deviation must be an array of tables ([[deviation]]), not {entries!r}")
    for k, entry in enumerate(entries):
        if not isinstance(entry, dict):
            raise KnownDeviationsError(f"{path}: deviation #{k + 1} must be a table ([[deviation]]), not {entry!r}")
        missing = [f for f in REQUIRED if f not in entry]
        if missing:
            raise KnownDeviationsError(f"{path}: deviation {_label(entry.get('id'), k)} lacks {', '.join(missing)}")
        unknown = set(entry) - set(Deviation.__dataclass_fields__)
        if unknown:
            raise KnownDeviationsError(f"{path}: deviation {_label(entry['id'], k)} has unknown fields {sorted(unknown)}")
        problem = _problem(entry)
        if problem:
            field_name, why = problem
            raise KnownDeviationsError(f"{path}: deviation {_label(entry.get('id'), k)}, field {field_name}: {why}")
        out.append(Deviation(**entry))
    return out


def _label(dev_id, k):
    """How an entry is named in a message: its id (shown as written), else its place in the file."""
    return repr(dev_id) if isinstance(dev_id, str) and dev_id.strip() else f"#{k + 1} (no usable id)"


def _number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _problem(entry):
    """(field, why) of the first field of a deviation entry that is not as the model needs it, or
    None. The model's parameters are a factor on the expected value and its uncertainty: ``scale``
    finite and > 0 (0 or a negative factor is no renderer's light, NaN compares false with
    everything), ``scale_se`` finite, >= 0 and below ``scale`` (an uncertainty as large as the
    factor admits a black render: the model would explain anything); ``observer`` one of
    exporters/colorimetry.py's; the texts non-empty strings; the patterns lists of strings (a bare
    string would be matched character by character)."""
    for name in ("id", "backend", "evidence", "explanation"):
        if not isinstance(entry[name], str) or not entry[name].strip():
            return name, f"must be a non-empty string, not {entry[name]!r}"
    if not isinstance(entry["date"], (str, datetime.date)) or not str(entry["date"]).strip():
        return "date", f"must be a date (\"2026-11-22\"), not {entry['date']!r}"
    for name in ("checks", "scenes", "modes", "versions", "films"):
        if name in entry:
            value = entry[name]
            if not isinstance(value, list) or not value or not all(isinstance(p, str) for p in value):
                return name, f"must be a non-empty list of patterns (strings), not {value!r}"
    scale = entry.get("scale", 1.0)
    if not _number(scale) or not math.isfinite(scale) or scale <= 0:
        return "scale", f"must be a finite number > 0 (the renderer's value over the expected one), not {scale!r}"
    scale_se = entry.get("scale_se", 0.0)
    if not _number(scale_se) or not math.isfinite(scale_se) or scale_se < 0:
        return "scale_se", f"must be a finite number >= 0 (the uncertainty of scale), not {scale_se!r}"
    if scale_se >= scale:
        return "scale_se", (f"{scale_se!r} is not below scale {scale!r}: a factor uncertain by as much as itself "
                            "admits a black render, and would explain any deviation")
    observer = entry.get("observer")
    if observer is not None:
        from ...exporters import colorimetry
        if not isinstance(observer, str) or observer not in colorimetry.OBSERVERS:
            return "observer", f"unknown observer {observer!r} (known: {', '.join(colorimetry.OBSERVERS)})"
    shadowing = entry.get("shadowing")
    if shadowing is not None:
        if shadowing not in SHADOWING_FORMS:
            return "shadowing", f"unknown Smith form {shadowing!r} (known: {', '.join(SHADOWING_FORMS)})"
        if observer is not None:
            return "shadowing", "a deviation carries an observer or a shadowing form, not both (no check judges both)"
    return None


def applicable(deviations, entry):
    """The deviations that apply to one job record (scene, backend, mode, renderer version)."""
    version = " ".join(f"{k} {v}" for k, v in sorted((entry.get("versions") or {}).items()))
    film = entry.get("film") or ("rgb" if entry["backend"] == "mitsuba" else "")  # a record from before films
    return [d for d in deviations if d.applies(entry["scene"], entry["backend"], entry.get("mode"), version, film)]
