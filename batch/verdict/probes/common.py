"""What every probe shares: its record and the smallest region it can be measured on."""
import numpy as np

MIN_PIXELS = 4


def probe(name, expected, measured, error, unit, passed, **extra):
    as_list = lambda v: None if v is None else (np.asarray(v, dtype=float).round(8).tolist() if np.ndim(v) else float(v))
    out = {"name": name, "expected": as_list(expected), "measured": as_list(measured),
           "error": None if error is None else float(error), "unit": unit,
           "pass": None if passed is None else bool(passed)}
    out.update(extra)
    return out
