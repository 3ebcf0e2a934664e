"""Band by band (issue 33): a render that comes with its spectrum (a declared renderer that writes
the spectral EXR layout, batch/spectral_passes.py) is also judged per band on every probe region
whose truth is a spectrum, so that two band errors which cancel in R, G, B (a metamer) are seen,
and a failure says which wavelengths are wrong.

Regions: the Lambertian patches of lambert.py (a chart's patches, lit plates): outgoing radiance
rho(l) L(l) everywhere on the patch; and the lone (fluorescent) sphere of fluorescence.py,
rho(l) L(l) + integral P(l_i, l) L(l_i) dl_i on every whole pixel of the sphere. Expected per band, from that spectrum and the renderer's
band model (batch/spectral_exr.py BAND_MODELS): "box", its mean over the band; "hat", its
average weighted by the band's hat function (1 at the band's wavelength, 0 at the neighbours');
"point", its value at the band's wavelength; each on a 0.1 nm grid (trapezoid rule). The end
samples' hats are halves (the spectrum is zero beyond them, as batch/spectral_exr.py reads it). Measured:
the mean of the band over the region's pixels, with the standard error of that mean from the
pixels' spread (independent draws of the same radiance, as lambert.py judges R, G, B), Student's t
with n - 1 degrees of freedom. A chart adds one test per band that pools every patch: the weighted
least-squares scale of measured over expected patches in that band, against 1 (as lambert.py's
luminance scale pools the patches' Y), which sees a band error an order of magnitude smaller
than one patch does. All tests (bands x (patches + 1)) share stats.ALPHA (Sidak).

Enough samples (issue 40): a band is judged on a region only where the t test of its mean holds
at the test's own threshold. A band's pixel values are skewed where few samples land in it (at 4
spp a 5 nm band gets a wavelength in one pixel of six: most pixels hold 0, a few a large value),
and the t statistic of a skewed mean has a heavy tail on one side: its first Edgeworth term (Hall
1992, The Bootstrap and Edgeworth Expansion, 2.6) moves the tail beyond x by
n^-1/2 (g/6) (2x^2 + 1) phi(x), where g is the pixels' skewness. Relative to the normal tail
phi(x)/x that is r = g x (2x^2 + 1) / (6 sqrt(n)); the band is judged when r <= 1 (that tail's
false-alarm rate at most twice its nominal one), i.e. with at least ``needed_pixels`` =
g^2 (x (2x^2 + 1) / 6)^2 pixels, x the normal quantile of the per-test threshold (Sidak: about
4.6 for a chart's 2350 tests, 1100 g^2 pixels). g is the region's sample skewness; with k of n
pixels holding a sample of the band and the rest 0, g^2 is about n / k, so the rule asks for about
1100 pixels with a sample in the band (compare Cochran's n > 25 g^2 for a 95 % interval, Sampling
Techniques 1977: the far tail tested here needs more). Checked by simulation (Poisson pixel values,
a band's sample counts, at alpha 1e-3 where 2e5 trials resolve the tail): at the needed count the
low tail is 2.6 times its nominal rate and the two tails together 1.4 times; at an eighth of it,
10 times (benchmarks/CALIBRATION.md, "Band checks: enough samples"). A band whose pixels do not vary (no sample at all, or all equal)
has no standard error to judge it with. A band not judged is said (``unjudged``: which bands, how
many pixels and samples they had, how many they need) and never fails; the pooled chart test of a
band uses the patches judged in that band (a weighted sum of means is no more skewed than the
most skewed of them). At the chart's default settings (620x420, 64 spp) every band of every patch
is judged; at --scale 0.125 --spp 4 none is (benchmarks/CALIBRATION.md, "Band checks: enough
samples").

Each region is one check ("bands lambert <patch>", "bands lambert chart scale") whose record names
its worst band ("patch_cyan 480-485 nm: 3.1 % low, z 6.2", ``worst``); the arrays per band
are in its ``stat`` and in the job's ``bands`` record (judge.py), which the report plots.
"""
import numpy as np

from ....exporters import spectra
from ... import spectral_exr
from ...stat_text import format_z
from .. import raycast, stats
from . import lambert
from .common import MIN_PIXELS, probe as _probe

GRID_NM = 0.1  # the grid the expected band values are integrated on
PREFIX = "bands "
RANGE_NM = (360.0, 830.0)  # where the IR defines spectra (docs/scene-format.md): bands outside are not judged


def band_edges(centres, model, width=None):
    """[(lo, hi)] the band of each channel covers: its box, or the support of its hat (the
    neighbouring centres; the end samples' hats are halves); a point sample's is its hat's, for
    naming only."""
    c = np.asarray(centres, dtype=np.float64)
    if model == "box":
        return spectral_exr.box_edges(c, width)
    lo = np.r_[c[0], c[:-1]]  # the end samples' hats are halves: zero beyond them
    hi = np.r_[c[1:], c[-1]]
    return np.stack([lo, hi], axis=-1)


