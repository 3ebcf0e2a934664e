"""Calibration of the verdicts on real renders at the product's default settings (not timings).

    .venv/bin/python benchmarks/calibrate_noise_test.py [--seeds 20] [-s SCENE ...] [--write]
    .venv/bin/python benchmarks/calibrate_noise_test.py --smoke -s ggx_copper_50   # seconds: 1 seed, 8 spp, 1/4 size; not recorded

False alarms: every canonical scene (every case, every channel: R, G, B and S0..S3), rendered at
its own resolution and sample count in two passes with new seeds, judged exactly as the runner
judges it (batch/verdict/judge.py: the noise test on the render's own noise against the committed
reference, the analytic probes, the known deviations). A calibrated test at alpha 0.01 fails about
1 % of unbiased renders. Power: deliberately wrong variants of a scene, rendered and judged as the
scene they claim to be. --write prepends the tables to benchmarks/CALIBRATION.md.
"""
import argparse
import collections
import copy
import datetime as dt
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import pkg_bootstrap  # noqa: E402

SMOKE_SPP = 8  # --smoke: every render at 8 spp (the figures mean nothing)
# --smoke: every render at 1/4 of the scene's resolution (an integer fraction, as the runner's --scale): a
# wrong variant's failed verdict is diagnosed (the judge's model fits), whose cost grows with the pixels
SMOKE_SCALE = 0.25
SEED0 = 10_000  # distinct from the runner's (0) and the references' (1000 + pass * 1000)


def _objects(sc, pred):
    return [o for o in sc["objects"] if pred(o)]


