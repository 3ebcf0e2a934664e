"""A spectral job's band record (metrics.json ``bands``, issue 33) as the report shows it: read
defensively (a job without one, or with a malformed one, shows nothing new; a region whose arrays
do not match the band centres is left out), each probe region's worst band in words (summary,
JUnit, the page), and each region's spectrum as a small plot (report.html draws it as inline SVG
from the numbers here: measured per band with its 95 % interval, +-1.96 standard errors, against
the expected spectrum; the bands that fail the Sidak-corrected threshold marked).

The record (contract between the verdict and the report, issue 33): {"model", "source",
"centres_nm": [...], "edges_nm": [[lo, hi], ...] or null, "preview": "spectral_preview.exr" or
null, "regions": [{"probe", "region", "check", "measured", "se", "expected", "z", "pass",
"worst": {"band_nm": [lo, hi], "relative", "z"}}, ...], "threshold", "alpha"}. Long arrays come
back from probe_arrays-*.npz through batch/records.py ``read`` (the page's and summary's loader),
so every list here is a list of numbers or None."""
import math
from statistics import NormalDist

from ..stat_text import format_z

Z95 = 1.959963984540054  # two-sided 95 %: the plotted interval is measured +- Z95 standard errors
PLOT_W, PLOT_H = 240, 130  # one region's plot, px (SVG user units)
PAD_L, PAD_R, PAD_T, PAD_B = 38, 8, 16, 22  # margins: y labels left, x labels below, title above


