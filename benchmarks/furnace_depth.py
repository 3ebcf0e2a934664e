"""Stability where path tracing strains (issue 41 item 4): a grey furnace whose reflectance runs
toward 0.99 (paths of hundreds of bounces), rendered by Mitsuba 3's path tracer with and without
Russian roulette and at finite depths, error against time.

    .venv/bin/python benchmarks/furnace_depth.py [--rho 0.5 0.9 0.99] [--spp 4 16 64 256] [--write]

The scene is furnace_spiky's enclosure (golden/ir: a closed icosphere wound inwards about the
camera) with a constant reflectance rho and a constant emitted radiance Le = 1, so that every pixel
sees exactly the Neumann series (batch/verdict/probes/furnace.py):

    L_d = Le (1 - rho^d) / (1 - rho)    with max_depth d (segments, docs/scene-format.md),
    L   = Le / (1 - rho)                without a limit.

Each configuration (CONFIGS: Mitsuba's ``path`` integrator, max_depth and rr_depth) renders the
scene at every rung of the spp ladder in two passes (seeds 0 and 1) through the runner's Mitsuba
backend, which times each pass (after one untimed pass that compiles the kernels). Every rung is judged by the furnace probe twice, with the
probe's own test on the render's noise (the image mean against its pixels' spread, Sidak over the
channels; Mitsuba's film read as its observer "mitsuba3", as known_deviations.toml records it):

- "own depth": against the series truncated at the configuration's own max_depth, i.e. is the
  estimator right about what it claims to compute (a biased Russian roulette or a wrong depth
  convention fails here);
- "whole series": against L, i.e. does it converge to the furnace's radiance (a finite depth
  fails here once its noise falls below the truncation's rho^d / (1 - rho) share; the chart's line
  then flattens at that error).

The chart (one per rho, benchmarks/sweep_charts/furnace_rho_*.png, drawn by the sweep's own chart
function) plots the RMSE of the pixels against L (relative, per channel: L's colour as Mitsuba's
film reads it) over the render time; a line whose top
rung fails the whole-series test is labelled NOT CONVERGING. ``--write`` records the table in
benchmarks/FURNACE_DEPTH.md with the machine and the charts."""
import argparse
import copy
import datetime
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

ROOT = pkg_bootstrap.ROOT
BASE = "furnace_spiky"
# (label, max_depth (IR and Mitsuba: segments; -1 no limit), rr_depth (Mitsuba: the depth from
# which Russian roulette may end a path; = max_depth: never))
CONFIGS = (
    ("RR from depth 5, no limit (Mitsuba's default)", -1, 5),
    ("no RR, max depth 1000", 1000, 1000),
    ("RR from depth 5, max depth 64", 64, 5),
    ("RR from depth 5, max depth 16", 16, 5),
)
END_MARK = "<!-- end of the measured part: what follows is written by hand -->"
OBSERVER = "mitsuba3"  # Mitsuba's RGB film (known_deviations.toml: mitsuba-film-rgb)


def furnace_scene(rho, max_depth, width):
    """furnace_spiky's IR with a grey reflectance ``rho``, Le = 1 and ``max_depth``."""
    scene = json.loads((ROOT / "golden" / "ir" / f"{BASE}.json").read_text())
    scene = copy.deepcopy(scene)
    obj = scene["objects"][0]
    obj["bsdf"]["reflectance"] = {"type": "constant", "value": float(rho)}
    obj["emitter"]["radiance"] = {"type": "constant", "value": 1.0}
    scene["name"] = f"furnace_grey_{rho:g}"
    scene["render"].update(max_depth=int(max_depth), width=width, height=width)
    scene["_base_dir"] = str(ROOT / "golden" / "ir")
    return scene


def with_rr_depth(xml_path, rr_depth):
    """The exported Mitsuba scene with the path integrator's rr_depth set (not an IR field: the
    study's own knob)."""
    text = Path(xml_path).read_text()
    anchor = '<integer name="max_depth" value="$max_depth"'
    if anchor not in text:
        raise SystemExit(f"furnace_depth: the Mitsuba export of {xml_path} has no {anchor!r}: the writer changed")
    text = text.replace(anchor, f'<integer name="rr_depth" value="{int(rr_depth)}"/>\n    {anchor}', 1)
    Path(xml_path).write_text(text)


def judge(scene, names, image, d):
    """The furnace probe's image-mean record against the series truncated at ``d``."""
    from spectral_bench.batch.verdict import probes
    sc = copy.deepcopy(scene)
    sc["render"]["max_depth"] = d
    rec = next(p for p in probes.evaluate(sc, names, image, observers=(OBSERVER,))
               if p["name"].startswith("furnace ") and "image mean" in p["name"])
    return rec["alternatives"][OBSERVER]


