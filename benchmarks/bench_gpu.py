"""Mitsuba on the GPU (cuda_ad_* variants) against the CPU, in one run (issue 23's benchmark).

    .venv/bin/python benchmarks/bench_gpu.py [--scale 1.0] [--ref-spp 1024] [--ref-scene S ...] [--write]
    .venv/bin/python benchmarks/bench_gpu.py --smoke     # seconds: tiny settings, checks the script runs

1. The default suite (every canonical scene, the Mitsuba backend, the product's default settings)
   with ``--device gpu`` and with ``--device cpu``: wall time, the sum of the renders' times, the
   jobs' statuses (a GPU render is judged against the CPU-made references like any other) and the
   exit status.
2. The reference maker (batch/make_references.py, default 8 passes) for 2-3 scenes at 1024 spp on
   each device: wall time.

Prints a Markdown table naming the devices; ``--write`` records it in benchmarks/GPU.md. Where
CUDA does not render (batch/backends/mitsuba/cuda.py's probe), it measures nothing and prints (and with
``--write`` records) that it was not measured, and why. Sized to finish within 10 minutes on one
H200 with 16 cores (``--budget`` seconds in all, default 570: a step that would run past it is
stopped and named in the table).
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
sys.path.insert(0, str(ROOT))
from record import machine, prepend  # noqa: E402

RESULTS = ROOT / "benchmarks" / "GPU.md"
HEAD = "# Mitsuba on the GPU against the CPU\n\nRecorded by `benchmarks/bench_gpu.py --write`; newest first.\n\n"
COMMAND = ".venv/bin/python benchmarks/bench_gpu.py --write"
REF_SCENES = ("ggx_copper_50", "macbeth_chart_D65", "iridescent_sphere_smooth")  # RGB, spectral, thin-film plugin


def cuda_probe():
    """(usable, message) of the product's own CUDA probe."""
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch.backends.mitsuba import cuda
    return cuda.find()


def gpu_name():
    try:
        proc = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True,
                              text=True, timeout=30)
        names = [n.strip() for n in proc.stdout.splitlines() if n.strip()]
        return ", ".join(names) or "a CUDA device"
    except (OSError, subprocess.SubprocessError):
        return "a CUDA device"


class Clock:
    """The run's time budget: each step gets what is left."""

    def __init__(self, budget):
        self.end = time.monotonic() + budget

    def left(self):
        return max(1.0, self.end - time.monotonic())


def timed(args, clock):
    """(exit status or "timed out", wall seconds) of one command within the clock's budget."""
    t0 = time.perf_counter()
    try:
        code = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, timeout=clock.left()).returncode
    except subprocess.TimeoutExpired:
        code = "timed out"
    return code, time.perf_counter() - t0


def suite(out, device, scale, spp, clock):
    args = [sys.executable, str(ROOT / "batch" / "run.py"), "-r", "mitsuba", "--device", device, "-o", str(out)]
    args += ["--scale", str(scale)] if scale != 1.0 else []
    args += ["--spp", str(spp)] if spp else []
    code, wall = timed(args, clock)
    try:
        runs = json.loads((Path(out) / "metrics.json").read_text())["runs"]
    except (OSError, ValueError, KeyError):
        runs = []
    rendered = [r for r in runs if r.get("wall_s")]
    statuses = {}
    for r in runs:
        statuses[r.get("status")] = statuses.get(r.get("status"), 0) + 1
    modes = sorted({r.get("mode", "") for r in rendered})
    return {"wall_s": wall, "renders_s": sum(r["wall_s"] for r in rendered), "jobs": len(rendered),
            "statuses": statuses, "exit": code, "modes": modes}


def references(out, device, scenes, spp, scale, clock):
    args = [sys.executable, str(ROOT / "batch" / "make_references.py"), "--device", device, "--spp", str(spp),
            "--out", str(out)]
    args += ["--scale", str(scale)] if scale != 1.0 else []
    for s in scenes:
        args += ["-s", s]
    code, wall = timed(args, clock)
    return {"wall_s": wall, "exit": code}


