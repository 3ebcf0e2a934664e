"""The readable summary: summary.md in the output folder, also printed. Failures first."""
from pathlib import Path

from ..verdict.status import ORDER


def _num(x, fmt="{:.4g}"):
    return "" if x is None else fmt.format(x)


def table(runs):
    rows = ["| status | scene | backend | mode | spp | resolution | time (s) | RMSE | relMSE | MAPE | FLIP | noise test | reason |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(runs, key=lambda r: (ORDER.get(r["status"], 9), r["scene"], r["backend"])):
        m = r.get("metrics") or {}
        t = r.get("test")
        test = ("" if not t else "not judged" if t.get("pass") is None
                else f"p_min {t['p_min']:.2g} / {t['threshold']:.2g}" if t.get("p_min") is not None
                else "failed (see reason)")
        res = "x".join(map(str, r["resolution"])) if r.get("resolution") else ""
        reason = (r.get("reason") or "").replace("|", "/").replace("\n", " ")
        rows.append(f"| {r['status']} | {r['scene']} | {r['backend']} | {r.get('mode') or ''} | {_num(r.get('spp'), '{}')} "
                    f"| {res} | {_num(r.get('time_s'), '{:.2f}')} | {_num(m.get('rmse'))} | {_num(m.get('relmse'))} "
                    f"| {_num(m.get('mape'))} | {_num(m.get('flip'))} | {test} | {reason[:300]} |")
    return "\n".join(rows)


def counts(runs):
    out = {}
    for r in runs:
        out[r["status"]] = out.get(r["status"], 0) + 1
    return out


def sweeps_table(sweeps):
    if not sweeps:
        return ""
    rows = ["", "## Speed against accuracy (sweeps)", "",
            "| scene | backend | mode | spp ladder | time (s) | RMSE | slope | converges | RMSE at equal time | time at equal error (s) |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for l in sweeps:
        if not l.get("points"):
            rows.append(f"| {l['scene']} | {l['backend']} | {l.get('mode') or ''} | | | | | | | {l.get('reason', '')} |")
            continue
        table = l.get("equal") or {}
        eq = next((r for r in table.get("rows", []) if r["mode"] == l["mode"] and r["backend"] == l["backend"]), {})
        gap = {k: "no overlap" for k, ok in (("rmse_at_equal_time", "time_overlap"), ("time_at_equal_error", "error_overlap"))
               if eq and table.get(ok) is False}  # the lines' ranges do not meet (batch/studies/sweep.py)
        pts = l["points"]
        spps = ", ".join(str(p["spp"]) for p in pts)
        times = ", ".join("{:.2f}".format(p["time_s"]) for p in pts)
        errs = ", ".join("{:.3g}".format(p["rmse"]) for p in pts)
        rows.append(f"| {l['scene']} | {l['backend']} | {l['mode']} | {spps} | {times} | {errs} "
                    f"| {_num(l.get('slope'), '{:.2f}')} | {'yes' if l.get('converges') else ('NO: ' if l.get('converges') is False else '') + l.get('flag', l.get('reason', ''))} "
                    f"| {gap.get('rmse_at_equal_time') or _num(eq.get('rmse_at_equal_time'))} "
                    f"| {gap.get('time_at_equal_error') or _num(eq.get('time_at_equal_error'), '{:.3g}')} |")
    return "\n".join(rows) + "\n"


def stability_table(rows):
    if not rows:
        return ""
    out = ["", "## Stability", "", "| sweep | value | backend | mode | status | mean | problems |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['sweep']} | {r.get('value', '')} | {r.get('backend', '')} | {r.get('mode') or ''} | {r['status']} "
                   f"| {_num(r.get('mean'))} | {'; '.join(r.get('problems') or []) or r.get('reason', '')} |")
    return "\n".join(out) + "\n"


RGB_BACKENDS = ("cycles", "luxcore")
SPECTRAL_BACKENDS = ("mitsuba", "art")


def _rgb_cell(r):
    if r is None:
        return ""
    if r["status"] in ("unsupported", "skipped"):
        return r["status"]
    m = r.get("metrics") or {}
    de = next((p["measured"] for p in r.get("probes") or [] if p["name"] == "lambert mean dE00"), None)
    parts = [f"RMSE {_num(m.get('rmse'), '{:.3g}')}" if m.get("rmse") is not None else "",
             f"dE00 {de:.2f}" if isinstance(de, (int, float)) else "", r["status"]]
    return ", ".join(p for p in parts if p)


def rgb_comparison(runs):
    """Per case and scene, each backend's error against the spectral reference (RMSE), the mean
    CIEDE2000 of the Lambertian patch probes where the scene has them, and its status: the RGB
    renderers (Cycles, LuxCore) next to the spectral ones (Mitsuba, ART). Empty without RGB runs."""
    runs = [r for r in runs if r.get("mode") != "export"]
    if not any(r["backend"] in RGB_BACKENDS for r in runs):
        return ""
    order = [b for b in SPECTRAL_BACKENDS + RGB_BACKENDS if any(r["backend"] == b for r in runs)]
    by = {(r["scene"], r["backend"]): r for r in runs}
    scenes = sorted({(r.get("case") or "", r["scene"]) for r in runs})
    rows = ["", "## RGB renderers against the spectral references", "",
            "What reducing spectra to RGB costs (exporters/rgb_reduction.py): each backend's RMSE against the "
            "scene's spectral reference, the mean CIEDE2000 of its Lambertian patch probes, and its status.", "",
            "| case | scene | " + " | ".join(order) + " |", "|---|---|" + "---|" * len(order)]
    for case, scene in scenes:
        rows.append(f"| {case} | {scene} | " + " | ".join(_rgb_cell(by.get((scene, b))) for b in order) + " |")
    return "\n".join(rows) + "\n"


def write(out_dir, runs, elapsed_s, sweeps=None, stability=None):
    c = counts(runs)
    head = ", ".join(f"{n} {s}" for s, n in sorted(c.items(), key=lambda kv: ORDER.get(kv[0], 9)))
    text = (f"# Spectral benchmark results\n\n{len(runs)} jobs in {elapsed_s:.1f} s: {head or 'nothing ran'}.\n\n"
            "A render is ok when every check passes: its agreement with the reference within noise (its own and "
            "the reference's; block test, Sidak-corrected) and the analytic probes (ground truth from no renderer). "
            "known: fails exactly as a recorded deviation (known_deviations.toml); unjudged: nothing could judge it. "
            "Images and diffs: `<scene>/results/<backend>/`; all numbers: `metrics.json`.\n\n"
            + table(runs) + "\n" + rgb_comparison(runs) + sweeps_table(sweeps) + stability_table(stability))
    Path(out_dir, "summary.md").write_text(text)
    return text
