#!/usr/bin/env python3
"""How often the diagnosis (batch/verdict/diagnosis/) names a planted error first, at two sizes
(one near the detection limit, one gross) over many seeds, and how often a correct render gets
any diagnosis (must be never: a passing render is not diagnosed). Writes benchmarks/DIAGNOSIS.md.

Each plant is a declared renderer (tests/plant_renderer.py, ``--plant MODEL=VALUE``) written to a
temporary TOML; each seed one batch run at ``--scale`` and ``--spp`` (the run's own ``detectable``
is recorded beside each row, so a size below the run's power shows as such, not as a miss).

    .venv/bin/python benchmarks/bench_diagnosis.py [--seeds 20] [--scale 0.25] [--only scale,flip]

Cost: (plants x 2 sizes + 1) x seeds batch runs of one job each; at --scale 0.25 and the spp below,
about 10-30 s of CPU per run on one core.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "batch" / "run.py"
PLANTER = ROOT / "tests" / "plant_renderer.py"
TOY = ROOT / "examples" / "your_renderer" / "toy_renderer.py"

# name: (scene, spp, extra renderer arguments or None for the observer plant, expected model,
#        parameter, [(size label, plant value, planted parameter value)])
PLANTS = {
    "scale": ("ggx_copper_50", 256, [], "uniform scale", "scale",
              [("near limit", "1.004", 1.004), ("gross", "1.03", 1.03)]),
    "srgb": ("ggx_copper_50", 256, [], "sRGB transfer applied", None, [("gross", "applied", None)]),
    "flip": ("ggx_copper_50", 256, [], "flipped vertically", None, [("gross", "y", None)]),
    "alpha": ("ggx_copper_50", 256, [], "GGX alpha", "alpha", [("near limit", "0.202", 0.202), ("gross", "0.22", 0.22)]),
    "emitter": ("ggx_copper_50", 256, [], "emitter radiance x pi", "factor", [("gross", "pi", 3.141592653589793)]),
    "polariser": ("polarizing_plane_0", 256, ["--format", "stokes"], "polariser angle", "angle deg",
                  [("gross", "other", 90.0)]),
    "stokes_rotate": ("polarizing_spheres", 64, ["--format", "stokes_mono"], "Stokes frame rotated", "angle deg",
                      [("near limit", "0.5", 0.5), ("gross", "90", 90.0)]),
    "observer": ("macbeth_chart_D65", 64, None, "observer CIE 1964", None, [("gross", "cie1964", None)]),
    "stain": ("ggx_copper_50", 256, [], None, None, [("near limit", "0.02", None), ("gross", "0.3", None)]),
}


def declaration(name, plant, value, extra):
    if extra is None:  # the observer: the example renderer's bands integrated with it by the benchmark
        cmd = ["{python}", str(TOY), "{scene}", "--out", "{output}", "--spp", "{spp}", "--seed", "{seed}",
               "--format", "spectral"]
        return {"command": cmd, "reads": "mitsuba", "writes": "spectral", "observer": value, "models": ["spectral"]}
    cmd = ["{python}", str(PLANTER), "{scene}", "--out", "{output}", "--spp", "{spp}", "--seed", "{seed}", *extra]
    if plant:
        cmd += ["--plant", f"{plant}={value}"]
    models = ["spectral", "polarization"] if extra else ["spectral"]
    return {"command": cmd, "reads": "mitsuba", "models": models}


def toml(name, table):
    def q(v):
        return json.dumps(v)
    lines = [f"[renderers.{name}]"]
    for k, v in table.items():
        lines.append(f"{k} = [{', '.join(q(x) for x in v)}]" if isinstance(v, list) else f"{k} = {q(v)}")
    return "\n".join(lines) + "\n"


def run_one(tmp, name, table, scene, spp, seed, scale):
    path = tmp / f"{name}.toml"
    path.write_text(toml(name, table))
    out = Path(tempfile.mkdtemp(dir=tmp, prefix=f"{name}_{seed}_")) / "run"  # a fresh folder for every run
    t = time.perf_counter()
    subprocess.run([sys.executable, str(RUN), "--renderers", str(path), "-r", name, "-s", scene, "--scale", str(scale),
                    "--spp", str(spp), "--seed", str(seed), "-o", str(out)], capture_output=True, text=True,
                   timeout=3600, cwd=ROOT)
    runs = json.loads((out / "metrics.json").read_text())["runs"]
    return runs[0], time.perf_counter() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--only", default="")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "DIAGNOSIS.md"))
    args = ap.parse_args(argv)
    only = [p for p in args.only.split(",") if p]
    rows = []
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        cases = [(p, *PLANTS[p]) for p in PLANTS if not only or p in only]
        # the correct render, on every scene a plant uses
        for scene, spp, extra in sorted({(c[1], c[2], tuple(c[3]) if c[3] is not None else ()) for c in cases}):
            diagnosed = 0
            for seed in range(args.seeds):
                run, _ = run_one(tmp, "plant_none", declaration("plant_none", None, None, list(extra)), scene, spp,
                                 seed, args.scale)
                diagnosed += "diagnosis" in run
            rows.append(("correct render", scene, "-", f"{diagnosed}/{args.seeds} diagnosed", "", "", ""))
        for plant, scene, spp, extra, model, param, sizes in cases:
            for label, value, planted in sizes:
                first = within = failed = 0
                dets, walls = [], []
                for seed in range(args.seeds):
                    run, wall = run_one(tmp, f"plant_{plant}", declaration(f"plant_{plant}", plant, value, extra),
                                        scene, spp, seed, args.scale)
                    walls.append(wall)
                    dets.append((run.get("detectable") or {}).get("scale"))
                    failed += run["status"] == "failed"
                    diag = run.get("diagnosis") or {}
                    top = (diag.get("models") or [None])[0]
                    print(f"{plant}={value} seed {seed}: {run['status']}; {diag.get('text', 'no diagnosis')}", flush=True)
                    if model is None:
                        first += run["status"] == "failed" and diag.get("likely") is None
                    elif top and top["model"] == model:
                        first += 1
                        if param is None or abs(top["params"][param][0] - planted) <= 2 * (top["params"][param][1] or 0):
                            within += 1
                det = statistics.median([d for d in dets if d is not None]) if any(dets) else None
                rows.append((f"{plant}={value}", scene, label, f"{failed}/{args.seeds} failed",
                             f"{first}/{args.seeds}" + (" no model" if model is None else " first"),
                             f"{within}/{args.seeds}" if model and param else "",
                             f"{det:.4f}" if det else ""))
    load = os.getloadavg()[0]
    text = ["# Diagnosis: planted errors named first (benchmarks/bench_diagnosis.py)", "",
            f"{args.seeds} seeds, --scale {args.scale}; load average {load:.1f} on {os.cpu_count()} cores.", "",
            "| plant | scene | size | failed | ranked first (stain: no model explains it) | within 2 se | median detectable |",
            "|---|---|---|---|---|---|---|"]
    text += ["| " + " | ".join(r) + " |" for r in rows]
    Path(args.out).write_text("\n".join(text) + "\n")
    print("\n".join(text))


if __name__ == "__main__":
    sys.exit(main())