def not_measured(why, args):
    return (f"Not measured: {why}.\n\nMachine: {machine()}; Python {platform.python_version()}.\n\n"
            f"Run `{COMMAND}` on a machine with an NVIDIA GPU (Mitsuba's cuda_ad_* variants; "
            f"about 10 minutes on one H200) to record the table.")


def ratio(a, b):
    """a / b as "1.23x", or "-" where b is nothing (no job rendered)."""
    return f"{a / b:.2f}x" if b > 0 else "-"


def table(gpu, rows, refs, args):
    text = [f"GPU: {gpu}. CPU: {machine()}; Python {platform.python_version()}; suite scale {args.scale:g}"
            + (f", --spp {args.spp}" if args.spp else ", each scene's default spp") + ".", "",
            "| device | default suite | jobs | wall s | sum of render wall s | wall / renders | statuses | exit |",
            "|---|---|---|---|---|---|---|---|"]
    for label, r in rows:
        st = ", ".join(f"{k} {v}" for k, v in sorted(r["statuses"].items(), key=lambda kv: str(kv[0])))
        text.append(f"| {label} | {' '.join(r['modes']) or '-'} | {r['jobs']} | {r['wall_s']:.1f} | {r['renders_s']:.1f} | "
                    f"{ratio(r['wall_s'], r['renders_s'])} | {st or '-'} | {r['exit']} |")
    (g_label, g), (c_label, c) = rows
    text += ["", f"Default suite: GPU {g['wall_s']:.1f} s wall against CPU {c['wall_s']:.1f} s "
             f"(CPU / GPU {ratio(c['wall_s'], g['wall_s'])}); renders {g['renders_s']:.1f} s against "
             f"{c['renders_s']:.1f} s (CPU / GPU {ratio(c['renders_s'], g['renders_s'])}).", "",
             f"| device | reference maker: {', '.join(args.ref_scene)} at {args.ref_spp} spp (8 passes) | wall s | exit |",
             "|---|---|---|---|"]
    for label, r in refs:
        text.append(f"| {label} | | {r['wall_s']:.1f} | {r['exit']} |")
    return "\n".join(text)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=1.0, help="the suite's --scale (default 1.0)")
    ap.add_argument("--spp", type=int, default=None, help="the suite's --spp (default: each scene's own)")
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--ref-scene", action="append", default=None, help=f"default: {', '.join(REF_SCENES)}")
    ap.add_argument("--budget", type=float, default=570.0, help="seconds for the whole run (default 570)")
    ap.add_argument("--smoke", action="store_true", help="tiny settings (scale 0.125, 4 spp, one reference at 16 spp)")
    ap.add_argument("--write", action="store_true", help="record the table (or why none) in benchmarks/GPU.md")
    args = ap.parse_args(argv)
    if args.smoke:
        args.scale, args.spp, args.ref_spp = 0.125, 4, 16
        args.ref_scene = args.ref_scene or ["ggx_copper_50"]
    args.ref_scene = args.ref_scene or list(REF_SCENES)
    usable, message = cuda_probe()
    if not usable:
        text = not_measured(f"no CUDA device ({message})", args)
    else:
        gpu = gpu_name()
        clock = Clock(args.budget)
        rows, refs = [], []
        with tempfile.TemporaryDirectory() as tmp:
            for device, label in (("gpu", f"GPU: {gpu}"), ("cpu", "CPU")):
                r = suite(Path(tmp) / f"suite_{device}", device, args.scale, args.spp, clock)
                rows.append((label, r))
                print(label, r, flush=True)
            for device, label in (("gpu", f"GPU: {gpu}"), ("cpu", "CPU")):
                r = references(Path(tmp) / f"refs_{device}", device, args.ref_scene, args.ref_spp, args.scale, clock)
                refs.append((label, r))
                print(label, r, flush=True)
        text = table(gpu, rows, refs, args)
    print(text, flush=True)
    if args.write:
        prepend(RESULTS, HEAD, f"## {dt.date.today().isoformat()}\n\n`benchmarks/bench_gpu.py`\n\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
