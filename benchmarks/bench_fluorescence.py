"""Time sb_fluorescent_path against Mitsuba's stock ``path`` integrator (llvm_ad_spectral, same
spp, same scene), interleaved A, B, A, B, ... in fresh child processes, medians and their ratio.

    .venv/bin/python benchmarks/bench_fluorescence.py [--scale 1] [--spp 64] [--rounds 5] [--write]

Rows:
- yellow_sphere_F8 (no fluorescence): the same scene.xml with ``path`` or with
  ``sb_fluorescent_path``: the price of the Python integrator itself. Target: within 1.3x.
- fluorescent_sphere_D50_red: ``sb_fluorescent_path`` re-radiating against ``path`` on the same
  scene with the sphere's elastic part only (a stock ``diffuse``): the price of fluorescence.

Each child process loads the scene, renders once (tracing and JIT compilation: "cold") and then
``--repeat`` more times ("warm": Dr.Jit re-traces every render call, Python integrator included,
but reuses the compiled kernel); its warm median is one sample of the round, and the ratio is the
median over rounds of the two back-to-back samples' ratio (the machine's load drifts between
rounds, far less within one). Prints a Markdown
table; --write records it in benchmarks/RESULTS.md. The numbers are only as good as the machine's
idleness: the ratio is what an interleaved run protects.
"""
import argparse
import datetime as dt
import json
import platform
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import pkg_bootstrap  # noqa: E402
from record import machine  # noqa: E402

TARGET = 1.3
VARIANT = "llvm_ad_spectral"
CHILD = r'''
import json, sys, time
import drjit as dr, mitsuba as mi
mi.set_variant(sys.argv[2])
sys.path.insert(0, sys.argv[1]); import load_plugins; load_plugins.register()
scene = mi.load_file(sys.argv[1] + "/scene.xml")
spp, repeat = int(sys.argv[3]), int(sys.argv[4])
times = []
for k in range(repeat + 1):
    t = time.perf_counter(); img = mi.render(scene, spp=spp, seed=k); dr.eval(img); dr.sync_thread()
    times.append(time.perf_counter() - t)
print(json.dumps({"cold": times[0], "warm": sorted(times[1:])[len(times[1:]) // 2]}))
'''



def export_pair(scene, out, elastic_only=False):
    """Two folders rendering ``scene``: (stock path, sb_fluorescent_path). With ``elastic_only``
    the stock folder has the fluorescence removed (a plain diffuse sphere)."""
    import copy
    from spectral_bench.exporters import mitsuba_plugins, mitsuba_writer
    stock_scene = copy.deepcopy(scene)
    if elastic_only:
        for obj in stock_scene["objects"]:
            (obj.get("bsdf") or {}).pop("fluorescence", None)
        stock_scene["needs"] = [n for n in stock_scene["needs"] if n != "fluorescence"]
    stock = mitsuba_writer.write(stock_scene, out / "path").parent
    ours = mitsuba_writer.write(scene, out / "sb_fluorescent_path").parent
    xml = (ours / "scene.xml").read_text()
    if 'type="sb_fluorescent_path"' not in xml:
        xml = re.sub(r'<integrator type="path">', '<integrator type="sb_fluorescent_path">', xml, count=1)
        (ours / "scene.xml").write_text(xml)
        mitsuba_plugins.write_into(ours, {"sb_fluorescent_path"})
    for folder in (stock,):
        if not (folder / "load_plugins.py").exists():  # a uniform child: registering nothing is fine
            mitsuba_plugins.write_into(folder, set())
    return stock, ours


def time_once(folder, spp, repeat):
    from spectral_bench.batch.backends.mitsuba import llvm
    proc = subprocess.run([sys.executable, "-c", CHILD, str(folder), VARIANT, str(spp), str(repeat)],
                          capture_output=True, text=True, env=llvm.env(), timeout=1800)
    if proc.returncode != 0:
        raise RuntimeError(proc.stderr[-2000:])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.backends.mitsuba import llvm
    from spectral_bench.batch.jobs import plan

    ap = argparse.ArgumentParser()
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=3, help="warm renders per child process")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    if llvm.find()[0] is None:
        raise SystemExit(f"needs Mitsuba's LLVM variants: {llvm.find()[1]}")

    scenes = dict(scene_sources.load([str(scene_sources.DEFAULT_BLEND)]))
    cases = [("yellow_sphere_F8", False, "no fluorescence: stock `path` vs `sb_fluorescent_path`"),
             ("fluorescent_sphere_D50_red", True, "`path` on the elastic part only vs `sb_fluorescent_path` re-radiating")]
    rows, results = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, elastic_only, what in cases:
            sc = plan.for_run(scenes[name], {"spp": args.spp, "scale": args.scale})
            stock, ours = export_pair(sc, Path(tmp) / name, elastic_only)
            samples = {"path": [], "ours": []}
            for r in range(args.rounds):
                order = (("path", stock), ("ours", ours)) if r % 2 == 0 else (("ours", ours), ("path", stock))
                for key, folder in order:
                    samples[key].append(time_once(folder, args.spp, args.repeat))
                print(f"{name} round {r + 1}/{args.rounds}: path {samples['path'][-1]['warm']:.3f} s, "
                      f"sb_fluorescent_path {samples['ours'][-1]['warm']:.3f} s", flush=True)
            med = {k: {m: statistics.median(s[m] for s in v) for m in ("cold", "warm")} for k, v in samples.items()}
            # each round's pair ran under the same load: the median of the paired ratios
            ratios = [o["warm"] / p["warm"] for o, p in zip(samples["ours"], samples["path"])]
            ratio = statistics.median(ratios)
            results[name] = ratio
            rows.append(f"| {name} | {what} | {sc['render']['width']}x{sc['render']['height']} | {args.spp} "
                        f"| {med['path']['warm']:.3f} ({med['path']['cold']:.3f}) "
                        f"| {med['ours']['warm']:.3f} ({med['ours']['cold']:.3f}) | {ratio:.2f}x "
                        f"({min(ratios):.2f}-{max(ratios):.2f}) |")
    verdict = results["yellow_sphere_F8"] <= TARGET
    text = "\n".join([
        f"## Fluorescent integrator against Mitsuba's path integrator, {dt.date.today().isoformat()}",
        "",
        f"Recorded by `benchmarks/bench_fluorescence.py`. Machine: {machine()}; "
        f"Python {platform.python_version()}; {VARIANT}; "
        f"{args.rounds} interleaved rounds, each a fresh process with one cold and {args.repeat} warm renders; "
        "times: medians of the rounds' warm medians (cold: first render call, tracing and JIT included); ratio: "
        "median (range) over rounds of the round's warm ratio, both renders of a round having run back to back.",
        "",
        "| scene | what | resolution | spp | `path` s (cold) | `sb_fluorescent_path` s (cold) | ratio, warm (range) |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"Target: `sb_fluorescent_path` within {TARGET}x of `path` on the non-fluorescent scene: "
        f"{'met' if verdict else 'MISSED'} ({results['yellow_sphere_F8']:.2f}x).",
        "",
    ])
    print(text)
    if args.write:
        from record import record_result
        record_result(text)


if __name__ == "__main__":
    main()
