"""The readable summary: summary.md in the output folder, also printed. Failures first."""
from pathlib import Path

from ..markdown import cell as _cell
from ..records import flip_text, noise_test_text
from ..verdict.status import rank
from .results import (JUDGED, SELF_CHECK, checked_against_itself, crosscheck_note, judged_without_reference, mode_text,
                      probes_measured)


def _num(x, fmt="{:.4g}"):
    return "" if x is None else fmt.format(x)


def table(runs):
    """The jobs, failures first; a backend skipped or unsupported on every scene with one reason is
    one row (batch/report/grouping.py), not a row per scene."""
    from .grouping import not_run_everywhere
    runs, grouped = not_run_everywhere(runs)
    rows = ["| status | scene | backend | mode | spp | resolution | time (s) | RMSE | relMSE | MAPE | FLIP | noise test | probes | reason |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for g in grouped:
        rows.append(f"| {_cell(g['status'])} | (all {g['scenes']} scenes) | {_cell(g['backend'])} | {_cell(g.get('mode') or '')} "
                    f"| | | | | | | | | | {_cell(g['reason'] or '')[:300]} |")
    for r in sorted(runs, key=lambda r: (rank(r["status"]), r["scene"], r["backend"])):
        m = r.get("metrics") or {}
        test = _cell(noise_test_text(r.get("test")) + detectable_cell(r))
        res = "x".join(map(str, r["resolution"])) if r.get("resolution") else ""
        reason = _cell(r.get("reason") or "")
        shown = (f"{r['status']} (without reference)" if judged_without_reference(r) else
                 f"{r['status']} (checked against itself)" if checked_against_itself(r) else
                 f"{r['status']} ({crosscheck_note(r)})" if crosscheck_note(r) else r["status"])
        rows.append(f"| {_cell(shown)} | {_cell(r['scene'])} | {_cell(r['backend'])} | {_cell(mode_text(r))} | {_num(r.get('spp'), '{}')} "
                    f"| {res} | {_num(r.get('time_s'), '{:.2f}')} | {_num(m.get('rmse'))} | {_num(m.get('relmse'))} "
                    f"| {_num(m.get('mape'))} | {_cell(flip_text(r))} | {test} | {probes_cell(r)} | {reason[:300]} |")
    if any(checked_against_itself(r) for r in runs):
        rows += ["", f"*checked against itself*: judged only against a reference made by the same renderer, no probe "
                     f"({SELF_CHECK.split(': ', 1)[1]}). Ground truth for these scenes needs a probe or another renderer's reference."]
    return "\n".join(rows)


def probes_cell(run):
    """The probes column: "25/25 pass", "1/2 pass", or "none" for a judged render no probe measured."""
    measured, passed = probes_measured(run)
    if measured:
        return f"{passed}/{measured} pass"
    return "none" if run.get("status") in JUDGED else ""


def detectable_cell(run):
    """Issue 20 (power helper): the run's power in the noise test cell, "; detects 0.12 %": the
    smallest uniform radiance scale error its checks detect with 90 % power (metrics.json
    ``detectable.scale``); empty when not stated."""
    d = run.get("detectable") or {}
    return f"; detects {100 * d['scale']:.2g} %" if isinstance(d.get("scale"), (int, float)) else ""


def reference_problems_table(runs):
    """Every reference passed over or unusable: the file, what is wrong with it and the jobs it
    concerned (one row per file and problem)."""
    rows, order = {}, []
    for r in runs:
        for p in r.get("reference_problems") or []:
            key = (str(p.get("file")), str(p.get("problem")))
            if key not in rows:
                rows[key] = []
                order.append(key)
            rows[key].append(f"{r['scene']} / {r['backend']}" + (f" {r['mode']}" if r.get("mode") else ""))
    without = [r for r in runs if judged_without_reference(r)]
    if not order and not without:
        return ""
    out = ["", "## Reference problems", ""]
    if order:
        out += ["A reference listed here was passed over for the next folder (or, with none left, the render "
                "was judged without one); an observer layer listed here was not used, its reference was.", "",
                "| file | problem | jobs |", "|---|---|---|"]
        out += [f"| {_cell(f)} | {_cell(p)} | {_cell(', '.join(rows[(f, p)]))} |" for f, p in order]
    if without:
        out += ["", "Judged without a reference (no usable one): "
                + _cell(", ".join(f"{r['scene']} / {r['backend']} ({r['status']})" for r in without)) + "."]
    return "\n".join(out) + "\n"


def conversions_table(runs):
    """Every scene's conversion warnings (what its export from Blender converted or lost), once per
    scene: the scene, the object and field, and what happened."""
    seen, out = set(), []
    for r in runs:
        if r.get("scene") in seen or not r.get("scene_warnings"):
            continue
        seen.add(r.get("scene"))
        out += [f"| {_cell(r['scene'])} | {_cell(w.get('object'))} | {_cell(w.get('field'))} | {_cell(w.get('message'))} |"
                for w in r["scene_warnings"]]
    if not out:
        return ""
    return "\n".join(["", "## Conversions from the source scene", "",
                      "What each scene's export converted or could not carry over (docs/scene-format.md, section 11).",
                      "", "| scene | object | field | conversion or loss |", "|---|---|---|---|", *out]) + "\n"


def spectra_table(runs):
    """Issue 33: each spectral job's failing probe regions, each by its worst band ("macbeth cyan
    480-490 nm: 3.1 % low, z -6.2": batch/report/spectra.py); empty when no region failed."""
    from .spectra import worst_lines
    rows = [f"| {_cell(r.get('scene'))} | {_cell(r.get('backend'))} | {_cell(line)} |" for r in runs for line in worst_lines(r)]
    if not rows:
        return ""
    return "\n".join(["", "## Spectra: the worst band of each failing region", "",
                      "A spectral render is also judged band by band on each probe region whose truth is a spectrum "
                      "(Sidak over bands and regions); the report plots each region's spectrum.", "",
                      "| scene | backend | worst band |", "|---|---|---|", *rows]) + "\n"


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
            rows.append(f"| {_cell(l['scene'])} | {_cell(l['backend'])} | {_cell(l.get('mode') or '')} | | | | | | | {_cell(l.get('reason', ''))} |")
            continue
        table = l.get("equal") or {}
        eq = next((r for r in table.get("rows", []) if r["mode"] == l["mode"] and r["backend"] == l["backend"]), {})
        gap = {k: "no overlap" for k, ok in (("rmse_at_equal_time", "time_overlap"), ("time_at_equal_error", "error_overlap"))
               if eq and table.get(ok) is False}  # the lines' ranges do not meet (batch/studies/sweep.py)
        pts = l["points"]
        spps = ", ".join(str(p["spp"]) for p in pts)
        times = ", ".join("{:.2f}".format(p["time_s"]) for p in pts)
        errs = ", ".join("{:.3g}".format(p["rmse"]) for p in pts)
        verdict = 'yes' if l.get('converges') else ('NO: ' if l.get('converges') is False else '') + str(l.get('flag', l.get('reason', '')))
        rows.append(f"| {_cell(l['scene'])} | {_cell(l['backend'])} | {_cell(l['mode'])} | {spps} | {times} | {errs} "
                    f"| {_num(l.get('slope'), '{:.2f}')} | {_cell(verdict)} "
                    f"| {gap.get('rmse_at_equal_time') or _num(eq.get('rmse_at_equal_time'))} "
                    f"| {gap.get('time_at_equal_error') or _num(eq.get('time_at_equal_error'), '{:.3g}')} |")
    return "\n".join(rows) + "\n"


def stability_table(rows):
    if not rows:
        return ""
    out = ["", "## Stability", "", "| sweep | value | backend | mode | status | mean | problems |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        problems = '; '.join(map(str, r.get('problems') or [])) or r.get('reason', '')
        out.append(f"| {_cell(r['sweep'])} | {_cell(r.get('value', ''))} | {_cell(r.get('backend', ''))} | {_cell(r.get('mode') or '')} "
                   f"| {_cell(r['status'])} | {_num(r.get('mean'))} | {_cell(problems)} |")
    return "\n".join(out) + "\n"


RGB_BACKENDS = ("cycles", "luxcore")
SPECTRAL_BACKENDS = ("mitsuba", "art", "pbrt")


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
            "| case | scene | " + " | ".join(map(_cell, order)) + " |", "|---|---|" + "---|" * len(order)]
    for case, scene in scenes:
        rows.append(f"| {_cell(case)} | {_cell(scene)} | " + " | ".join(_cell(_rgb_cell(by.get((scene, b)))) for b in order) + " |")
    return "\n".join(rows) + "\n"


def _against_baseline(runs):
    """--baseline: the jobs judged against the previous run, changed first (batch/verdict/baseline.py)."""
    from ..verdict import baseline
    section = baseline.summary_section(runs)
    return section.lstrip("\n") if section else ""


def studies_table(rows):
    """--study spectral-vs-rgb: per scene, light and RGB route, the verdict in the study's words,
    the CIEDE2000 over the noise test's blocks and whether the difference is beyond noise."""
    if not rows:
        return ""
    out = ["", "## What spectral rendering changes (--study spectral-vs-rgb)", "",
           "Each scene rendered spectrally (Mitsuba) and in RGB by the same renderer, no reference: CIEDE2000 between "
           "the two over the noise test's blocks (in CIELAB of the light's white), and whether the difference is "
           "beyond both renders' noise (block test, Sidak). Maps: `studies/spectral_vs_rgb/<scene>/<light>/`.", "",
           "| scene | light | RGB route | verdict | dE00 mean | dE00 p95 | dE00 max | noise alone p95 | beyond noise | reason |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        d, t = r.get("de00") or {}, r.get("test") or {}
        beyond = "" if not t else (f"yes (p {t['p_min']:.2g} < {t['threshold']:.2g})" if t.get("beyond_noise")
                                   else f"no (p {t['p_min']:.2g} >= {t['threshold']:.2g})")
        route = " ".join(str(x) for x in (r.get("rgb"), r.get("rgb_mode")) if x)
        out.append(f"| {_cell(r.get('scene', ''))} | {_cell(r.get('light', ''))} | {_cell(route)} "
                   f"| {_cell(r.get('verdict') or r.get('status', ''))} | {_num(d.get('mean'), '{:.2f}')} "
                   f"| {_num(d.get('p95'), '{:.2f}')} | {_num(d.get('max'), '{:.2f}')} | {_num(d.get('noise_p95'), '{:.2f}')} "
                   f"| {beyond} | {_cell(r.get('reason') or '')[:300]} |")
    return "\n".join(out) + "\n"


def write(out_dir, runs, elapsed_s, sweeps=None, stability=None, studies=None):
    if studies and not runs:  # a study instead of the judged jobs
        pairs = [r for r in studies if r.get("de00")]
        text = (f"# Spectral benchmark study\n\n{len(pairs)} render pair{'s' if len(pairs) != 1 else ''} compared in "
                f"{elapsed_s:.1f} s.\n" + studies_table(studies) + conversions_table(studies))
        Path(out_dir, "summary.md").write_text(text)
        return text
    c = counts(runs)
    head = ", ".join(f"{n} {s}" for s, n in sorted(c.items(), key=lambda kv: rank(kv[0])))
    without = sum(1 for r in runs if judged_without_reference(r))
    if without:
        head += f" ({without} judged without a usable reference: see Reference problems)"
    text = (f"# Spectral benchmark results\n\n{len(runs)} jobs in {elapsed_s:.1f} s: {head or 'nothing ran'}.\n\n"
            "A render is ok when every check passes: its agreement with the reference within noise (its own and "
            "the reference's; block test, Sidak-corrected) and the analytic probes (ground truth from no renderer). "
            "known: fails exactly as a recorded deviation (known_deviations.toml); unjudged: nothing could judge it. "
            "Images and diffs: `<scene>/results/<backend>/`; all numbers: `metrics.json`.\n\n"
            + _against_baseline(runs) + table(runs) + "\n" + spectra_table(runs) + reference_problems_table(runs) + conversions_table(runs)
            + rgb_comparison(runs) + sweeps_table(sweeps) + stability_table(stability) + studies_table(studies))
    Path(out_dir, "summary.md").write_text(text)
    return text
