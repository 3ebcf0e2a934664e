"""One full run of the RGB backends next to the spectral ones, recorded in benchmarks/RGB.md.

    .venv/bin/python benchmarks/bench_rgb_backends.py [--scale 0.5] [--passes 4] [--repeats 3] [--write]
    .venv/bin/python benchmarks/bench_rgb_backends.py --smoke --scale 0.25 --passes 2 --repeats 1   # seconds: 2 scenes, 4 spp (0.25: an integer fraction of every scene)

1. The batch (batch/run.py) on every scene with -r mitsuba -r art -r cycles -r luxcore (ART where
   an artist is installed), and the polarisation scenes again with --approximate for the RGB ones.
2. From its renders: the ColorChecker under D50 (and D65) in CIEDE2000 per patch, for every
   backend, next to what the reduction rule predicts without a renderer; GGX copper against the
   Mitsuba references (RMSE, the noise test, and the plate's mean against the reference's).
3. Timings: render time of one job per backend and scene from the run, and, for speed ratios,
   interleaved repeats (mitsuba, cycles, luxcore, mitsuba, ...) of ggx_copper_50 and
   macbeth_chart_D50 at the same scale and spp (medians), since the machine is shared.
--write replaces the "Recorded run" section of benchmarks/RGB.md with the tables.
"""
import argparse
import datetime as dt
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

BACKENDS = ["mitsuba", "art", "cycles", "luxcore"]
POLARISATION = ["polarizing_plane_0", "polarizing_plane_90", "polarizing_spheres"]
# --smoke: one scene of each table's kind, at 4 spp (the D65 chart's table is the D50 one's code: empty in a
# smoke run); the interleaved timing on the first of its scenes only (the same loop). Its figures mean nothing.
SMOKE_SCENES = ["ggx_copper_50", "macbeth_chart_D50"]
TIMED = ("ggx_copper_50", "macbeth_chart_D50")  # the interleaved repeats' scenes


def run_batch(out, args, extra):
    cmd = [sys.executable, str(ROOT / "batch" / "run.py"), "--scale", str(args.scale), "--passes", str(args.passes),
           "--no-flip", "-o", str(out), *extra]
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    return json.loads((out / "metrics.json").read_text())


def chart_table(out, runs, chart):
    from spectral_bench.batch import exr
    from spectral_bench.batch.studies import rgb_error
    from spectral_bench.exporters import ir_json
    cols, per = [], {}
    for b in BACKENDS:
        r = next((r for r in runs if r["scene"] == chart and r["backend"] == b and r.get("image")), None)
        if r is None:
            continue
        scene = ir_json.load(out / chart / "json" / f"{chart}.json")  # a chart this run rendered (--smoke: D50 alone)
        _, img = exr.read_image(out / r["image"])
        per[b] = rgb_error.chart_errors(scene, img)
        cols.append(b)
    if not per:
        return ""
    patches = list(next(iter(per.values())))
    rows = ["| patch | rule predicts | " + " | ".join(cols) + " |", "|---|---|" + "---|" * len(cols)]
    for p in patches:
        pred = next(iter(per.values()))[p][1]
        rows.append(f"| {p.replace('patch_', '')} | {pred:.2f} | " + " | ".join(f"{per[b][p][0]:.2f}" for b in cols) + " |")
    rows.append("| **mean** | {:.2f} | ".format(np.mean([next(iter(per.values()))[p][1] for p in patches]))
                + " | ".join(f"**{np.mean([per[b][p][0] for p in patches]):.2f}**" for b in cols) + " |")
    return "\n".join(rows)


