"""Time export of all scenes and render of each scene, Mitsuba scalar vs LLVM variant, same spp.

    .venv/bin/python benchmarks/bench_export_render.py [--scale 0.5] [--repeat 3] [--write]
    .venv/bin/python benchmarks/bench_export_render.py --smoke   # seconds: checks the script runs; not recorded

Prints a Markdown table; --write also records it in benchmarks/RESULTS.md. Render time counts
the render calls only; wall time adds process start, scene loading and JIT compilation.
Run it on a quiet machine: the numbers are only as good as the machine's idleness.
"""
import argparse
import datetime as dt
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import machine  # noqa: E402
import pkg_bootstrap  # noqa: E402



def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, scene_sources
    from spectral_bench.batch.jobs import plan
    from spectral_bench.exporters import ir_json, mitsuba_writer

    ap = argparse.ArgumentParser()
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="checks that the script runs: every scene exported once, "
                    "two rendered at scale 0.05 (the first with a scalar twin, the first with a Python plugin); "
                    "never recorded")
    args = ap.parse_args()
    if args.smoke and args.write:
        ap.error("--smoke checks that the script runs; its figures are never recorded: leave out --write")
    if args.smoke:
        args.scale, args.repeat = 0.05, 1

    t = time.perf_counter()
    scenes = scene_sources.load([str(scene_sources.DEFAULT_BLEND)])
    t_extract_first = time.perf_counter() - t
    export_times = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.repeat):
            t = time.perf_counter()
            scenes = scene_sources.load([str(scene_sources.DEFAULT_BLEND)])
            for name, sc in scenes:
                mitsuba_writer.write(sc, Path(tmp) / f"{k}" / name / "mitsuba")
                ir_json.write(sc, Path(tmp) / f"{k}" / name / "json" / f"{name}.json")
            export_times.append(time.perf_counter() - t)

    from spectral_bench.batch.backends.mitsuba.backend import PLUGIN_NEEDS, scalar_twin
    backend = backends.get("mitsuba")
    rows, kinds = [], set()
    with tempfile.TemporaryDirectory() as tmp:
        for name, sc in scenes:
            sc = plan.for_run(sc, {"spp": None, "scale": args.scale})
            # a scene with a Python plugin would call Python per ray in a scalar variant (and the
            # fluorescent integrator needs a JIT one): its plugin's own benchmark times it instead
            plugin = bool(PLUGIN_NEEDS & set(sc.get("needs", [])))
            if args.smoke and plugin in kinds:
                continue  # --smoke: one scene of each kind
            kinds.add(plugin)
            xml = backend.export(sc, Path(tmp) / name)
            mode, _ = backend.mode_for(sc)
            scalar = None if plugin else scalar_twin(mode)
            fast = mode
            times = {}
            for variant in (v for v in (scalar, fast) if v):
                runs = [backend.render(xml, variant, sc["render"]["spp"], Path(tmp) / f"{name}_{variant}.exr")
                        for _ in range(args.repeat)]
                times[variant] = (statistics.median(r["time_s"] for r in runs),
                                  statistics.median(r["wall_s"] for r in runs))
            l = times[fast]
            if scalar is None:
                scalar_cell, speedup = "(Python plugin: bench_thin_film/dispersion/fluorescence.py)", "-"
            else:
                s = times[scalar]
                scalar_cell, speedup = f"{scalar} {s[0]:.2f} ({s[1]:.2f})", f"{s[0] / l[0]:.1f}x"
            rows.append(f"| {name} | {sc['render']['width']}x{sc['render']['height']} | {sc['render']['spp']} "
                        f"| {scalar_cell} | {fast} {l[0]:.2f} ({l[1]:.2f}) | {speedup} |")

    n = len(scenes)
    text = "\n".join([
        f"## Export and render times, {dt.date.today().isoformat()}",
        "",
        f"Machine: {machine()}; "
        f"Python {platform.python_version()}; medians of {args.repeat} runs.",
        "",
        f"Export of all {n} scenes from scenes.blend (extract + Mitsuba XML + JSON): "
        f"{statistics.median(export_times):.2f} s (first extraction incl. opening the .blend: {t_extract_first:.2f} s).",
        "",
        "| scene | resolution | spp | scalar render s (wall s) | LLVM render s (wall s) | speed-up (render) |",
        "|---|---|---|---|---|---|",
        *rows,
        "",
    ])
    print(text)
    if args.write:
        from record import record_result
        record_result(text)


if __name__ == "__main__":
    main()
