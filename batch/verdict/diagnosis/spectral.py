"""Spectral error models: the film integrating with another observer than the ground truth's CIE
1931 (evidence: the Lambertian patches' closed form, each observer's expected colours)."""
import numpy as np

from . import Fit, Model

FAMILY = "spectral"


def _patch_chi2(records):
    """(chi2, residual count, every test passes) over probe stats (measured, expected, se)."""
    chi2, n, ok = 0.0, 0, True
    for stat in records:
        m, e, s = (np.asarray(stat[k], dtype=np.float64) for k in ("measured", "expected", "se"))
        chi2 += float(np.sum(((m - e) / np.maximum(s, 1e-300)) ** 2))
        n += m.size
        ok = ok and bool(stat["pass"])
    return chi2, n, ok


def _lambert_records(ev, name):
    """The Lambertian probe records with their verdict under observer ``name``: the verdict's own
    when it computed that observer (a known deviation's), else the probe again with every
    catalogue observer at once (once per render; not for a quick diagnosis)."""
    from ..probes import Measurement, lambert
    own = [r for r in ev.entry.get("probes") or [] if r.get("stat") and r["name"].startswith("lambert ")]
    if own and all(name in (r.get("alternatives") or {}) for r in own):
        return own
    if ev.quick:
        return None
    if "lambert" not in ev.cache:
        m = Measurement(ev.scene, ev.names, ev.image, ev.stderr, None, ev.passes, OBSERVERS)
        ev.cache["lambert"] = [r for r in lambert.patches(m) if r.get("stat")]
    return ev.cache["lambert"]


def _observer(name):
    def fit(ev):
        if "R" not in ev.names:
            return None
        records = _lambert_records(ev, name)
        if not records:
            return None
        chi2_none, n, _ = _patch_chi2([r["stat"] for r in records])
        chi2, _, ok = _patch_chi2([r["alternatives"][name] for r in records])
        return Fit([], [], chi2, chi2_none, n, 0, ok)
    return fit


OBSERVERS = ("cie1964", "mitsuba3")
MODELS = [
    Model("observer CIE 1964", FAMILY, (), "probe:lambert",
          "the film integrates with the CIE 1964 10-degree observer instead of CIE 1931 2-degree",
          _observer("cie1964"), deviation=lambda f: {"observer": "cie1964"}),
    Model("observer Mitsuba 3 (5 nm table)", FAMILY, (), "probe:lambert",
          "the film integrates with CIE 1931 sampled every 5 nm and Mitsuba 3's normalisation",
          _observer("mitsuba3"), deviation=lambda f: {"observer": "mitsuba3"}),
]