def copper_table(out, runs):
    from spectral_bench.batch import exr
    rows = ["| scene | backend | mode | status | RMSE | relMSE | noise test p_min / threshold | max abs z | image mean / reference mean (R, G, B) |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(runs, key=lambda r: (r["scene"], BACKENDS.index(r["backend"]) if r["backend"] in BACKENDS else 9)):
        if not r["scene"].startswith("ggx_copper") or r["status"] in ("skipped",):
            continue
        m, t = r.get("metrics") or {}, r.get("test") or {}
        ratio = ""
        # the scene's shared reference (issue 21), or a render folder's own copy (older runs)
        ref_path = out / ((r.get("reference") or {}).get("image") or f"{r['scene']}/results/{r['backend']}/reference.exr")
        if r.get("image") and ref_path.is_file():
            _, img = exr.read_image(out / r["image"])
            ref = exr.read_rgb(ref_path)
            ratio = ", ".join(f"{a:.4f}" for a in img[..., :3].mean(axis=(0, 1)) / ref.mean(axis=(0, 1)))
        test = f"{t['p_min']:.2g} / {t['threshold']:.2g}" if t else ""
        rows.append(f"| {r['scene']} | {r['backend']} | {r.get('mode') or ''} | {r['status']} | "
                    f"{'' if m.get('rmse') is None else format(m['rmse'], '.4g')} | "
                    f"{'' if m.get('relmse') is None else format(m['relmse'], '.3g')} | {test} | "
                    f"{'' if not t else format(t['z_max'], '.1f')} | {ratio} |")
    return "\n".join(rows)


def timing_table(runs):
    scenes = sorted({r["scene"] for r in runs})
    rows = ["| scene | " + " | ".join(BACKENDS) + " |", "|---|" + "---|" * len(BACKENDS)]
    for s in scenes:
        cells = []
        for b in BACKENDS:
            r = next((r for r in runs if r["scene"] == s and r["backend"] == b), None)
            cells.append("" if r is None or r.get("time_s") is None else f"{r['time_s']:.2f} ({r['spp']} spp)")
        rows.append(f"| {s} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def interleaved(args):
    """Median render time per backend over interleaved repeats, same scene, spp and passes."""
    from spectral_bench.batch import backends, scene_sources
    from spectral_bench.batch.jobs.plan import for_run
    golden = dict(scene_sources.load([str(scene_sources.DEFAULT_BLEND)]))
    rows = ["| scene | resolution, spp | " + " | ".join(f"{b} median (s)" for b in ("mitsuba", "cycles", "luxcore"))
            + " | cycles / mitsuba | luxcore / mitsuba |", "|---|---|---|---|---|---|---|"]
    for name in TIMED[:1] if args.smoke else TIMED:
        sc = for_run(golden[name], {"spp": 4 if args.smoke else None, "scale": args.scale})
        times = {b: [] for b in ("mitsuba", "cycles", "luxcore")}
        with tempfile.TemporaryDirectory() as tmp:
            made = {b: backends.get(b) for b in times}
            paths = {b: made[b].export(sc, Path(tmp) / b) for b in times}
            for k in range(args.repeats):
                for b in times:
                    mode = made[b].mode_for(sc)[0]
                    info = made[b].render(paths[b], mode, sc["render"]["spp"], Path(tmp) / f"{b}{k}.exr",
                                          passes=args.passes, seed=10 * k)
                    times[b].append(info["time_s"])
        med = {b: statistics.median(v) for b, v in times.items()}
        rows.append(f"| {name} | {sc['render']['width']}x{sc['render']['height']}, {sc['render']['spp']} | "
                    + " | ".join(f"{med[b]:.2f}" for b in times)
                    + f" | {med['cycles'] / med['mitsuba']:.1f} | {med['luxcore'] / med['mitsuba']:.1f} |")
        print(rows[-1], flush=True)
    return "\n".join(rows)


def _table_only(markdown):
    """The table lines of a summary section (its own level-2 heading stays out of RGB.md)."""
    return "\n".join(l for l in markdown.splitlines() if l.startswith("|")) + "\n"


def main(argv=None):
    pkg_bootstrap.package()
    from spectral_bench.batch.report import summary
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=None)
    ap.add_argument("--smoke", action="store_true", help=f"seconds: {', '.join(SMOKE_SCENES)} and one polarisation "
                    "scene at 4 spp; not recorded")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    out = Path(args.out or tempfile.mkdtemp(prefix="rgb-bench-"))
    smoke = ["--spp", "4", *sum((["-s", s] for s in SMOKE_SCENES), [])] if args.smoke else []
    data = run_batch(out / "main", args, sum((["-r", b] for b in BACKENDS), []) + smoke)
    approx = run_batch(out / "approx", args, ["-r", "cycles", "-r", "luxcore", "--approximate"]
                       + sum((["-s", s] for s in (POLARISATION[:1] if args.smoke else POLARISATION)), [])
                       + (["--spp", "4"] if args.smoke else []))
    runs = data["runs"]
    versions = {}
    for r in runs:
        versions.update(r.get("versions") or {})
    text = [f"Recorded {dt.datetime.now().isoformat(timespec='minutes')} on {platform.machine()} "
            f"{platform.system()}, {os.cpu_count()} cores (shared with other sessions: times are indicative; the "
            f"ratios come from interleaved repeats). Scale {args.scale}, {args.passes} passes, each scene's own spp. "
            f"Versions: {json.dumps(versions)}.", "",
            "### Every scene: RMSE against the spectral reference, mean dE00 of the patch probes, status", "",
            _table_only(summary.rgb_comparison(runs)),
            "### Polarisation scenes with --approximate", "", _table_only(summary.rgb_comparison(approx["runs"])),
            "### ColorChecker under D50, CIEDE2000 per patch against the spectral truth", "",
            chart_table(out / "main", runs, "macbeth_chart_D50"), "",
            "### ColorChecker under D65, CIEDE2000 per patch", "", chart_table(out / "main", runs, "macbeth_chart_D65"), "",
            "### GGX copper against the Mitsuba references", "", copper_table(out / "main", runs), "",
            "### Render times of this run (s, one job each)", "", timing_table(runs), "",
            f"### Interleaved timing ({args.repeats} repeats each, medians of the render time)", "", interleaved(args), ""]
    body = "\n".join(text)
    print(body)
    print(f"outputs: {out}")
    if args.write and not args.smoke:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from record import replace_section
        replace_section(ROOT / "benchmarks" / "RGB.md", "Recorded run",
                        "`benchmarks/bench_rgb_backends.py --write`\n\n" + body)


if __name__ == "__main__":
    main()
