"""Index of refraction as a function of wavelength: the one place that evaluates a dielectric's
``int_ior`` (writers, validation, probes and studies all call it).

``int_ior`` in the IR is either a number (a constant IOR, as before) or a model object:
  {"type": "sellmeier", "B": [B1, B2, B3], "C": [C1, C2, C3]}
        n^2(l) = 1 + sum_i B_i l^2 / (l^2 - C_i), l in micrometres, C_i in um^2 (1 to 3 terms)
  {"type": "cauchy", "A": A, "B": B, "C": C}
        n(l) = A + B / l^2 + C / l^4, l in micrometres (B in um^2, C in um^4; C optional)
  {"type": "named", "name": "N-BK7"}          a glass of NAMED_GLASSES (Sellmeier coefficients)

A model object is always treated as dispersive (it needs the "dispersion" phenomenon and the
project's Mitsuba plugin), even when its coefficients make n constant: that is how the tests run
the plugin against Mitsuba's native dielectric. A number keeps every renderer's native dielectric.
"""
import math

import numpy as np

from ..reference_code import appearance  # the formulas (tested against SCHOTT's indices)

LAMBDA_MIN, LAMBDA_MAX = 360.0, 830.0  # nm: the renderers' range (spectra.py)
# Physical bounds (docs/scene-format.md): no transparent material has an index above MAX_IOR over
# 360-830 nm (diamond 2.4, rutile 2.9, silicon 5.6 where it is opaque); a Sellmeier B_i beyond
# MAX_SELLMEIER_B or a C_i beyond MAX_SELLMEIER_C um^2 is no glass or crystal (the shipped ones: B < 2, C < 160)
MAX_IOR = 10.0
MAX_SELLMEIER_B = 100.0
MAX_SELLMEIER_C = 1e6

# Fraunhofer lines (nm): F (hydrogen), d (helium), C (hydrogen); the Abbe number is
# v_d = (n_d - 1) / (n_F - n_C) (SCHOTT, "TIE-29: Refractive Index and Dispersion", 2016)
FRAUNHOFER_NM = {"F": 486.1327, "d": 587.5618, "C": 656.2725}

# Sellmeier coefficients (B_i, C_i in um^2) of named glasses, from the manufacturers' data:
# - N-BK7, N-SF11: SCHOTT optical glass data sheets (SCHOTT AG, "Optical Glass - Data Sheets",
#   2017-01-20): N-BK7 n_d 1.51680, n_F 1.52238, n_C 1.51432, v_d 64.17; N-SF11 n_d 1.78472,
#   v_d 25.68 (tests/probes/test_dispersion.py checks N-BK7 against these published values).
# - fused silica: I. H. Malitson, "Interspecimen Comparison of the Refractive Index of Fused
#   Silica", J. Opt. Soc. Am. 55(10), 1205-1209 (1965), eq. (1) at 20 C; Malitson gives the
#   resonance wavelengths (0.0684043, 0.1162414, 9.896161 um), whose squares are the C_i.
NAMED_GLASSES = {
    "N-BK7": {"B": [1.03961212, 0.231792344, 1.01046945], "C": [0.00600069867, 0.0200179144, 103.560653]},
    "N-SF11": {"B": [1.73759695, 0.313747346, 1.89878101], "C": [0.013188707, 0.0623068142, 155.23629]},
    "fused_silica": {"B": [0.6961663, 0.4079426, 0.8974794],
                     "C": [0.0684043 ** 2, 0.1162414 ** 2, 9.896161 ** 2]},
}
MODEL_TYPES = ("sellmeier", "cauchy", "named")


def is_model(value):
    """True for an IOR model object, False for a plain number."""
    return isinstance(value, dict)


def is_dispersive(value):
    """Whether ``value`` (an ``int_ior``) needs the dispersion phenomenon: every model object does."""
    return is_model(value)


def sellmeier(value):
    """(B, C) lists (three terms, zero-padded) of a Sellmeier or named model; None for Cauchy.
    A number n is the exact one-term Sellmeier B1 = n^2 - 1, C1 = 0."""
    if not is_model(value):
        return [float(value) ** 2 - 1.0, 0.0, 0.0], [0.0, 0.0, 0.0]
    kind = value.get("type")
    if kind == "named":
        value = NAMED_GLASSES[value["name"]]
        kind = "sellmeier"
    if kind == "sellmeier":
        b, c = [float(x) for x in value["B"]], [float(x) for x in value["C"]]
        return b + [0.0] * (3 - len(b)), c + [0.0] * (3 - len(c))
    if kind == "cauchy" and not value.get("B", 0.0) and not value.get("C", 0.0):
        return [float(value["A"]) ** 2 - 1.0, 0.0, 0.0], [0.0, 0.0, 0.0]  # a constant: exact
    return None


