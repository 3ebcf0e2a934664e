"""Render time of the thin-film plugin (sb_thin_film_conductor, thickness 0) against Mitsuba's
native roughconductor on the same scene: iridescent_spheres_height with every sphere made the
same bare conductor (eta 1.9, k 1.5, Beckmann alpha 0.1), once through each BSDF.

    .venv/bin/python benchmarks/bench_thin_film.py [--scale 0.5] [--spp 64] [--repeat 7]
        [--variant llvm_ad_spectral --variant llvm_ad_spectral_polarized] [--write]

Both scenes are loaded in one process from their exported folders (the plugin registered by the
folder's own load_plugins.py, as the backend does), rendered once to compile their kernels
(reported as "first call"), then rendered alternately A, B, A, B, ... --repeat times each; the
table gives medians and the ratio plugin / native. Target: within 1.3x. --write records the table
in benchmarks/RESULTS.md. Run it on a quiet machine: the ratio is robust to load, the seconds are not.
"""
import argparse
import copy
import datetime as dt
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import machine  # noqa: E402
import pkg_bootstrap  # noqa: E402

SCENE = "iridescent_spheres_height"
TARGET = 1.3


def bare_spheres(scene, film):
    """The scene with every sphere the same bare conductor; with ``film`` through the plugin at
    thickness 0."""
    sc = copy.deepcopy(scene)
    for obj in sc["objects"]:
        if obj["shape"]["type"] == "sphere":
            b = {"type": "conductor", "eta": {"type": "constant", "value": 1.9}, "k": {"type": "constant", "value": 1.5},
                 "roughness": {"distribution": "beckmann", "alpha": 0.1}}
            if film:
                b["thin_film"] = {"ior": 1.33, "thickness": 0.0, "ext_ior": 1.0}
            obj["bsdf"] = b
    return sc


def timed_render(mi, dr, scene, spp, seed):
    t = time.perf_counter()
    img = mi.render(scene, spp=spp, seed=seed)
    dr.eval(img)
    dr.sync_thread()
    return time.perf_counter() - t


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.jobs import plan
    from spectral_bench.exporters import ir, mitsuba_plugins, mitsuba_writer
    import drjit as dr
    import mitsuba as mi

    ap = argparse.ArgumentParser()
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--variant", action="append")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    variants = args.variant or ["llvm_ad_spectral", "llvm_ad_spectral_polarized"]

    scene = dict(scene_sources.load([str(scene_sources.DEFAULT_BLEND)]))[SCENE]
    scene = plan.for_run(scene, {"spp": args.spp, "scale": args.scale})
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folders = {}
        for label, film in (("native roughconductor", False), ("plugin, thickness 0", True)):
            sc = bare_spheres(scene, film)
            sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
            folders[label] = mitsuba_writer.write(sc, Path(tmp) / label.split()[0]).parent
        for variant in variants:
            mi.set_variant(variant)
            loaded, first = {}, {}
            for label, folder in folders.items():
                mitsuba_plugins.register_exported(folder)
                loaded[label] = mi.load_file(str(folder / "scene.xml"))
                first[label] = timed_render(mi, dr, loaded[label], args.spp, 0)
            times = {label: [] for label in loaded}
            for k in range(args.repeat):
                for label, sc in loaded.items():  # interleaved: A, B, A, B, ...
                    times[label].append(timed_render(mi, dr, sc, args.spp, k + 1))
            med = {label: statistics.median(t) for label, t in times.items()}
            native, plugin = med["native roughconductor"], med["plugin, thickness 0"]
            ratio = plugin / native
            rows.append(f"| {variant} | {scene['render']['width']}x{scene['render']['height']} | {args.spp} "
                        f"| {native:.3f} ({first['native roughconductor']:.2f}) "
                        f"| {plugin:.3f} ({first['plugin, thickness 0']:.2f}) | {ratio:.2f}x "
                        f"| {'yes' if ratio <= TARGET else 'NO'} |")
            print(rows[-1], flush=True)
    text = "\n".join([
        f"## Thin-film plugin against roughconductor, {dt.date.today().isoformat()}",
        "",
        f"`benchmarks/bench_thin_film.py`: {SCENE} with four identical bare Beckmann spheres (eta 1.9, k 1.5, "
        f"alpha 0.1) through Mitsuba's roughconductor and through sb_thin_film_conductor at thickness 0. "
        f"Machine: {machine()}; medians of {args.repeat} "
        f"interleaved renders after one compiling render (its time in parentheses). Target: plugin within {TARGET}x.",
        "",
        "| variant | resolution | spp | native s (first call) | plugin s (first call) | plugin / native | within target |",
        "|---|---|---|---|---|---|---|",
        *rows,
        "",
    ])
    print(text)
    if args.write:
        from record import record_result
        record_result(text)


if __name__ == "__main__":
    main()
