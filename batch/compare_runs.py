"""What changed between two finished runs of the batch runner.

    python batch/compare_runs.py OLD NEW [-o DIR] [--alpha A] [--min-samples N] [--block B]

Matches the jobs of the two output folders by scene, backend and mode and lists, changed jobs
first: status changes, changes of the noise test's and the probes' verdicts, the renders judged
against each other on both their noises (exactly as ``batch/run.py --baseline``:
batch/verdict/baseline.py, with a z-map per job), metric deltas, render time as the ratio of the
median pass times with its spread (a sentence "slower by X % (+- Y)" only when the spread allows
it), and jobs new in NEW or missing from it. A verdict (status, noise test, probe) that flipped
while the renders agree within their noise and every probe's residual stayed within it is not a
change: the job is listed ``unstable`` with the deviation both runs measure against what the check
detects ("verdict unstable: the deviation 0.10 % is at the test's detectable 0.11 %"), a check at
the edge of its power passing or failing with the seed. Prints the markdown and writes DIR/compare.md,
DIR/compare.html (standalone, Jinja2 with autoescaping, the report's environment) and
DIR/compare.json (DIR defaults to NEW/compare; the z-maps go below it).

Run folders are anyone's data (a folder received from someone else): compare_runs only reads OLD
and NEW, and writes only into an output folder it creates itself, or one that is empty. It never
deletes or overwrites: without ``-o`` the comparison goes to NEW/compare, or the first free
NEW/compare-2, -3, ... when that is taken (an earlier comparison stays as it was); an ``-o DIR``
that exists and is not empty is refused, and so is one that is OLD or NEW, contains either, or
lies inside either. Its files are created new (O_EXCL | O_NOFOLLOW): nothing is written through a
symbolic link.

Exit status: 0 every job judged and nothing changed beyond noise (an unstable verdict included); 1
something changed (a job changed, or a job is new or missing); 2 usage error, nothing compared (a folder missing or not a
run, a corrupt metrics.json, an output folder refused: named); 3 nothing changed that could be
judged, but a job could not be judged (an unreadable or oversized render, a render missing from
its folder, one pass only: no per-pixel noise, pass times or probes that are not what a run
writes: each named in the report and on stderr). Render time is reported, not part of the exit
status: its spread is the pass-to-pass spread within each run, and a machine that is busier
during one whole run is not in it.
"""
import argparse
import json
import os
import stat
import sys
import traceback
from pathlib import Path

if __name__ == "__main__" and __package__ in (None, ""):  # run as a script: this module from the package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    import pkg_bootstrap  # noqa: E402
    pkg_bootstrap.package()
    from spectral_bench.batch import compare_runs  # noqa: E402
    sys.exit(compare_runs.main())

from . import run_folder  # noqa: E402
from .verdict import baseline  # noqa: E402

EXIT_SAME, EXIT_CHANGED, EXIT_USAGE, EXIT_UNJUDGED = 0, 1, 2, 3
METRICS = ("rmse", "relmse", "mape", "flip")
MAX_FRESH = 1000  # NEW/compare, NEW/compare-2, ... NEW/compare-999


class OutputRefused(ValueError):
    """An output folder compare_runs will not write into (exit 2); the message names it and why."""