def measure(rho, config, ladder, width, tmp):
    from spectral_bench.batch import backends, exr
    label, max_depth, rr_depth = config
    scene = furnace_scene(rho, max_depth, width)
    backend = backends.get("mitsuba")
    mode, why = backend.mode_for(scene)
    if mode is None:
        raise SystemExit(f"furnace_depth: Mitsuba cannot render the furnace: {why}")
    out = Path(tmp) / f"rho{rho:g}_d{max_depth}_rr{rr_depth}"
    xml = backend.export(scene, out / "mitsuba")
    with_rr_depth(xml, rr_depth)
    from spectral_bench.batch.verdict.probes import furnace
    obj = scene["objects"][0]
    # the whole series' colour as Mitsuba's film reads it (Le = 1 is no white in sRGB)
    whole = np.asarray(furnace.expected_rgb(obj["bsdf"]["reflectance"], obj["emitter"]["radiance"], -1, OBSERVER))
    # one untimed pass first: the LLVM variant compiles its kernels on the first render, which the
    # ladder's first rung would otherwise pay for
    backend.render(xml, mode, ladder[0], out / "warm-up.exr", passes=1, seed=99)
    points = []
    for spp in ladder:
        rec = backend.render(xml, mode, spp, out / f"{spp}.exr", passes=2, seed=0)
        names, img, _se = exr.read_image_and_stderr(out / f"{spp}.exr")
        rgb = img[..., [names.index(c) for c in "RGB"]].astype(np.float64)
        own, full = judge(scene, names, img, max_depth), judge(scene, names, img, -1)
        px = rgb.reshape(-1, 3) / whole - 1.0
        points.append({"spp": spp, "time_s": float(rec["time_s"]),
                       "rmse": float(np.sqrt(np.mean(px ** 2))),
                       "mean_rel": float(px.mean()), "mean_rel_se": float(px.mean(axis=1).std(ddof=1) / np.sqrt(len(px))),
                       "mean_rel_rgb": px.mean(axis=0).tolist(), "mean_rel_rgb_se": (px.std(axis=0, ddof=1) / np.sqrt(len(px))).tolist(),
                       "own": {"pass": bool(own["pass"]), "z": float(np.max(np.abs(own["z"])))},
                       "whole": {"pass": bool(full["pass"]), "z": float(np.max(np.abs(full["z"])))}})
    return {"rho": rho, "config": label, "max_depth": max_depth, "rr_depth": rr_depth, "mode": mode,
            "truncation": float(rho ** max_depth) if max_depth > 0 else 0.0, "points": points}


def line_for_chart(row):
    from spectral_bench.batch.studies import sweep
    spps, errs = [p["spp"] for p in row["points"]], [p["rmse"] for p in row["points"]]
    return {"backend": "mitsuba", "mode": row["config"], "points": row["points"],
            "slope": sweep.fit_slope(spps, errs), "converges": row["points"][-1]["whole"]["pass"]}


def table(rows):
    lines = ["| rho | configuration | truncated share rho^d | spp | time s (2 passes) | image mean / L - 1 "
             "| RMSE / L | own depth: z, verdict | whole series: z, verdict |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for p in r["points"]:
            lines.append(f"| {r['rho']:g} | {r['config']} | {r['truncation']:.3g} | {p['spp']} | {p['time_s']:.2f} | "
                         f"{100 * p['mean_rel']:+.3f} +- {100 * p['mean_rel_se']:.3f} % | {p['rmse']:.4f} | "
                         f"{p['own']['z']:.1f}, {'pass' if p['own']['pass'] else 'FAIL'} | "
                         f"{p['whole']['z']:.1f}, {'pass' if p['whole']['pass'] else 'FAIL'} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rho", type=float, nargs="+", default=[0.5, 0.9, 0.99])
    ap.add_argument("--spp", type=int, nargs="+", default=[4, 16, 64, 256], help="the ladder")
    ap.add_argument("--size", type=int, default=32, help="image width and height (pixels)")
    ap.add_argument("--config", type=int, action="append", help="only CONFIGS[i] (repeatable)")
    ap.add_argument("--write", action="store_true", help="record in benchmarks/FURNACE_DEPTH.md with charts")
    ap.add_argument("--json", help="also write the rows to this file")
    args = ap.parse_args(argv)
    if any(not 0.0 <= r < 1.0 for r in args.rho):
        ap.error("--rho: every reflectance in [0, 1)")
    pkg_bootstrap.package()
    configs = [CONFIGS[i] for i in args.config] if args.config else list(CONFIGS)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for rho in args.rho:
            for config in configs:
                rows.append(measure(rho, config, args.spp, args.size, tmp))
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    text = table(rows)
    print(text)
    if args.write:
        from spectral_bench.batch.studies import sweep
        sys.path.insert(0, str(ROOT / "benchmarks"))
        import record
        charts = ROOT / "benchmarks" / "sweep_charts"
        for rho in args.rho:
            lines = [line_for_chart(r) for r in rows if r["rho"] == rho]
            sweep.chart(str(charts / f"furnace_rho_{rho:g}"), f"grey furnace, rho {rho:g}", lines,
                        ylabel="RMSE / L, L = Le / (1 - rho) (relative, per channel)")
        load = os.getloadavg()
        head = (f"# Path depth and Russian roulette in a grey furnace\n\n"
                f"`benchmarks/furnace_depth.py --write` (--rho {' '.join(f'{r:g}' for r in args.rho)}, --spp "
                f"{' '.join(map(str, args.spp))}, {args.size} x {args.size}), {datetime.date.today().isoformat()}, "
                f"Mitsuba {rows[0]['mode']}, {record.machine()}, load average {load[0]:.1f} at the end. Times are "
                "the two passes' render seconds as the runner measures them (one measurement each, a shared "
                "machine: compare within a row's rho, not across machines). Charts: "
                + ", ".join(f"[rho {r:g}](sweep_charts/furnace_rho_{r:g}.png)" for r in args.rho) + ".\n\n")
        # the measured part between the markers; what is written by hand below them stays
        path = ROOT / "benchmarks" / "FURNACE_DEPTH.md"
        old = path.read_text() if path.exists() else ""
        rest = old.split(END_MARK, 1)[1] if END_MARK in old else "\n"
        path.write_text(head + text + "\n" + END_MARK + rest)
    return 0


if __name__ == "__main__":
    sys.exit(main())