def ior(value, wavelengths_nm):
    """n at ``wavelengths_nm`` (float64 array) for a number or a model object."""
    wl = np.asarray(wavelengths_nm, dtype=np.float64)
    if not is_model(value):
        return np.full(wl.shape, float(value))
    if value.get("type") == "cauchy":
        return appearance.cauchy(wl, value["A"], value.get("B", 0.0), value.get("C", 0.0))
    return appearance.sellmeier(wl, *sellmeier(value))


def abbe_number(value):
    """(n_d, v_d) with the Fraunhofer F, d, C lines."""
    n_f, n_d, n_c = ior(value, [FRAUNHOFER_NM[k] for k in "FdC"])
    return float(n_d), float((n_d - 1.0) / (n_f - n_c)) if n_f != n_c else math.inf


def plugin_coefficients(value):
    """The parameters of the Mitsuba plugin (exporters/mitsuba_plugins/dispersive_dielectric.py):
    {"model": "sellmeier", "B1".."B3", "C1".."C3"} or {"model": "cauchy", "A", "B", "C"}."""
    if is_model(value) and value.get("type") == "cauchy":
        return {"model": "cauchy", "A": float(value["A"]), "B": float(value.get("B", 0.0)),
                "C": float(value.get("C", 0.0))}
    b, c = sellmeier(value)
    out = {"model": "sellmeier"}
    out.update({f"B{i + 1}": b[i] for i in range(3)})
    out.update({f"C{i + 1}": c[i] for i in range(3)})
    return out


def _finite(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def problems(value, field):
    """Yield (field, message) for an ``int_ior`` that is not a usable IOR over 360-830 nm."""
    if not is_model(value):
        if not _finite(value) or not 0 < value <= MAX_IOR:
            yield field, f"must be a finite IOR in (0, {MAX_IOR:g}], got {value!r}"
        return
    kind = value.get("type")
    if kind not in MODEL_TYPES:
        yield f"{field}.type", f"unknown IOR model {kind!r} (known: {', '.join(MODEL_TYPES)})"
        return
    if kind == "named":
        if "B" in value or "C" in value:
            # inline coefficients that exporters/inline_data.py left in place are malformed: say where
            yield from problems({"type": "sellmeier", "B": value.get("B", []), "C": value.get("C", [])}, field)
            return
        if value.get("name") not in NAMED_GLASSES:
            yield f"{field}.name", f"unknown glass {value.get('name')!r} (known: {', '.join(NAMED_GLASSES)})"
            return
    elif kind == "sellmeier":
        b, c = value.get("B", []), value.get("C", [])
        if not 1 <= len(b) <= 3 or len(b) != len(c):
            yield field, f"B and C must hold 1 to 3 coefficients each, equally many (got {len(b)} and {len(c)})"
            return
        bad = False
        for key, coeffs in (("B", b), ("C", c)):
            for i, x in enumerate(coeffs):
                if not _finite(x):
                    bad = True
                    yield f"{field}.{key}[{i}]", f"must be a finite number, got {x!r}"
                elif key == "C" and not 0 <= x <= MAX_SELLMEIER_C:
                    bad = True
                    yield f"{field}.C[{i}]", (f"must be in [0, {MAX_SELLMEIER_C:g}] (a squared resonance wavelength "
                                              f"in um^2), got {x!r}")
                elif key == "B" and abs(x) > MAX_SELLMEIER_B:
                    bad = True
                    yield f"{field}.B[{i}]", f"must be within +-{MAX_SELLMEIER_B:g} (no real glass), got {x!r}"
        if bad:
            return
    else:
        for key in ("A", "B", "C"):
            if key in value and not _finite(value[key]):
                yield f"{field}.{key}", f"must be a finite number, got {value[key]!r}"
                return
    grid = np.arange(LAMBDA_MIN, LAMBDA_MAX + 0.5, 1.0)
    with np.errstate(all="ignore"):
        n = ior(value, grid)
    bad = ~np.isfinite(n) | (n <= 0)
    if kind == "sellmeier":
        # a resonance inside the range makes n infinite or imaginary next to it
        l2 = (grid * 1e-3) ** 2
        bad |= np.any(np.abs(l2[:, None] - np.asarray(value["C"], float)[None, :]) < 1e-9, axis=1)
    if bad.any():
        yield field, (f"n(lambda) must be finite and > 0 over {LAMBDA_MIN:g}-{LAMBDA_MAX:g} nm; "
                      f"it is not at {grid[bad][0]:g} nm")
    elif n.max() > MAX_IOR:
        yield field, (f"n(lambda) reaches {n.max():.4g} at {grid[n.argmax()]:g} nm, above {MAX_IOR:g}: no "
                      f"transparent material has such an index over {LAMBDA_MIN:g}-{LAMBDA_MAX:g} nm")