def expected_bands(spectrum_fn, centres, model, width=None):
    """The value each channel of a ``model`` band film holds for a radiance spectrum
    (``spectrum_fn``: wavelengths in nm -> values)."""
    c = np.asarray(centres, dtype=np.float64)
    if model == "point":
        return np.asarray(spectrum_fn(c), dtype=np.float64)
    out = np.empty(c.size)
    for k, (lo, hi) in enumerate(band_edges(c, model, width)):
        x = np.linspace(lo, hi, max(2, int(round((hi - lo) / GRID_NM)) + 1))  # ends exact (a hat's are its peak)
        v = np.asarray(spectrum_fn(x), dtype=np.float64)
        if model == "box":
            out[k] = np.trapz(v, x) / (hi - lo)
        else:
            w = np.interp(x, c, np.eye(c.size)[k], left=0.0, right=0.0)  # zero beyond the end samples
            out[k] = np.trapz(v * w, x) / np.trapz(w, x)
    return out


def needed_pixels(skewness, threshold):
    """Pixels a region needs for the t test of a band's mean to hold at the per-test p
    ``threshold``, given the pixels' skewness (module docstring, "Enough samples")."""
    x = stats.z_critical(threshold)
    return np.ceil(np.asarray(skewness, dtype=np.float64) ** 2 * (x * (2 * x * x + 1) / 6) ** 2)


def enough_samples(px, threshold):
    """Per band of a region's pixels (n x bands): (judged, needed, with_sample): whether its t
    test holds at ``threshold`` (``needed_pixels``; a band whose pixels all hold one value has no
    standard error and is not judged), the pixels it needs, and how many hold a sample of it."""
    n = px.shape[0]
    d = px - px.mean(axis=0)
    m2 = np.mean(d**2, axis=0)
    spread = m2 > 0
    g = np.where(spread, np.mean(d**3, axis=0) / np.where(spread, m2, 1.0) ** 1.5, np.inf)
    needed = np.where(spread, np.maximum(needed_pixels(np.where(spread, g, 0.0), threshold), MIN_PIXELS), np.inf)
    return spread & (n >= needed) & (n >= MIN_PIXELS), needed, np.count_nonzero(px, axis=0)