def _num(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _numbers(x, n):
    """``x`` as n floats (NaN where a value is missing or not a number), or None when it is not a
    list of length n."""
    if not isinstance(x, list) or len(x) != n:
        return None
    return [float(v) if _num(v) else math.nan for v in x]


def _edges(b, centres):
    """The bands' [lo, hi] in nm: the record's ``edges_nm`` when it is one finite pair per band,
    else midway between neighbouring centres, the outer ones half a spacing out."""
    e = b.get("edges_nm")
    if isinstance(e, list) and len(e) == len(centres) and all(
            isinstance(p, list) and len(p) == 2 and all(_num(v) for v in p) and p[0] < p[1] for p in e):
        return [(float(p[0]), float(p[1])) for p in e]
    mids = [(a + c) / 2 for a, c in zip(centres, centres[1:])]
    return list(zip([centres[0] - (mids[0] - centres[0])] + mids, mids + [centres[-1] + (centres[-1] - mids[-1])]))


def record(run):
    """The run's band record, checked: {"model", "source", "centres", "edges", "preview",
    "threshold", "alpha", "z_crit", "regions": [...]} or None when the run has none usable. Each
    region: probe, region, check (text), measured, se, expected, z (n floats, NaN where missing;
    z computed from the others when the record has none), pass (bool or None), worst (band index
    or None), failing (band indices with |z| above the threshold's)."""
    b = run.get("bands") if isinstance(run, dict) else None
    c = b.get("centres_nm") if isinstance(b, dict) else None
    if not (isinstance(c, list) and len(c) >= 2 and all(_num(v) for v in c)
            and all(x < y for x, y in zip(c, c[1:]))):
        return None
    centres = [float(v) for v in c]
    n = len(centres)
    threshold = b.get("threshold") if _num(b.get("threshold")) and 0 < b["threshold"] < 1 else None
    z_crit = NormalDist().inv_cdf(1 - threshold / 2) if threshold else None
    regions = []
    for r in b.get("regions") if isinstance(b.get("regions"), list) else ():
        if not isinstance(r, dict):
            continue
        m, se, e = (_numbers(r.get(k), n) for k in ("measured", "se", "expected"))
        if m is None or e is None:
            continue
        se = se or [math.nan] * n
        z = _numbers(r.get("z"), n) or [(a - x) / s if s > 0 else math.nan for a, x, s in zip(m, e, se)]
        failing = [i for i, v in enumerate(z) if z_crit is not None and math.isfinite(v) and abs(v) > z_crit]
        finite = [i for i, v in enumerate(z) if math.isfinite(v)]
        worst = _worst_index(r.get("worst"), _edges(b, centres)) if isinstance(r.get("worst"), dict) else None
        if worst is None and finite:
            worst = max(finite, key=lambda i: abs(z[i]))
        regions.append({"probe": _text(r.get("probe")), "region": _text(r.get("region")), "check": _text(r.get("check")),
                        "measured": m, "se": se, "expected": e, "z": z,
                        "pass": r.get("pass") if isinstance(r.get("pass"), bool) else None,
                        "worst": worst, "failing": failing, "record_worst": _dict(r.get("worst"))})
    preview = b.get("preview") if isinstance(b.get("preview"), str) and b.get("preview") else None
    return {"model": _text(b.get("model")), "source": _text(b.get("source")), "centres": centres,
            "edges": _edges(b, centres), "preview": preview, "threshold": threshold,
            "alpha": b.get("alpha") if _num(b.get("alpha")) else None, "z_crit": z_crit, "regions": regions}


def _text(x):
    return "" if x is None else str(x)


def _dict(x):
    return x if isinstance(x, dict) else {}


def _worst_index(worst, edges):
    """The band a record's ``worst`` names (its band_nm), or None."""
    nm = worst.get("band_nm")
    if isinstance(nm, list) and len(nm) == 2 and all(_num(v) for v in nm):
        mid = (nm[0] + nm[1]) / 2
        for i, (lo, hi) in enumerate(edges):
            if lo <= mid <= hi:
                return i
    return None


def band_text(lo, hi):
    """``480-490 nm`` (whole nm where the edges are whole)."""
    f = (lambda v: f"{v:.0f}") if all(abs(v - round(v)) < 1e-6 for v in (lo, hi)) else (lambda v: f"{v:.1f}")
    return f"{f(lo)}-{f(hi)} nm"


def _worst(rec, region):
    """(band text, how far off in words, z) of the region's worst band (the record's ``worst``
    where it gives its numbers, else the band of largest |z| from the arrays), or None."""
    i = region["worst"]
    if i is None:
        return None
    w = region["record_worst"]
    m, e = region["measured"][i], region["expected"][i]
    rel = w.get("relative") if _num(w.get("relative")) else (m / e - 1 if e and math.isfinite(m) and math.isfinite(e) else None)
    z = w.get("z") if _num(w.get("z")) else region["z"][i]
    how = f"{abs(100 * rel):.3g} % {'low' if rel < 0 else 'high'}" if rel is not None else "relative error unknown"
    return band_text(*rec["edges"][i]), how, z


def worst_text(rec, region):
    """The region's worst band in words: ``macbeth cyan 480-490 nm: 3.1 % low, z -6.2``; None
    without a band to name."""
    got = _worst(rec, region)
    if got is None:
        return None
    band, how, z = got
    name = " ".join(p for p in (region["probe"], region["region"]) if p)
    return f"{name} {band}: {how}" + (f", z {format_z(z)}" if math.isfinite(z) else "")


def worst_lines(run):
    """The worst band of every region that failed its band check, in words (``worst_text``);
    [] for a run without a band record or without a failing region."""
    rec = record(run)
    if not rec:
        return []
    return [t for t in (worst_text(rec, r) for r in rec["regions"] if r["pass"] is False) if t]


def _scale(lo, hi, a, b):
    span = hi - lo or 1.0
    return lambda v: a + (v - lo) / span * (b - a)


def _nice(v):
    """v rounded to 3 significant digits, as a label."""
    return f"{v:.3g}"


def plot(rec, region):
    """The numbers of one region's plot (report.html's ``spectrum`` macro draws them): every
    coordinate rounded to 0.1 px, every label text (escaped by the template). ``points``: one per
    band with a measured value (x, y, y of the interval's ends, failing); ``expected``: the
    expected spectrum as an SVG polyline's points; ``failing``: the x extent of each failing band
    (a red band behind the points); the axes' ranges and labels."""
    edges, n = rec["edges"], len(rec["centres"])
    m, se, e = region["measured"], region["se"], region["expected"]
    lo_nm, hi_nm = edges[0][0], edges[-1][1]
    ends = [v for i in range(n) for v in (m[i] - Z95 * se[i], m[i] + Z95 * se[i], m[i], e[i]) if math.isfinite(v)]
    y_lo, y_hi = min(ends + [0.0]), max(ends + [0.0])
    y_hi = y_hi + 0.05 * (y_hi - y_lo or 1.0)
    x = _scale(lo_nm, hi_nm, PAD_L, PLOT_W - PAD_R)
    y = _scale(y_lo, y_hi, PLOT_H - PAD_B, PAD_T)
    failing = set(region["failing"])
    r1 = lambda v: round(v, 1)  # noqa: E731
    points = []
    for i in range(n):
        if not math.isfinite(m[i]):
            continue
        c = rec["centres"][i]
        s = se[i] if math.isfinite(se[i]) else 0.0
        points.append({"x": r1(x(c)), "y": r1(y(m[i])), "y0": r1(y(m[i] - Z95 * s)), "y1": r1(y(m[i] + Z95 * s)),
                       "fail": i in failing, "title": f"{band_text(*edges[i])}: measured {m[i]:.4g} +- {Z95 * s:.2g}, "
                                                     f"expected {e[i]:.4g}, z {format_z(region['z'][i])}"})
    expected = " ".join(f"{r1(x(rec['centres'][i]))},{r1(y(e[i]))}" for i in range(n) if math.isfinite(e[i]))
    spans = [{"x": r1(x(edges[i][0])), "w": r1(x(edges[i][1]) - x(edges[i][0]))} for i in sorted(failing)]
    worst, short = worst_text(rec, region), _worst(rec, region)
    return {"title": region["region"] or region["probe"], "check": region["check"],
            "note": f"{short[0]} {short[1]}" if short and region["pass"] is False else "",
            "pass": region["pass"], "points": points, "expected": expected, "failing": spans,
            "worst": worst or "", "w": PLOT_W, "h": PLOT_H, "left": PAD_L, "right": PLOT_W - PAD_R,
            "top": PAD_T, "bottom": PLOT_H - PAD_B, "nm_lo": f"{lo_nm:.0f}", "nm_hi": f"{hi_nm:.0f}",
            "y_lo": _nice(y_lo), "y_hi": _nice(y_hi), "zero": r1(y(0.0)) if y_lo < 0 < y_hi else None}


def plots(rec):
    """Every region's plot, failing regions first (then as recorded)."""
    order = sorted(range(len(rec["regions"])), key=lambda k: rec["regions"][k]["pass"] is not False)
    return [plot(rec, rec["regions"][k]) for k in order]
