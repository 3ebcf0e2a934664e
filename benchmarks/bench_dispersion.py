"""Render time of the dispersive dielectric plugin (sb_dispersive_dielectric) with a constant IOR
against Mitsuba's native dielectric / roughdielectric on the same non-dispersive scene (the
dispersion_fringes scene with its sphere's IOR set to 1.5), same llvm variant, same spp.

    .venv/bin/python benchmarks/bench_dispersion.py [--size 128] [--spp 64] [--repeat 5] [--write]

Native and plugin renders alternate (A, B, A, B, ...), each in a fresh child process that loads
the exported scene, renders once (JIT compilation included: "first") and then ``--calls`` more
times with the compiled kernels ("steady", the median of those calls), with distinct seeds; the
per-pixel variance across those renders gives the noise ratio. The table gives medians over the
repeats and the plugin / native ratios; --write records it in benchmarks/RESULTS.md.
Target: the plugin within 1.3x of the native dielectric (steady render time).
"""
import argparse
import copy
import datetime as dt
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import pkg_bootstrap  # noqa: E402
from record import machine  # noqa: E402

CHILD = r"""
import json, sys, time
import drjit as dr, mitsuba as mi
mi.set_variant(sys.argv[2])
sys.path.insert(0, sys.argv[1])
from pathlib import Path
loader = Path(sys.argv[1]) / "load_plugins.py"
if loader.is_file():
    import load_plugins
    load_plugins.register()
scene = mi.load_file(str(Path(sys.argv[1]) / "scene.xml"))
spp, calls = int(sys.argv[3]), int(sys.argv[4])
import numpy as np
times, images = [], []
for k in range(calls + 1):
    t = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=k)
    dr.eval(img)
    dr.sync_thread()
    times.append(time.perf_counter() - t)
    images.append(np.array(img, dtype=np.float64))
# per-pixel variance across the calls (independent seeds), averaged over the image and channels
variance = float(np.mean(np.var(np.stack(images), axis=0, ddof=1)))
print(json.dumps({"first": times[0], "steady": sorted(times[1:])[len(times[1:]) // 2], "variance": variance}))
"""


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.backends.mitsuba import llvm
    from spectral_bench.exporters import ir, mitsuba_writer

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--calls", type=int, default=3)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    if llvm.find()[0] is None:
        raise SystemExit(f"needs an llvm variant: {llvm.find()[1]}")
    scenes = dict(scene_sources.load([str(scene_sources.DEFAULT_BLEND)]))
    base = scenes["dispersion_fringes"]
    variant = "llvm_ad_spectral"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, rough in (("smooth", None), ("rough GGX 0.2", {"distribution": "ggx", "alpha": 0.2})):
            folders = {}
            for kind, ior in (("native", 1.5), ("plugin", {"type": "sellmeier", "B": [1.5 ** 2 - 1.0], "C": [0.0]})):
                sc = copy.deepcopy(base)
                sc["render"].update(width=args.size, height=args.size)
                sphere = next(o for o in sc["objects"] if (o.get("bsdf") or {}).get("type") == "dielectric")
                sphere["bsdf"] = {"type": "dielectric", "int_ior": ior, "ext_ior": 1.000277}
                if rough:
                    sphere["bsdf"]["roughness"] = rough
                sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
                folders[kind] = Path(tmp) / label.split()[0] / kind
                mitsuba_writer.write(sc, folders[kind])
            runs = {"native": [], "plugin": []}
            for _ in range(args.repeat):
                for kind in ("native", "plugin"):  # interleaved: A, B, A, B, ...
                    proc = subprocess.run([sys.executable, "-c", CHILD, str(folders[kind]), variant, str(args.spp),
                                           str(args.calls)], capture_output=True, text=True, env=llvm.env(), timeout=900)
                    if proc.returncode != 0:
                        raise SystemExit(proc.stderr[-2000:])
                    runs[kind].append(json.loads(proc.stdout.strip().splitlines()[-1]))
            med = {k: {m: statistics.median(r[m] for r in v) for m in ("first", "steady", "variance")}
                   for k, v in runs.items()}
            var_ratio = med["plugin"]["variance"] / med["native"]["variance"]
            rows.append(f"| {label} | {args.size}x{args.size} | {args.spp} | {med['native']['steady']:.3f} "
                        f"({med['native']['first']:.2f}) | {med['plugin']['steady']:.3f} ({med['plugin']['first']:.2f}) "
                        f"| {med['plugin']['steady'] / med['native']['steady']:.2f}x "
                        f"({med['plugin']['first'] / med['native']['first']:.2f}x) | {var_ratio:.2f} "
                        f"| {var_ratio * med['plugin']['steady'] / med['native']['steady']:.2f} |")
    text = "\n".join([
        f"## Dispersive dielectric plugin against Mitsuba's native dielectric, {dt.date.today().isoformat()}",
        "",
        f"Machine: {machine()}; "
        f"{variant}; dispersion_fringes with its sphere's IOR 1.5 (native: a number; plugin: a constant "
        f"Sellmeier model); medians of {args.repeat} interleaved runs, each a fresh process: steady = median "
        f"of {args.calls} render calls after the first (compiled kernels), first = the first call (JIT included).",
        "",
        "| sphere | resolution | spp | native s steady (first) | plugin s steady (first) | plugin / native steady (first) "
        "| variance plugin / native | time to equal error, plugin / native |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "Target: the plugin within 1.3x of the native dielectric (steady). At equal spp the smooth plugin "
        "keeps one wavelength per refraction (colour noise; a second refraction keeps the live one with "
        "probability 1/4, and dead paths end early): the variance ratio (per pixel, across "
        f"{args.calls + 1} seeds, image mean) and variance x time compare equal-error cost.",
        "",
    ])
    print(text)
    if args.write:
        from record import record_result
        record_result(text)


if __name__ == "__main__":
    main()