def _worst(stat, edges):
    m, e, s = (np.asarray(stat[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    j = _judged(stat)
    if not j.any():
        return None
    z = np.where(j, (m - e) / np.maximum(s, 1e-300), 0.0)
    k = int(np.argmax(np.abs(z)))
    rel = float(m[k] / e[k] - 1.0) if e[k] else None
    return {"band": k, "band_nm": [float(edges[k][0]), float(edges[k][1])], "relative": rel, "z": float(z[k])}


def _judged(stat):
    m = np.asarray(stat["measured"])
    return np.ones(m.shape, dtype=bool) if stat.get("judged") is None else np.asarray(stat["judged"], dtype=bool)


def describe(region, worst):
    """'patch_cyan 480-485 nm: 3.1 % low, z 6.2'."""
    lo, hi = worst["band_nm"]
    rel = worst["relative"]
    how = "" if rel is None else f"{abs(rel) * 100:.3g} % {'low' if rel < 0 else 'high'}, "
    return f"{region} {lo:g}-{hi:g} nm: {how}z {format_z(worst['z'])}"


def describe_unjudged(region, unjudged, bands):
    """'patch_cyan: 90 of 94 bands not judged, too few samples (e.g. 495-500 nm: 18 pixels, 3
    with a sample in the band; the t test at this threshold needs 4800)'."""
    if not unjudged:
        return ""
    w = min(unjudged, key=lambda b: b["needed"] if b["needed"] is not None else float("inf"))  # the nearest to judged
    lo, hi = w["band_nm"]
    had = f"{w['pixels']} pixels" + (f", {w['with_sample']} with a sample in the band" if w["with_sample"] is not None else "")
    need = ("no spread to estimate its noise from" if w["needed"] is None
            else f"the t test at this threshold needs {w['needed']:.0f}")
    return f"{region}: {len(unjudged)} of {bands} bands not judged, too few samples (e.g. {lo:g}-{hi:g} nm: {had}; {need})"


def judged(sp):
    """The bands that are judged: those inside RANGE_NM (ART's film starts at 320 nm), or None."""
    centres, model, width = np.asarray(sp["wavelengths_nm"], dtype=np.float64), sp["bands"], sp.get("band_width_nm")
    if model == "hat":  # a hat spans its neighbours: inside when its own wavelength is
        inside = (centres >= RANGE_NM[0]) & (centres <= RANGE_NM[1])
    else:
        e = band_edges(centres, model, width)
        inside = (e[:, 0] >= RANGE_NM[0] - 1e-9) & (e[:, 1] <= RANGE_NM[1] + 1e-9)
    if not inside.any():
        return None
    out = dict(sp, wavelengths_nm=centres[inside], mean=np.asarray(sp["mean"])[..., inside])
    if sp.get("stderr") is not None:
        out["stderr"] = np.asarray(sp["stderr"])[..., inside]
    return out


def lambert_bands(m):
    """The Lambertian patches, band by band (module docstring); [] without a spectral render."""
    sp = m.spectral
    env = m.scene.get("environment")
    if sp is None or not env:
        return []
    sp = judged(sp)
    if sp is None:
        return []
    centres, cube, model, width = sp["wavelengths_nm"], sp["mean"], sp["bands"], sp.get("band_width_nm")
    cam, objs = m.scene["camera"], m.scene["objects"]
    h, w = cube.shape[:2]
    hits = raycast.corner_hits(cam, w, h, objs)
    found = [(objs[i], raycast.pixels_inside(cam, w, h, objs, i, margin=0.7, hits=hits)) for i in lambert._patches(m.scene)]
    found = [(o, mk) for o, mk in found if mk.sum() >= MIN_PIXELS]
    if not found:
        return []
    edges = band_edges(centres, model, width)
    nb = len(centres)
    tests = nb * (len(found) + (1 if len(found) > 1 else 0))
    threshold = stats.sidak_threshold(stats.ALPHA, tests)
    radiance = env["radiance"]
    rows, out = [], []
    for obj, mask in found:
        refl = obj["bsdf"]["reflectance"]
        expected = expected_bands(lambda x, refl=refl: spectra.evaluate(refl, x) * spectra.evaluate(radiance, x),
                                  centres, model, width)
        px = cube[mask].astype(np.float64)
        n = px.shape[0]
        measured = px.mean(axis=0)
        se = px.std(axis=0, ddof=1) / np.sqrt(n)
        tested, needed, with_sample = enough_samples(px, threshold)
        rows.append((measured, expected, se, tested))
        out.append(_region_record(f"{PREFIX}lambert {obj['name']}", obj["name"], measured, expected, se, n - 1, tests,
                                  edges, tested, needed=needed, with_sample=with_sample, pixels=n))
    if len(found) > 1:
        # per band: the WLS scale of measured over expected patches, against 1, over the patches
        # judged in that band
        M, E, S = (np.array([r[i] for r in rows]) for i in range(3))  # patches x bands
        J = np.array([r[3] for r in rows])
        wts = np.where(J, 1.0 / np.maximum(S, 1e-300) ** 2, 0.0)
        den = np.sum(wts * E**2, axis=0)
        ok = (den > 0) & np.isfinite(den)
        scale = np.where(ok, np.sum(wts * M * E, axis=0) / np.where(ok, den, 1.0), 1.0)
        se = np.where(ok, 1.0 / np.sqrt(np.where(ok, den, 1.0)), 0.0)
        out.append(_region_record(f"{PREFIX}lambert chart scale", "chart", scale, np.ones(nb), se, None, tests, edges,
                                  ok, patches=len(found), patches_judged=J.sum(axis=0).tolist()))
    return out


def _failing_bands(stat, edges):
    """Every judged band whose test fails, worst first: [{"band", "band_nm", "relative", "z"}]."""
    m, e, s = (np.asarray(stat[k], dtype=np.float64) for k in ("measured", "expected", "se"))
    j = _judged(stat)
    z = np.where(j, (m - e) / np.maximum(s, 1e-300), 0.0)
    p = np.where(j, np.atleast_1d(stats.two_sided_p(z, stat.get("dof"))), 1.0)
    bad = [int(k) for k in np.argsort(-np.abs(z)) if p[k] < stat["threshold"]]
    return [{"band": k, "band_nm": [float(edges[k][0]), float(edges[k][1])],
             "relative": float(m[k] / e[k] - 1.0) if e[k] else None, "z": float(z[k])} for k in bad]


def _region_record(name, region, measured, expected, se, dof, tests, edges, tested, needed=None, with_sample=None,
                   **extra):
    stat = stats.compare_means(measured, expected, se, dof=dof, tests=tests, judged=tested)
    pixels = extra.get("pixels")
    unjudged = [{"band": int(k), "band_nm": [float(edges[k][0]), float(edges[k][1])], "pixels": pixels,
                 "with_sample": None if with_sample is None else int(with_sample[k]),
                 "needed": None if needed is None or not np.isfinite(needed[k]) else float(needed[k]),
                 **({} if "patches_judged" not in extra else {"patches_judged": int(extra["patches_judged"][k])})}
                for k in np.flatnonzero(~np.asarray(tested, dtype=bool))]
    if needed is None:  # the pooled test: a band no patch could judge
        unjudged = [dict(b, needed=None) for b in unjudged]
    note = describe_unjudged(region, unjudged, len(edges))
    worst = _worst(stat, edges)
    if worst is None:
        return _probe(name, None, None, None, "relative", None, stat=stat, worst={"text": note}, failing_bands=[],
                      unjudged=unjudged, unjudged_text=note, region=region, **extra)
    failing = _failing_bands(stat, edges)
    text = describe(region, worst)
    if len(failing) > 1:  # the other failing bands, nm and size only: "also 550-555 nm +1.9 %"
        text += "; also " + ", ".join(
            f"{b['band_nm'][0]:g}-{b['band_nm'][1]:g} nm" + ("" if b["relative"] is None else f" {b['relative'] * 100:+.1f} %")
            for b in failing[1:4]) + (f" and {len(failing) - 4} more" if len(failing) > 4 else "")
    return _probe(name, float(np.asarray(expected)[worst["band"]]), float(np.asarray(measured)[worst["band"]]),
                  worst["relative"], "relative", stat["pass"], z=stat["z"], stat=stat,
                  worst=dict(worst, text=text), failing_bands=failing, unjudged=unjudged, unjudged_text=note,
                  region=region, **extra)


def lone_sphere_bands(m):
    """The lone (fluorescent) Lambertian sphere of fluorescence.py, band by band: rho L + integral
    P L through the band model, on the sphere's whole pixels (their spread gives the standard
    error); [] without a spectral render or such a sphere."""
    from . import fluorescence
    sp = m.spectral
    env, objs = m.scene.get("environment"), m.scene["objects"]
    if sp is None or not fluorescence.applies(m.scene):
        return []
    sp = judged(sp)
    if sp is None:
        return []
    centres, cube, model, width = sp["wavelengths_nm"], sp["mean"], sp["bands"], sp.get("band_width_nm")
    h, w = cube.shape[:2]
    mask = raycast.pixels_inside(m.scene["camera"], w, h, objs, 0)
    if mask.sum() < MIN_PIXELS:
        return []
    obj = objs[0]
    expected = expected_bands(lambda x: fluorescence.expected_radiance(obj["bsdf"], env["radiance"], x),
                              centres, model, width)
    px = cube[mask].astype(np.float64)
    n = px.shape[0]
    tested, needed, with_sample = enough_samples(px, stats.sidak_threshold(stats.ALPHA, len(centres)))
    return [_region_record(f"{PREFIX}lone sphere {obj['name']}", obj["name"], px.mean(axis=0), expected,
                           px.std(axis=0, ddof=1) / np.sqrt(n), n - 1, len(centres), band_edges(centres, model, width),
                           tested, needed=needed, with_sample=with_sample, pixels=n)]


PROBES = [lambert_bands, lone_sphere_bands]


def record(entry_probes, sp):
    """The job's ``bands`` record (the report's spectra; docs/backends.md, "Spectral images") from its band
    checks, or None without a spectral render."""
    sp = None if sp is None else judged(sp)
    if sp is None:
        return None
    centres, model, width = sp["wavelengths_nm"], sp["bands"], sp.get("band_width_nm")
    edges = band_edges(centres, model, width)
    regions = []
    for p in entry_probes:
        if not p["name"].startswith(PREFIX) or not p.get("stat"):
            continue
        st = p["stat"]
        j = _judged(st)
        z = ((np.asarray(st["measured"]) - np.asarray(st["expected"])) / np.maximum(np.asarray(st["se"]), 1e-300))
        # a band not judged has no z and no standard error to draw (None: the report leaves them out)
        regions.append({"probe": p["name"], "region": p.get("region"), "check": p["name"],
                        "measured": st["measured"], "se": [float(v) if ok else None for v, ok in zip(st["se"], j)],
                        "expected": st["expected"], "z": [float(x) if ok else None for x, ok in zip(z, j)],
                        "judged": j.tolist(), "pass": p["pass"], "worst": p.get("worst"),
                        "unjudged": p.get("unjudged_text") or None})
    threshold = next((p["stat"]["threshold"] for p in entry_probes if p["name"].startswith(PREFIX) and p.get("stat")), None)
    return {"model": model, "source": sp.get("source", "declared"), "centres_nm": [float(c) for c in centres],
            "edges_nm": None if model == "point" else [[float(a), float(b)] for a, b in edges],
            "band_width_nm": width, "preview": sp.get("preview"), "regions": regions, "threshold": threshold,
            "alpha": stats.ALPHA}