def _num(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _probes(entry):
    p = entry.get("probes")
    return p if isinstance(p, list) else []


def _probe_passes(entry):
    return {str(p.get("name")): p.get("pass") for p in _probes(entry) if isinstance(p, dict)}


def entry_problems(entry, which):
    """Why a job record cannot be judged as a run writes it (fields of a hand-edited metrics.json),
    as sentences naming the run and the field; empty when nothing is wrong."""
    out = []
    if entry.get("probes") is not None and not isinstance(entry.get("probes"), list):
        out.append(f"{which}'s probes is {type(entry['probes']).__name__}, not a list")
    why = baseline.times_problem(entry)
    if why:
        out.append(f"{which}'s {why}")
    return out


def compare_job(old, new, old_folder, new_folder, out_dir, base, settings, zmap_prefix=""):
    """One matched job: its changes (a list of sentences; empty: nothing changed beyond noise), what
    could not be judged (``unjudged``: sentences, empty when everything was), the image verdict
    (baseline record), metric deltas and time."""
    rec = baseline.judge_entry(new, Path(new_folder), base, settings, zmap_root=out_dir, zmap_prefix=zmap_prefix)
    problems = entry_problems(old, "OLD") + entry_problems(new, "NEW")
    if rec.get("status") == "unjudged":
        problems.insert(0, f"image not judged: {rec.get('reason')}")
    # verdicts that flipped while the images agree within noise (the baseline record's ``unstable``)
    # are named, not changes: a check at the edge of its power passes or fails with the seed
    unstable = rec.get("unstable") if isinstance(rec.get("unstable"), str) else None
    changes = [] if unstable else [f["text"] for f in baseline.verdict_flips(old, new, rec.get("probes"))]
    po, pn = _probe_passes(old), _probe_passes(new)
    for name in list(pn) + [n for n in po if n not in pn]:  # (a probe's flip is among the verdicts above)
        if name not in po:
            changes.append(f"probe {name} new ({_verdict(pn[name])})")
        elif name not in pn:
            changes.append(f"probe {name} gone (was {_verdict(po[name])})")
    for p in rec.get("probes") or []:
        if p.get("moved"):
            changes.append(f"probe {p['name']} moved beyond noise (z = {p['z']:.1f})")
    test = rec.get("test")
    if isinstance(test, dict) and test.get("pass") is False:  # whichever part failed: block or scale test
        from .records import noise_test_failure
        changes.append(f"image differs beyond noise: {noise_test_failure(test)}")
    elif rec["status"] == "changed" and not isinstance(test, dict):  # rendered in one run only
        changes.append(f"image: {rec.get('reason')}")
    mo, mn = old.get("metrics") or {}, new.get("metrics") or {}
    deltas = {k: [mo.get(k), mn.get(k), (mn[k] - mo[k]) if _num(mo.get(k)) and _num(mn.get(k)) else None]
              for k in METRICS if isinstance(mo, dict) and isinstance(mn, dict) and (mo.get(k) is not None or mn.get(k) is not None)}
    return {"scene": new.get("scene"), "backend": new.get("backend"), "mode": new.get("mode"),
            "old_status": old.get("status"), "new_status": new.get("status"), "changes": changes,
            "changed": bool(changes), "unstable": None if changes else unstable, "unjudged": problems, "baseline": rec,
            "metrics": deltas, "time": rec.get("time")}


def _failed_job(new, exc):
    """The record of a job whose comparison broke (never the whole comparison's problem)."""
    rec = {"status": "unjudged", "reason": f"comparison failed: {type(exc).__name__}: {exc}"}
    return {"scene": new.get("scene"), "backend": new.get("backend"), "mode": new.get("mode"),
            "old_status": None, "new_status": new.get("status"), "changes": [], "changed": False, "unstable": None,
            "unjudged": [rec["reason"]], "baseline": rec, "metrics": {}, "time": None}


def _verdict(passed):
    return {True: "pass", False: "FAIL", None: "not judged"}.get(passed, str(passed))


def compare(old_folder, new_folder, out_dir, settings=None):
    """The comparison as plain data (also written as compare.json). Raises run_folder.NotARun
    for a folder that is missing or not a run."""
    old_folder, new_folder, out_dir = Path(old_folder), Path(new_folder), Path(out_dir)
    base = baseline.Run(old_folder, given=str(old_folder))
    new_data = run_folder.read(new_folder)
    opts = new_data.get("options") if isinstance(new_data.get("options"), dict) else {}
    s = {"alpha": opts.get("alpha") if _num(opts.get("alpha")) else 0.01,
         "min_samples": opts.get("min_samples") if _num(opts.get("min_samples")) else None,
         "block": opts.get("block") if _num(opts.get("block")) else None}
    s.update({k: v for k, v in (settings or {}).items() if v is not None})
    seen, jobs, new_jobs, zmap_folders = set(), [], [], set()
    for e in new_data["runs"]:
        k = baseline.key_of(e)
        if k is None or k in seen:
            continue
        seen.add(k)
        old = base.jobs.get(k)
        if old is None:
            new_jobs.append({"scene": k[0], "backend": k[1], "mode": k[2], "status": e.get("status")})
            continue
        # each job's z-map in a folder of its own (two records naming one render folder: the second
        # one's goes below _duplicate/<n>/, never over the first's)
        folder = run_folder.job_dir(new_folder, e)
        prefix = f"_duplicate/{len(zmap_folders)}" if folder is not None and folder in zmap_folders else ""
        zmap_folders.add(folder)
        try:
            jobs.append(compare_job(old, e, old_folder, new_folder, out_dir, base, s, prefix))
        except Exception as exc:  # noqa: BLE001 - one job that cannot be compared is that job's problem
            jobs.append(_failed_job(e, exc))
    missing = [{"scene": k[0], "backend": k[1], "mode": k[2], "status": e.get("status")}
               for k, e in base.jobs.items() if k not in seen]
    jobs.sort(key=lambda j: (not j["changed"], not j["unjudged"], not j.get("unstable"), str(j["scene"]), str(j["backend"]),
                             str(j["mode"])))
    changed = any(j["changed"] for j in jobs) or bool(new_jobs) or bool(missing)
    unjudged = [j for j in jobs if j["unjudged"]]
    return {"old": str(old_folder), "new": str(new_folder), "settings": s, "jobs": jobs, "new_jobs": new_jobs,
            "missing_jobs": missing, "changed": changed, "unjudged": len(unjudged)}


def exit_code(result):
    """1 when something changed, else 3 when a job could not be judged, else 0."""
    if result["changed"]:
        return EXIT_CHANGED
    return EXIT_UNJUDGED if result.get("unjudged") else EXIT_SAME


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
        out.append({"changed": j["changed"], "unjudged": bool(j.get("unjudged")), "unstable": bool(j.get("unstable")),
                    "scene": str(j["scene"]), "backend": str(j["backend"]),
                    "mode": str(j["mode"] or ""), "status": f"{j['old_status']} -> {j['new_status']}"
                    if j["old_status"] != j["new_status"] else str(j["new_status"]),
                    "what": "; ".join(j["changes"] + [f"NOT JUDGED: {u}" for u in j.get("unjudged") or []])
                    or j.get("unstable") or "nothing beyond noise", "image": image,
                    "how_much": baseline.how_much(b), "zmap": b.get("zmap") or "",
                    "zmap_png": run_folder.zmap_png(b.get("zmap")),
                    "metrics": deltas, "time": _time_text(j.get("time"))})
    return out


def verdict_word(row):
    """The first column: CHANGED, UNJUDGED (nothing changed that could be judged, something could
    not be), unstable (nothing changed beyond noise, but a verdict flipped: a check at the edge of
    its power) or same."""
    return ("CHANGED" if row["changed"] else "UNJUDGED" if row["unjudged"] else
            "unstable" if row.get("unstable") else "same")


def markdown(result):
    from .markdown import cell as _cell
    rs = rows(result)
    n_changed = sum(r["changed"] for r in rs)
    n_unjudged = sum(r["unjudged"] and not r["changed"] for r in rs)
    n_unstable = sum(verdict_word(r) == "unstable" for r in rs)
    head = (f"# Changes from {_cell(result['old'])} to {_cell(result['new'])}\n\n"
            f"{len(rs)} jobs in both: {n_changed} changed, {n_unjudged} not judged, "
            f"{len(rs) - n_changed - n_unjudged} without a change beyond noise"
            + (f" ({n_unstable} of them with a verdict that flipped within noise: unstable)" if n_unstable else "") + "; "
            f"{len(result['new_jobs'])} new, {len(result['missing_jobs'])} missing. Renders judged against each other "
            "on both their noises (two-sample block test, Sidak-corrected), probes compared; time as the ratio of "
            "the median pass times (new / old) with its spread.\n\n")
    table = ["| changed | scene | backend | mode | status | what changed | image | how much | where (z-map) | metrics | time |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rs:
        table.append("| " + " | ".join(_cell(x) for x in (verdict_word(r), r["scene"], r["backend"],
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
        r["zmap_src"] = run_folder.local_url(Path(out_dir), r["zmap_png"]) if r["zmap_png"] else None
        r["word"] = verdict_word(r)
    return html._env.get_template("compare.html").render(
        old=result["old"], new=result["new"], rows=rs, new_jobs=result["new_jobs"], missing=result["missing_jobs"],
        changed=sum(r["changed"] for r in rs), unjudged=sum(r["unjudged"] and not r["changed"] for r in rs))


# -- the output folder: made here or empty, never deleted, nothing written through a link ----------
def _resolved(path):
    return Path(os.path.abspath(path)).resolve()


def check_output(out_dir, old, new, default=False):
    """OutputRefused when ``out_dir`` is OLD or NEW, contains either, or lies inside OLD (or inside
    NEW, unless it is the default NEW/compare), naming it and why."""
    o = _resolved(out_dir)
    label = f"the output folder {out_dir} (give another with -o DIR)" if default else f"-o {out_dir}"
    for name, folder in (("OLD", _resolved(old)), ("NEW", _resolved(new))):
        if o == folder:
            raise OutputRefused(f"{label}: is {name} ({folder}); the comparison never writes into a run's folder")
        if folder.is_relative_to(o):
            raise OutputRefused(f"{label}: contains {name} ({folder}); give a folder of its own")
        if o.is_relative_to(folder) and not (default and name == "NEW"):
            raise OutputRefused(f"{label}: lies inside {name} ({folder}); give a folder outside both runs "
                                "(without -o the comparison goes to NEW/compare)")


def _empty_folder(path):
    """Whether ``path`` is a real (not linked) folder with nothing in it."""
    try:
        st = os.lstat(path)
        return stat.S_ISDIR(st.st_mode) and not os.listdir(path)
    except OSError:
        return False


def make_output(out_dir, fresh=False):
    """The folder the comparison is written to: ``out_dir`` made here (its parents as needed) or
    already there and empty; with ``fresh`` (the default NEW/compare) the first of out_dir,
    out_dir-2, out_dir-3, ... that is new or empty. Never deletes; refuses (OutputRefused) an
    ``out_dir`` that holds anything or is a link."""
    out_dir = Path(out_dir)
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputRefused(f"cannot make the output folder {out_dir}: {exc.strerror or exc}") from None
    names = [out_dir] + ([out_dir.with_name(f"{out_dir.name}-{k}") for k in range(2, MAX_FRESH)] if fresh else [])
    for path in names:
        try:
            os.mkdir(path)
            return path
        except FileExistsError:
            if _empty_folder(path):
                return path
        except OSError as exc:
            raise OutputRefused(f"cannot make the output folder {path}: {exc.strerror or exc}"
                                + (" (give another with -o DIR)" if fresh else "")) from None
    if fresh:
        raise OutputRefused(f"{out_dir} and {out_dir.name}-2 ... -{MAX_FRESH - 1} are all taken: remove earlier comparisons")
    raise OutputRefused(f"-o {out_dir}: exists and is not an empty folder; compare_runs never deletes or overwrites "
                        "one: remove it or give a new folder")


def _write_new(path, text):
    """Create ``path`` (it must not exist; a link there is not followed) and write ``text``."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o666)
    with open(fd, "w", encoding="utf-8") as f:
        f.write(text)


def write(result, out_dir):
    """compare.md, compare.html and compare.json, each a new file in ``out_dir`` (``make_output``)."""
    out_dir = Path(out_dir)
    text = markdown(result)
    _write_new(out_dir / "compare.md", text)
    _write_new(out_dir / "compare.html", html_page(result, out_dir))
    _write_new(out_dir / "compare.json", json.dumps(result, indent=1, default=str) + "\n")
    return text


def run(old, new, out=None, settings=None):
    """Compare the runs in ``old`` and ``new`` into ``out`` (default NEW/compare, or the first free
    NEW/compare-N) and write the three files: (result, output folder, markdown). Raises
    run_folder.NotARun for a folder that is not a run, OutputRefused for an output folder
    refused (both exit 2), OSError for one that cannot be written."""
    for folder in (old, new):
        run_folder.read(folder)
    default = out is None
    out_dir = Path(new) / run_folder.COMPARE_DIR if default else Path(out)
    check_output(out_dir, old, new, default)
    out_dir = make_output(out_dir, fresh=default)
    result = compare(old, new, out_dir, settings)
    return result, out_dir, write(result, out_dir)


def _printable(text):
    """``text`` for a terminal: control characters (from a metrics.json: anyone's text) escaped."""
    return "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)


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
    settings = {"alpha": args.alpha, "min_samples": args.min_samples, "block": args.block}
    try:
        result, out_dir, text = run(args.old, args.new, args.out, settings)
    except (run_folder.NotARun, OutputRefused) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f"error: cannot write the comparison: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    except Exception:  # noqa: BLE001 - a bug here must not read as exit 1 ("changed")
        traceback.print_exc()
        print("error: internal error while comparing (above); nothing was judged", file=sys.stderr)
        return EXIT_USAGE
    print(text)
    for j in result["jobs"]:
        for why in j["unjudged"]:
            print(_printable(f"error: {j['scene']} / {j['backend']} {j['mode'] or ''}: not judged: {why}"[:2000]),
                  file=sys.stderr)
    print(f"written to {out_dir}", file=sys.stderr)
    return exit_code(result)

