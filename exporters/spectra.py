"""Spectra of the scene IR and their evaluation in numpy.

Kinds (the IR's JSON form, see schema/scene.schema.json):
  {"type": "constant", "value": v}
  {"type": "sampled", "wavelengths": [nm...], "values": [...]}   linear interpolation
  {"type": "named", "name": "cie_d65", "scale": s}          illuminants (cie_*) and
  {"type": "named", "name": "colorchecker_red"}             ColorChecker reflectances
  {"type": "blackbody", "temperature": K, "scale": s}

Radiometric normalisation (identical in every writer): a named illuminant or a blackbody
with scale s is s * S(l) / S(560 nm), i.e. 1.0 at 560 nm, in the renderer's radiance unit.
Named reflectances (the ColorChecker patches, N. Ohta's data) are used as measured, times s.
ART's raw CIE tables (D65 = 100 at 560 nm) therefore take s / 100; Mitsuba's own ``d65``
plugin is not used (it is 1.0101 at 560 nm), the table is written out instead.

Every spectrum is defined over the renderer range 360-830 nm: a sampled or tabulated
spectrum is padded with its edge values, because Mitsuba returns 0 outside a spectrum's
range while it samples wavelengths over 360-830 nm.
"""
import json
import math
from functools import lru_cache
from pathlib import Path

import numpy as np

LAMBDA_MIN, LAMBDA_MAX = 360.0, 830.0
NORMALISATION_NM = 560.0
DATA_DIR = Path(__file__).resolve().parent / "data"

# Conductors that the IR names; each writer maps the name to its renderer's table
# (Mitsuba: data/ior/<name>.{eta,k}.spd, ART: <NAME>_MATERIAL).
NAMED_CONDUCTORS = ("Ag", "Al", "Au", "Be", "Cr", "Cu", "Cu2O", "CuO", "Hg", "Ir", "Li",
                    "Mo", "Rh", "Se", "Ta", "Te", "W", "V_palik", "Ni_palik")


class SpectrumError(ValueError):
    """A spectrum that cannot be evaluated; ``field`` is the offending key."""

    def __init__(self, field, message):
        super().__init__(message)
        self.field = field


@lru_cache(maxsize=1)
def _named_tables():
    """{name: (table, normalised at 560 nm)} of every named spectrum."""
    tables = {n: (t, True) for n, t in
              json.loads((DATA_DIR / "cie_illuminants.json").read_text())["illuminants"].items()}
    cc = json.loads((DATA_DIR / "colorchecker_n_ohta.json").read_text())
    tables.update({n: (t, False) for n, t in cc["reflectances"].items()})
    return tables


def named_spectra():
    """Names accepted by {"type": "named"}."""
    return sorted(_named_tables())


def colorchecker_patches():
    """The 24 ColorChecker patch names in chart order (row by row, dark skin first)."""
    return json.loads((DATA_DIR / "colorchecker_n_ohta.json").read_text())["order"]


@lru_cache(maxsize=1)
def cie_1931_cmfs():
    """(wavelengths, x_bar, y_bar, z_bar) as arrays, 360-830 nm at 1 nm."""
    d = json.loads((DATA_DIR / "cie_1931_2deg_cmfs.json").read_text())
    return tuple(np.asarray(d[k], dtype=np.float64) for k in ("wavelengths", "x_bar", "y_bar", "z_bar"))


def _planck(wl_nm, temperature):
    """Planck's law, spectral radiance per unit wavelength (unnormalised)."""
    h, c, k = 6.62607015e-34, 2.99792458e8, 1.380649e-23
    wl = np.asarray(wl_nm, dtype=np.float64) * 1e-9
    return (2 * h * c**2 / wl**5) / np.expm1(h * c / (wl * k * temperature))


def _interp_padded(wl, xs, ys):
    """Linear interpolation, constant (edge value) extrapolation."""
    return np.interp(np.asarray(wl, dtype=np.float64), np.asarray(xs, float), np.asarray(ys, float))


