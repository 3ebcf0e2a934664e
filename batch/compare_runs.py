"""What changed between two finished runs of the batch runner.

    python batch/compare_runs.py OLD NEW [-o DIR] [--alpha A] [--min-samples N] [--block B]

Matches the jobs of the two output folders by scene, backend and mode and lists, changed jobs
first: status changes, changes of the noise test's and the probes' verdicts, the renders judged
against each other on both their noises (exactly as ``batch/run.py --baseline``:
batch/verdict/baseline.py, with a z-map per job), metric deltas, render time as the ratio of the
median pass times with its spread (a sentence "slower by X % (+- Y)" only when the spread allows
it), and jobs new in NEW or missing from it. Prints the markdown and writes DIR/compare.md,
DIR/compare.html (standalone, Jinja2 with autoescaping, the report's environment) and
DIR/compare.json (DIR defaults to NEW/compare; the z-maps go below it).

Exit status: 0 nothing changed beyond noise; 1 something did (a job changed, or a job is new or
missing); 2 usage error (a folder missing or not a run, a corrupt metrics.json: named). Render
time is reported, not part of the exit status: its spread is the pass-to-pass spread within each
run, and a machine that is busier during one whole run is not in it.
"""
import argparse
import json
import shutil
import sys
from pathlib import Path

if __name__ == "__main__" and __package__ in (None, ""):  # run as a script: this module from the package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import pkg_bootstrap  # noqa: E402
    pkg_bootstrap.package()
    from spectral_bench.batch import compare_runs  # noqa: E402
    sys.exit(compare_runs.main())

from .verdict import baseline  # noqa: E402

EXIT_SAME, EXIT_CHANGED, EXIT_USAGE = 0, 1, 2
METRICS = ("rmse", "relmse", "mape", "flip")


