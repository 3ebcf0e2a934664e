"""The engines' overhead, measured side by side in one run (issue 10's benchmark).

    .venv/bin/python benchmarks/bench_engines.py [--scale 1.0] [--reference-scene ggx_copper_50] [--write]
    .venv/bin/python benchmarks/bench_engines.py --smoke   # seconds: one scene, tiny settings, one cluster size

1. The full default suite (every scene, the Mitsuba backend, the product's default settings) on
   the default engine: total wall time against the sum of its renders' wall times (each render's
   child process: scene loading, JIT and rendering; the physical floor on one machine, since a
   render uses every core). Target: within 1.15x.
2. The same suite on ``--cluster local:1`` and ``--cluster local:2``: wall time and the engine's
   overhead per job ((wall - sum of renders) / jobs).
3. The reference maker for one scene (8 passes) on 1 and on 2 Dask workers: wall time.

Prints a Markdown table; --write records it in benchmarks/ENGINES.md. Run it on a quiet machine.
"""
import argparse
import datetime as dt
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import machine  # noqa: E402



SMOKE_SUITE = ["-s", "ggx_copper_50", "--spp", "4"]  # --smoke: tiny settings, checks the script runs
SMOKE_REFERENCE = ["--spp", "16", "--passes", "2", "--scale", "0.125"]
ENGINES = (("default engine (this machine)", None), ("--cluster local:1", "local:1"), ("--cluster local:2", "local:2"))
WORKERS = (1, 2)  # the reference maker's Dask workers
SMOKE_ENGINES, SMOKE_WORKERS = ENGINES[:2], WORKERS[:1]  # --smoke: each code path once (local:2 is local:1's)


def suite(out, scale, cluster=None, extra=()):
    args = [sys.executable, str(ROOT / "batch" / "run.py"), "-r", "mitsuba", "-o", str(out), *extra]
    if scale != 1.0:
        args += ["--scale", str(scale)]
    if cluster:
        args += ["--cluster", cluster]
    t0 = time.perf_counter()
    proc = subprocess.run(args, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    runs = json.loads((Path(out) / "metrics.json").read_text())["runs"]
    rendered = [r for r in runs if r.get("wall_s")]
    return {"wall_s": wall, "renders_s": sum(r["wall_s"] for r in rendered), "jobs": len(rendered),
            "exit": proc.returncode}


def reference(scene, workers, out, extra=()):
    args = [sys.executable, str(ROOT / "batch" / "make_references.py"), "-s", scene, "--out", str(out),
            "--cluster", f"local:{workers}", *extra]
    t0 = time.perf_counter()
    subprocess.run(args, capture_output=True, text=True, cwd=ROOT, check=True)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--reference-scene", default="ggx_copper_50")
    ap.add_argument("--smoke", action="store_true", help="one scene at scale 0.125 and 4 spp, on the default engine "
                    "and local:1; a 16-spp reference on 1 worker")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    if args.smoke:
        args.scale, args.write = 0.125, False
    extra, ref_extra = (SMOKE_SUITE, SMOKE_REFERENCE) if args.smoke else ((), ())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, cluster in (SMOKE_ENGINES if args.smoke else ENGINES):
            r = suite(Path(tmp) / label.replace(" ", "_").replace(":", ""), args.scale, cluster, extra)
            r["label"] = label
            rows.append(r)
            print(label, r, flush=True)
        refs = {w: reference(args.reference_scene, w, Path(tmp) / f"ref{w}", ref_extra)
                for w in (SMOKE_WORKERS if args.smoke else WORKERS)}
    text = [f"Machine: {machine()}; "
            f"Python {platform.python_version()}; scale {args.scale}.", "",
            "| suite on | jobs | wall s | sum of render wall s | wall / renders | overhead per job s | exit |",
            "|---|---|---|---|---|---|---|"]
    for r in rows:
        text.append(f"| {r['label']} | {r['jobs']} | {r['wall_s']:.1f} | {r['renders_s']:.1f} | "
                    f"{r['wall_s'] / max(r['renders_s'], 1e-9):.2f}x | "
                    f"{(r['wall_s'] - r['renders_s']) / max(r['jobs'], 1):.2f} | {r['exit']} |")
    speed_up = f" ({refs[1] / refs[2]:.2f}x)" if 2 in refs else ""
    text += ["", f"Reference maker, {args.reference_scene} ({'tiny settings' if args.smoke else '4096 spp in 8 passes'}): "
             + ", ".join(f"{w} worker{'s' if w > 1 else ''} {t:.1f} s" for w, t in refs.items()) + f"{speed_up}."]
    table = "\n".join(text)
    print(table)
    if args.write:
        from record import prepend
        prepend(ROOT / "benchmarks" / "ENGINES.md", "# Engines: wall time against render time\n\n",
                f"## {dt.date.today().isoformat()}\n\n`benchmarks/bench_engines.py`\n\n{table}\n")


if __name__ == "__main__":
    main()
