"""Spectral error models: the film integrating with another observer than the ground truth's CIE
1931 (evidence: the Lambertian patches' closed form, each observer's expected colours)."""
import numpy as np

from . import Fit, Model, least_squares, reference_model

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
def _shift_fit(ev):
    """A wavelength shift (nm) fitted on the Lambertian patches: the renderer evaluates every
    spectrum at l + shift (an off-by-one band, a table read from the wrong start); each patch's
    expected colour computed at the shift, against its measured mean and standard error."""
    from ....exporters import colorimetry, spectra
    from .. import stats
    env = ev.scene.get("environment")
    records = [r for r in ev.entry.get("probes") or [] if r.get("stat") and r["name"].startswith("lambert patch")
               and len(r["stat"]["measured"]) == 3]
    if not env or not records:
        return None
    objs = {f"lambert {o['name']}": o for o in ev.scene["objects"]}
    rows = [(objs[r["name"]]["bsdf"]["reflectance"], r["stat"]) for r in records if r["name"] in objs]
    if not rows:
        return None
    wl = spectra.cie_1931_cmfs()[0]
    radiance = env["radiance"]
    m = np.array([st["measured"] for _, st in rows])
    se = np.maximum(np.array([st["se"] for _, st in rows]), 1e-300)

    def expected(x):
        d = 0.0 if x is None else float(x[0])
        light = spectra.evaluate(radiance, wl + d)
        return np.array([colorimetry.xyz_to_srgb(colorimetry.xyz(spectra.evaluate(refl, wl + d) * light))
                         for refl, _ in rows])

    def residual(x):
        return ((m - expected(x)) / se).ravel()
    found = least_squares(residual, [[0.0], [2.0], [-2.0]], bounds=([-20.0], [20.0]), var_ratio="residuals", channels=3)
    if found is None:
        return None
    x, err, chi2 = found
    r0 = residual(None)
    ok = stats.compare_means(m.ravel(), expected(x).ravel(), se.ravel(), tests=m.size)["pass"]
    return Fit([float(x[0])], [float(err[0])], chi2, float(r0 @ r0), r0.size, 1, ok)


def _main_illuminant(scene):
    env = scene.get("environment")
    if env and env.get("radiance"):
        return env["radiance"]
    for o in scene["objects"]:
        if o.get("emitter"):
            return o["emitter"]["radiance"]
    return None


def _illuminant_factors(spec):
    """{label: the factor the render is off by} when a renderer normalises the scene's
    illuminant (to Y = 1, to 1 at 560 nm, to a peak of 1) where absolute radiance was due."""
    from ....exporters import colorimetry, spectra
    wl = spectra.cie_1931_cmfs()[0]
    v = spectra.evaluate(spec, wl)
    out = {"to Y = 1": 1 / colorimetry.spectrum_xyz(spec)[1], "to 1 at 560 nm": 1 / float(np.interp(560.0, wl, v)),
           "to a peak of 1": 1 / float(np.max(v))}
    return {k: f for k, f in out.items() if np.isfinite(f) and f > 0 and abs(np.log(f)) > 1e-3}


def _normalisation_fit(ev):
    """The reference evidence with the render a fixed factor (the illuminant normalised one of
    three ways) times the reference, the one nearest the freely fitted scale; no free parameter,
    the free scale reported beside it."""
    from .image import _uniform
    spec = _main_illuminant(ev.scene) if ev.has_reference else None
    factors = _illuminant_factors(spec) if spec else {}
    if not factors:
        return None
    free = reference_model(_uniform, starts=[[1.0]])(ev)
    if free is None or free.values[0] <= 0:
        return None
    label, factor = min(factors.items(), key=lambda kv: abs(np.log(kv[1] / free.values[0])))
    f = reference_model(lambda x, e: _uniform([factor], e))(ev)
    f.values, f.se, f.note = free.values, free.se, f"illuminant normalised {label}: factor {factor:.6g}"
    return f


MODELS = [
    Model("observer CIE 1964", FAMILY, (), "probe:lambert",
          "the film integrates with the CIE 1964 10-degree observer instead of CIE 1931 2-degree",
          _observer("cie1964"), deviation=lambda f: {"observer": "cie1964"}),
    Model("observer Mitsuba 3 (5 nm table)", FAMILY, (), "probe:lambert",
          "the film integrates with CIE 1931 sampled every 5 nm and Mitsuba 3's normalisation",
          _observer("mitsuba3"), deviation=lambda f: {"observer": "mitsuba3"}),
    Model("wavelength shift", FAMILY, ("shift nm",), "probe:lambert",
          "every spectrum evaluated at a shifted wavelength (an off-by-one band, a table's start)", _shift_fit),
    Model("illuminant normalised", FAMILY, ("factor",), "reference",
          "the illuminant normalised (to Y = 1, at 560 nm or to its peak) where absolute radiance was due",
          _normalisation_fit, deviation=lambda f: {"scale": float(f.note.rsplit(" ", 1)[-1]), "scale_se": 0.0}),
]