def _num(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _probe_passes(entry):
    return {str(p.get("name")): p.get("pass") for p in entry.get("probes") or [] if isinstance(p, dict)}


def _test_pass(entry):
    t = entry.get("test")
    return t.get("pass") if isinstance(t, dict) else None


def compare_job(old, new, old_folder, new_folder, out_dir, base, settings):
    """One matched job: its changes (a list of sentences; empty: nothing changed beyond noise), the
    image verdict (baseline record), metric deltas and time."""
    rec = baseline.judge_entry(new, Path(new_folder), base, settings, zmap_root=out_dir)
    changes = []
    if old.get("status") != new.get("status"):
        changes.append(f"status {old.get('status')} -> {new.get('status')}")
    if _test_pass(old) != _test_pass(new):
        changes.append(f"noise test against the reference {_verdict(_test_pass(old))} -> {_verdict(_test_pass(new))}")
    po, pn = _probe_passes(old), _probe_passes(new)
    for name in list(pn) + [n for n in po if n not in pn]:
        if name not in po:
            changes.append(f"probe {name} new ({_verdict(pn[name])})")
        elif name not in pn:
            changes.append(f"probe {name} gone (was {_verdict(po[name])})")
        elif po[name] != pn[name]:
            changes.append(f"probe {name} {_verdict(po[name])} -> {_verdict(pn[name])}")
    for p in rec.get("probes") or []:
        if p.get("moved"):
            changes.append(f"probe {p['name']} moved beyond noise (z = {p['z']:.1f})")
    if rec["status"] == "changed" and not (rec.get("p_min") is not None and rec["p_min"] >= rec["threshold"]):
        changes.append("image differs beyond noise")
    mo, mn = old.get("metrics") or {}, new.get("metrics") or {}
    deltas = {k: [mo.get(k), mn.get(k), (mn[k] - mo[k]) if _num(mo.get(k)) and _num(mn.get(k)) else None]
              for k in METRICS if isinstance(mo, dict) and isinstance(mn, dict) and (mo.get(k) is not None or mn.get(k) is not None)}
    return {"scene": new.get("scene"), "backend": new.get("backend"), "mode": new.get("mode"),
            "old_status": old.get("status"), "new_status": new.get("status"), "changes": changes,
            "changed": bool(changes), "baseline": rec, "metrics": deltas, "time": rec.get("time")}


def _verdict(passed):
    return {True: "pass", False: "FAIL", None: "not judged"}.get(passed, str(passed))


def compare(old_folder, new_folder, out_dir, settings=None):
    """The comparison as plain data (also written as compare.json). Raises baseline.BaselineError
    for a folder that is missing or not a run."""
    old_folder, new_folder, out_dir = Path(old_folder), Path(new_folder), Path(out_dir)
    base = baseline.Run(old_folder, given=str(old_folder))
    new_data = baseline.read_metrics(new_folder)
    opts = new_data.get("options") if isinstance(new_data.get("options"), dict) else {}
    s = {"alpha": opts.get("alpha") if _num(opts.get("alpha")) else 0.01,
         "min_samples": opts.get("min_samples") if _num(opts.get("min_samples")) else None,
         "block": opts.get("block") if _num(opts.get("block")) else None}
    s.update({k: v for k, v in (settings or {}).items() if v is not None})
    seen, jobs, new_jobs = set(), [], []
    for e in new_data["runs"]:
        k = baseline.key_of(e)
        if k is None or k in seen:
            continue
        seen.add(k)
        old = base.jobs.get(k)
        if old is None:
            new_jobs.append({"scene": k[0], "backend": k[1], "mode": k[2], "status": e.get("status")})
            continue
        jobs.append(compare_job(old, e, old_folder, new_folder, out_dir, base, s))
    missing = [{"scene": k[0], "backend": k[1], "mode": k[2], "status": e.get("status")}
               for k, e in base.jobs.items() if k not in seen]
    jobs.sort(key=lambda j: (not j["changed"], str(j["scene"]), str(j["backend"]), str(j["mode"])))
    changed = any(j["changed"] for j in jobs) or bool(new_jobs) or bool(missing)
    return {"old": str(old_folder), "new": str(new_folder), "settings": s, "jobs": jobs, "new_jobs": new_jobs,
            "missing_jobs": missing, "changed": changed}


# -- output ---------------------------------------------------------------------------------------
def _fmt(x, f="{:.4g}"):
    return "" if x is None else f.format(x) if _num(x) else str(x)


def _time_text(tc):
    if not isinstance(tc, dict):
        return "no pass times"
    if tc.get("text"):
        return tc["text"]
    se = "" if tc.get("se") is None else f" +- {tc['se']:.2f}"
    return f"x{tc['ratio']:.2f}{se} (not beyond the spread)" if tc.get("ratio") is not None else ""


def rows(result):
    """The jobs as rows of text (for markdown and HTML alike)."""
    out = []
    for j in result["jobs"]:
        b = j["baseline"]
        image = b.get("status")
        if b.get("status") in ("unjudged", "missing"):
            image += f": {b.get('reason')}"
        deltas = "; ".join(f"{k} {_fmt(v[0])} -> {_fmt(v[1])}" + (f" ({v[2]:+.3g})" if v[2] is not None else "")
                           for k, v in j["metrics"].items())
        out.append({"changed": j["changed"], "scene": str(j["scene"]), "backend": str(j["backend"]),
                    "mode": str(j["mode"] or ""), "status": f"{j['old_status']} -> {j['new_status']}"
                    if j["old_status"] != j["new_status"] else str(j["new_status"]),
                    "what": "; ".join(j["changes"]) or "nothing beyond noise", "image": image,
                    "how_much": baseline.how_much(b), "zmap": b.get("zmap") or "",
                    "zmap_png": (str(Path(b["zmap"]).with_name(baseline.ZMAP_PNG)) if b.get("zmap") else ""),
                    "metrics": deltas, "time": _time_text(j.get("time"))})
    return out


def markdown(result):
    from .markdown import cell as _cell
    rs = rows(result)
    n_changed = sum(r["changed"] for r in rs)
    head = (f"# Changes from {_cell(result['old'])} to {_cell(result['new'])}\n\n"
            f"{len(rs)} jobs in both: {n_changed} changed, {len(rs) - n_changed} without a change beyond noise; "
            f"{len(result['new_jobs'])} new, {len(result['missing_jobs'])} missing. Renders judged against each other "
            "on both their noises (two-sample block test, Sidak-corrected), probes compared; time as the ratio of "
            "the median pass times (new / old) with its spread.\n\n")
    table = ["| changed | scene | backend | mode | status | what changed | image | how much | where (z-map) | metrics | time |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rs:
        table.append("| " + " | ".join(_cell(x) for x in ("CHANGED" if r["changed"] else "same", r["scene"], r["backend"],
                                                          r["mode"], r["status"], r["what"], r["image"][:300], r["how_much"],
                                                          r["zmap"], r["metrics"], r["time"])) + " |")
    text = head + "\n".join(table) + "\n"
    for title, items in (("New jobs (not in OLD)", result["new_jobs"]), ("Missing jobs (in OLD, not in NEW)", result["missing_jobs"])):
        if items:
            text += f"\n## {title}\n\n" + "\n".join(
                f"- {_cell(i['scene'])} / {_cell(i['backend'])} {_cell(i['mode'] or '')} ({_cell(i['status'])})" for i in items) + "\n"
    return text


def html_page(result, out_dir):
    """compare.html: a standalone page (the report's Jinja2 environment, autoescaped); its images are
    only relative links to files inside ``out_dir``."""
    from .report import html
    rs = rows(result)
    for r in rs:
        r["zmap_src"] = html._local_url(Path(out_dir), r["zmap_png"]) if r["zmap_png"] else None
    return html._env.get_template("compare.html").render(
        old=result["old"], new=result["new"], rows=rs, new_jobs=result["new_jobs"], missing=result["missing_jobs"],
        changed=sum(r["changed"] for r in rs))


def write(result, out_dir):
    out_dir = Path(out_dir)
    text = markdown(result)
    (out_dir / "compare.md").write_text(text, encoding="utf-8")
    (out_dir / "compare.html").write_text(html_page(result, out_dir), encoding="utf-8")
    (out_dir / "compare.json").write_text(json.dumps(result, indent=1, default=str) + "\n", encoding="utf-8")
    return text


def main(argv=None):
    ap = argparse.ArgumentParser(prog="batch/compare_runs.py", description=__doc__.splitlines()[0])
    ap.add_argument("old", metavar="OLD", help="the earlier run's output folder")
    ap.add_argument("new", metavar="NEW", help="the later run's output folder")
    ap.add_argument("-o", "--out", metavar="DIR", help="where compare.md/.html/.json and the z-maps go (default NEW/compare)")
    ap.add_argument("--alpha", type=float, help="false-alarm rate per job (default: NEW's --alpha)")
    ap.add_argument("--min-samples", type=int, help="samples per block of the image test (default: NEW's)")
    ap.add_argument("--block", type=int, help="block side of the image test (default: NEW's)")
    args = ap.parse_args(argv)
    if args.alpha is not None and not 0 < args.alpha < 1:
        ap.error("--alpha must be in (0, 1)")
    for name in ("min_samples", "block"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            ap.error(f"--{name.replace('_', '-')} must be >= 1")
    for folder in (args.old, args.new):
        try:
            baseline.read_metrics(folder)
        except baseline.BaselineError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_USAGE
    out_dir = Path(args.out) if args.out else Path(args.new) / "compare"
    try:
        if out_dir.is_dir() and (out_dir / "compare.json").is_file():
            shutil.rmtree(out_dir)  # an earlier comparison written here: replaced whole
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"error: cannot write the output folder {out_dir}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        result = compare(args.old, args.new, out_dir, {"alpha": args.alpha, "min_samples": args.min_samples,
                                                      "block": args.block})
    except baseline.BaselineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    print(write(result, out_dir))
    return EXIT_CHANGED if result["changed"] else EXIT_SAME