def evaluate(spec, wavelengths):
    """Values of an IR spectrum (a dict) at ``wavelengths`` in nm, as float64 array."""
    wl = np.asarray(wavelengths, dtype=np.float64)
    kind = spec.get("type")
    if kind == "constant":
        return np.full(wl.shape, float(spec["value"]))
    if kind == "sampled":
        return _interp_padded(wl, spec["wavelengths"], spec["values"])
    if kind == "named":
        tables = _named_tables()
        name = spec.get("name")
        if name not in tables:
            raise SpectrumError("name", f"unknown named spectrum {name!r} (known: {', '.join(sorted(tables))})")
        t, normalised = tables[name]
        ref = _interp_padded(NORMALISATION_NM, t["wavelengths"], t["values"]) if normalised else 1.0
        return spec.get("scale", 1.0) * _interp_padded(wl, t["wavelengths"], t["values"]) / ref
    if kind == "blackbody":
        temp = float(spec["temperature"])
        return spec.get("scale", 1.0) * _planck(wl, temp) / _planck(NORMALISATION_NM, temp)
    raise SpectrumError("type", f"unknown spectrum type {kind!r}")


def tabulate(spec, step=5.0, lo=LAMBDA_MIN):
    """(wavelengths, values) covering lo-830 nm (360 nm unless a fluorescent scene needs its
    light and reflectances at excitation wavelengths below: exporters/fluorescence.py); keeps a
    sampled spectrum's own points."""
    grid = np.arange(lo, LAMBDA_MAX + 0.5 * step, step)
    if spec.get("type") == "sampled":
        inner = [w for w in spec["wavelengths"] if lo < w < LAMBDA_MAX]
        grid = np.unique(np.concatenate([[lo], inner, [LAMBDA_MAX]]))
    elif spec.get("type") == "named":
        t = _named_tables()[spec["name"]][0]
        inner = [w for w in t["wavelengths"] if lo < w < LAMBDA_MAX]
        grid = np.unique(np.concatenate([[lo], inner, [LAMBDA_MAX]]))
    return grid, evaluate(spec, grid)


def is_constant(spec):
    return spec.get("type") == "constant"


def check(spec, where, allow_negative=False):
    """Yield (field, message) problems of one spectrum dict; ``where`` prefixes the field."""
    if not isinstance(spec, dict):
        yield where, f"must be a spectrum object, got {spec!r}"
        return
    kind = spec.get("type")
    def bad(x):
        return not isinstance(x, (int, float)) or isinstance(x, bool) or math.isnan(x) or math.isinf(x)
    if kind == "constant":
        v = spec.get("value")
        if bad(v):
            yield f"{where}.value", f"must be a finite number, got {v!r}"
        elif v < 0 and not allow_negative:
            yield f"{where}.value", f"must be >= 0, got {v}"
    elif kind == "sampled":
        wls, vals = spec.get("wavelengths", []), spec.get("values", [])
        if len(wls) != len(vals) or len(wls) < 1:
            yield where, f"wavelengths and values must be non-empty and of equal length ({len(wls)} vs {len(vals)})"
            return
        for i, (w, v) in enumerate(zip(wls, vals)):
            if bad(w) or w <= 0:
                yield f"{where}.wavelengths[{i}]", f"must be a positive finite number, got {w!r}"
            if bad(v) or (v < 0 and not allow_negative):
                yield f"{where}.values[{i}]", f"must be a finite number >= 0, got {v!r}"
        if any(b <= a for a, b in zip(wls, wls[1:])):
            yield f"{where}.wavelengths", "must be strictly increasing"
    elif kind == "named":
        if spec.get("name") not in _named_tables():
            yield f"{where}.name", f"unknown named spectrum {spec.get('name')!r} (known: {', '.join(named_spectra())})"
        s = spec.get("scale", 1.0)
        if bad(s) or s < 0:
            yield f"{where}.scale", f"must be a finite number >= 0, got {s!r}"
    elif kind == "blackbody":
        t = spec.get("temperature")
        if bad(t) or t <= 0:
            yield f"{where}.temperature", f"must be a positive finite temperature in kelvin, got {t!r}"
        s = spec.get("scale", 1.0)
        if bad(s) or s < 0:
            yield f"{where}.scale", f"must be a finite number >= 0, got {s!r}"
    else:
        yield f"{where}.type", f"unknown spectrum type {kind!r} (constant, sampled, named, blackbody)"