def variants():
    """{scene: [(label, change)]}: each change makes the render wrong in one known way."""
    def conductor(sc, name):
        for o in _objects(sc, lambda o: (o.get("bsdf") or {}).get("type") == "conductor"):
            o["bsdf"].pop("eta", None), o["bsdf"].pop("k", None)
            o["bsdf"]["material"] = name

    def alpha(sc, a):
        for o in _objects(sc, lambda o: (o.get("bsdf") or {}).get("roughness")):
            o["bsdf"]["roughness"]["alpha"] = a

    def brighter(radiance, f):
        # a constant spectrum is its value (its exporters ignore "scale"): before 2026-12-01 the
        # variant left polarizing_spheres' constant environment unchanged and "missed" nothing
        if radiance.get("type") == "constant":
            radiance["value"] *= f
        else:
            radiance["scale"] = radiance.get("scale", 1.0) * f

    def light(sc, f):
        for o in _objects(sc, lambda o: o.get("emitter")):
            brighter(o["emitter"].get("radiance") or o["emitter"]["irradiance"], f)
        if sc.get("environment"):
            brighter(sc["environment"]["radiance"], f)

    def illuminant(sc, name):
        sc["environment"]["radiance"]["name"] = name

    def polariser(sc, d):
        sc["camera"]["polarizer"]["angle"] += d

    def film(sc, d):
        for o in _objects(sc, lambda o: (o.get("bsdf") or {}).get("thin_film")):
            o["bsdf"]["thin_film"]["thickness"] += d

    def glass(sc, name):
        for o in _objects(sc, lambda o: isinstance((o.get("bsdf") or {}).get("int_ior"), dict)):
            o["bsdf"]["int_ior"] = {"type": "named", "name": name}
    return {
        "ggx_copper_50": [("Au instead of Cu", lambda s: conductor(s, "Au")), ("alpha 0.2 -> 0.22", lambda s: alpha(s, 0.22)),
                          ("light +1 %", lambda s: light(s, 1.01))],
        "ggx_copper_50_isolated": [("alpha 0.2 -> 0.22", lambda s: alpha(s, 0.22)), ("light +1 %", lambda s: light(s, 1.01))],
        "ggx_glass": [("alpha 0.2 -> 0.22", lambda s: alpha(s, 0.22)), ("light +1 %", lambda s: light(s, 1.01))],
        "macbeth_chart_D65": [("illuminant +1 %", lambda s: light(s, 1.01)),
                              ("D50 for D65", lambda s: illuminant(s, "cie_d50"))],
        "polarizing_plane_0": [("polariser +5 deg", lambda s: polariser(s, 5.0)), ("light +1 %", lambda s: light(s, 1.01))],
        "polarizing_spheres": [("light +1 %", lambda s: light(s, 1.01))],
        "iridescent_sphere_smooth": [("film 10 nm thinner", lambda s: film(s, -10.0))],
        "dispersion_prism": [("fused silica for N-BK7", lambda s: glass(s, "fused_silica")),
                             ("beam +1 %", lambda s: light(s, 1.01))],
    }


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, scene_sources
    from spectral_bench.batch.jobs import engines, job as jobs, plan
    from spectral_bench.batch.verdict import known

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("-s", "--scene", action="append")
    ap.add_argument("--smoke", action="store_true", help=f"checks that the script runs: one seed, every render at "
                    f"{SMOKE_SPP} spp and scale {SMOKE_SCALE}; never recorded")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    if args.smoke and args.write:
        ap.error("--smoke checks that the script runs; its figures are never recorded: leave out --write")
    if args.smoke:
        args.seeds = 1
    spp_of = (lambda sc: SMOKE_SPP) if args.smoke else (lambda sc: sc["render"]["spp"])
    settings = plan.verdict_settings({"alpha": 0.01, "min_samples": 65536, "block": None, "flip": False,
                                      "references": None, "known": None})
    backend = backends.get("mitsuba")
    scenes = {n: s for n, s in scene_sources.load([str(scene_sources.DEFAULT_BLEND)]) if isinstance(s, dict)
              and (not args.scene or n in args.scene)}
    sources = dict(scenes)  # as committed: what the references were made from (their staleness check)
    if args.smoke:
        scenes = {n: plan.for_run(s, {"scale": SMOKE_SCALE}) for n, s in scenes.items()}
    deviations = known.load()
    outcomes = collections.defaultdict(list)
    power = []
    with tempfile.TemporaryDirectory() as tmp:
        job_list = []
        for name, sc in scenes.items():
            mode, _ = backend.mode_for(sc)
            for k in range(args.seeds):
                job_list.append(jobs.make("render", name, sc, "mitsuba", mode, spp_of(sc), tmp,
                                          f"{name}/seed{k}", passes=2, seed=SEED0 + 100 * k, source_scene=sources[name],
                                          verdict=settings, label=f"{name} seed {k}"))

        def unbiased(job, entry):
            outcomes[job["scene_name"]].append(entry)
            print(f"{job['label']}: {entry['status']}", flush=True)
        engines.LocalEngine(deviations).map(job_list, unbiased)
        for name, changes in variants().items():
            if name not in scenes:
                continue
            sc = scenes[name]
            for label, change in changes:
                wrong = copy.deepcopy(sc)
                change(wrong)
                mode, _ = backend.mode_for(wrong)
                job = jobs.make("render", name, wrong, "mitsuba", mode, spp_of(sc), tmp,
                                f"{name}/wrong_{len(power)}", passes=2, seed=SEED0 - 1, source_scene=sources[name],
                                verdict=settings)
                record = jobs.execute(job)
                claimed = dict(job, scene=sc)  # judged as the scene it claims to be
                entry = jobs.judge(claimed, record, deviations)
                failing = [p["name"] for p in entry["probes"] if p["pass"] is False]
                test = entry.get("test") or {}
                power.append(f"| {name} | {label} | {entry['status']} | "
                             f"{'fail' if test.get('pass') is False else 'pass' if test.get('pass') else 'not judged'} "
                             f"(max abs z {test.get('z_max', float('nan')):.1f}) | "
                             f"{', '.join(failing[:3]) + (' ...' if len(failing) > 3 else '') or 'none'} |")
                print(power[-1], flush=True)
    rows = []
    for name in sorted(outcomes):
        es = outcomes[name]
        tests = [e["test"] for e in es if e.get("test") and e["test"].get("pass") is not None]
        fa_test = sum(not t["pass"] for t in tests)
        probe_runs = [e for e in es if any(p["pass"] is not None for p in e["probes"])]
        fa_probe = sum(any(p["pass"] is False for p in e["probes"]) for e in probe_runs)
        med = float(np.median([t["p_min"] * t["tests"] for t in tests])) if tests else float("nan")
        statuses = collections.Counter(e["status"] for e in es)
        channels = len(es[0].get("channels") or [])
        rows.append(f"| {name} | {channels} | {tests[0]['block'] if tests else ''} | "
                    f"{tests[0]['tests'] if tests else ''} | {fa_test}/{len(tests)} | {med:.2f} | "
                    f"{fa_probe}/{len(probe_runs)} | {', '.join(f'{n} {s}' for s, n in sorted(statuses.items()))} |")
    text = "\n".join([
        f"## Verdicts at default settings, {dt.date.today().isoformat()}: each scene's resolution and "
        f"{'spp' if not args.smoke else f'{SMOKE_SPP} spp at scale {SMOKE_SCALE} (--smoke)'}, "
        f"2 passes, alpha 0.01, {args.seeds} seeds per scene, {os.cpu_count()} cores",
        "", "False alarms on unbiased renders (the noise test on the render's own noise, every channel; the probes "
        "with their Sidak-corrected tests; the status with the known deviations applied):", "",
        "| scene | channels | block (px) | tests | noise test failed | median p_min x tests | probes failed | statuses |",
        "|---|---|---|---|---|---|---|---|", *rows,
        "", "Power: wrong variants rendered once (seed 9999) and judged as the scene they claim to be:", "",
        "| scene | wrong variant | status | noise test | failing probes |", "|---|---|---|---|---|", *power, ""])
    print(text)
    if args.write:
        from record import prepend
        prepend(Path(__file__).resolve().parent / "CALIBRATION.md", "# Calibration\n\n", text)


if __name__ == "__main__":
    main()
