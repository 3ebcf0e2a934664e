"""Does the same seed give a bit-identical render? (benchmarks/TESTS.md, issue 45 item 7)

    .venv/bin/python benchmarks/measure_determinism.py [--repeats 3] [--spp 16] [--size 32]

Renders one small canonical scene (golden/ir/ggx_copper_50, and the RGB backends' own plane of
tests/backends/test_rgb_backends.py's kind: the golden scene exported for them) REPEATS times with the same
seed and passes through each backend this machine has (Mitsuba scalar_spectral, llvm_ad_spectral,
ART, Cycles, LuxCore), and prints, per backend, whether the mean image and the per-pixel standard
error are bit-identical between the repeats (and the largest difference when not). A backend whose
same-seed renders are bit-identical makes a statistical test on its render a fixed outcome: the
test cannot false-alarm between runs of the suite (on the same machine and build).

    .venv/bin/python benchmarks/measure_determinism.py --mitsuba-threads

renders Mitsuba's Cornell box (mi.cornell_box) in-process with Dr.Jit's thread count 1, 2, 7 and 16,
twice each, through a one-pixel box filter (what the IR's exporters write) and through the box's
default Gaussian filter, in scalar_spectral and llvm_ad_spectral: is the render bit-identical
whatever the thread count (the machine's cores)?

    .venv/bin/python benchmarks/measure_determinism.py --luxcore-threads

renders ggx_copper_50 (32x32) exported for LuxCore three times with one seed and 8 samples per
pixel asked (batch.haltspp), with LuxCore's default threads and with native.threads.count = 1,
in a child process that imports only pyluxcore (as batch/backends/luxcore/worker.py does): the
samples it took and whether the images are bit-identical."""
import argparse
import copy
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()


def render_once(backend, variant, scene, folder, spp, passes, seed):
    from spectral_bench.batch import backends, exr
    from spectral_bench.exporters import ir
    sc = copy.deepcopy(scene)
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    b = backends.get(backend, force_variant=variant) if variant else backends.get(backend)
    path = b.export(sc, Path(folder) / backend)
    mode = b.mode_for(sc)[0]
    info = b.render(path, mode, spp, Path(folder) / "render.exr", passes=passes, seed=seed)
    _names, img, se = exr.read_image_and_stderr(Path(folder) / "render.exr")
    return mode, info, img, se


def mitsuba_threads(spp=16, seed=3):
    """Per variant and filter: the thread counts whose two renders are bit-identical to each other
    and to the one-thread render, and the largest difference from it."""
    import drjit as dr
    import mitsuba as mi
    rows = []
    for variant in ("scalar_spectral", "llvm_ad_spectral"):
        mi.set_variant(variant)
        for rfilter in ("box", "gaussian"):
            d = mi.cornell_box()
            d["sensor"]["film"]["rfilter"] = {"type": rfilter}
            scene = mi.load_dict(d)
            out, repeat_same = {}, {}
            for n in (1, 2, 7, 16):
                dr.set_thread_count(n)
                a, b = (np.array(mi.render(scene, spp=spp, seed=seed)) for _ in range(2))
                out[n], repeat_same[n] = a, bool(np.array_equal(a, b))
            rows.append({"variant": variant, "rfilter": rfilter, "repeat_bit_identical": repeat_same,
                         "same_as_one_thread": {n: bool(np.array_equal(out[1], img)) for n, img in out.items()},
                         "max_abs_diff_from_one_thread": max(float(np.abs(out[1] - img).max()) for img in out.values())})
            print(json.dumps(rows[-1]), flush=True)
    return rows


LUXCORE_CHILD = r"""
import json, sys, time
from pathlib import Path
import numpy as np
import pyluxcore
cfg = Path(sys.argv[1]); folder = cfg.parent
pyluxcore.Init()

def render(threads, spp=8, seed=1):
    pyluxcore.ClearFileNameResolverPaths(); pyluxcore.AddFileNameResolverPath(str(folder))
    base = pyluxcore.Properties(str(cfg))
    w, h = base.Get("film.width").GetInt(), base.Get("film.height").GetInt()
    scene = pyluxcore.Scene(); scene.Parse(pyluxcore.Properties(str(folder / base.Get("scene.file").GetString())))
    props = pyluxcore.Properties(base)
    props.Set(pyluxcore.Property("renderengine.seed", seed))
    props.Set(pyluxcore.Property("batch.haltspp", spp))
    if threads:
        props.Set(pyluxcore.Property("native.threads.count", threads))
    s = pyluxcore.RenderSession(pyluxcore.RenderConfig(props, scene))
    s.Start()
    while True:
        time.sleep(0.02); s.UpdateStats()
        if s.HasDone():
            break
    s.Stop()
    n = s.GetStats().Get("stats.renderengine.total.samplecount").GetFloat() / (w * h)
    buf = np.zeros(w * h * 3, dtype=np.float32); s.GetFilm().GetOutputFloat(pyluxcore.FilmOutputType.RGB, buf)
    return n, buf

for threads in (None, 1):
    r = [render(threads) for _ in range(3)]
    print(json.dumps({"luxcore_threads": threads or "default (all cores)", "spp_asked": 8,
                      "spp_taken": [round(x[0], 3) for x in r],
                      "bit_identical": all(np.array_equal(r[0][1], x[1]) for x in r[1:])}), flush=True)
"""


def luxcore_threads():
    import subprocess
    from spectral_bench.batch import backends
    from spectral_bench.exporters import ir, ir_json
    sc = ir_json.load(ROOT / "golden" / "ir" / "ggx_copper_50.json")
    sc["render"]["width"] = sc["render"]["height"] = 32
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    folder = Path(tempfile.mkdtemp(prefix="det_lux_"))
    try:
        cfg = backends.get("luxcore").export(sc, folder / "luxcore")
        proc = subprocess.run([sys.executable, "-c", LUXCORE_CHILD, str(cfg)], capture_output=True, text=True, timeout=600)
        rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
        for row in rows:
            print(json.dumps(row), flush=True)
        return rows
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--luxcore-threads", action="store_true", help="the LuxCore one-thread measurement instead (see above)")
    ap.add_argument("--mitsuba-threads", action="store_true", help="the thread-count measurement instead (see above)")
    ap.add_argument("--scene", default="ggx_copper_50")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--passes", type=int, default=2)
    ap.add_argument("--size", type=int, default=32)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="*", help="backend labels to measure (default: all)")
    ap.add_argument("--art-threads", type=int, nargs="*",
                    help="ART only, once per thread count given (artist -j N; the backend passes the machine's cores)")
    args = ap.parse_args()
    if args.mitsuba_threads:
        return mitsuba_threads()
    if args.luxcore_threads:
        return luxcore_threads()
    from spectral_bench.exporters import ir_json
    scene = ir_json.load(ROOT / "golden" / "ir" / f"{args.scene}.json")
    scene["render"]["width"] = scene["render"]["height"] = args.size
    scene["render"]["spp"] = args.spp
    cases = [("mitsuba scalar_spectral", "mitsuba", "scalar_spectral"),
             ("mitsuba llvm_ad_spectral", "mitsuba", "llvm_ad_spectral"),
             ("art", "art", None), ("cycles", "cycles", None), ("luxcore", "luxcore", None)]
    if args.art_threads:
        import os
        counts = args.art_threads
        cases = []
        for n in counts:
            cases.append((f"art -j {n}", "art", None))
        real_cpu_count = os.cpu_count
    rows, by_label = [], {}
    for label, backend, variant in cases:
        if args.art_threads:
            n = int(label.split()[-1])
            os.cpu_count = lambda n=n: n  # the ART backend runs artist -j os.cpu_count()
        if args.only and not args.art_threads and label.split()[-1] not in args.only and backend not in args.only:
            continue
        renders = []
        try:
            for _ in range(args.repeats):
                folder = Path(tempfile.mkdtemp(prefix="det_"))
                try:
                    renders.append(render_once(backend, variant, scene, folder, args.spp, args.passes, args.seed))
                finally:
                    shutil.rmtree(folder, ignore_errors=True)
        except Exception as exc:  # a backend this machine lacks (ART unbuilt, no bpy, ...)
            rows.append({"backend": label, "measured": False, "why": f"{type(exc).__name__}: {str(exc)[:200]}"})
            print(json.dumps(rows[-1]), flush=True)
            continue
        mode, info, img0, se0 = renders[0]
        by_label[label] = img0
        same_img = all(np.array_equal(img0, r[2]) for r in renders[1:])
        same_se = all((se0 is None and r[3] is None) or np.array_equal(se0, r[3]) for r in renders[1:])
        diff = max(float(np.max(np.abs(img0 - r[2]))) for r in renders[1:])
        rel = diff / max(float(np.mean(np.abs(img0))), 1e-30)
        spps = [r[1].get("spp") for r in renders]
        rows.append({"backend": label, "mode": mode, "measured": True, "repeats": args.repeats,
                     "bit_identical": bool(same_img and same_se), "max_abs_diff": diff, "max_diff_over_mean": rel,
                     "spp_taken": spps, "per_pass": [r[1].get("samples_per_pixel_per_pass") for r in renders]})
        print(json.dumps(rows[-1]), flush=True)
    if args.art_threads:
        os.cpu_count = real_cpu_count
        first = next(iter(by_label.values()), None)
        same = {label: bool(np.array_equal(first, img)) for label, img in by_label.items()}
        rows.append({"art_same_image_whatever_the_thread_count": same})
        print(json.dumps(rows[-1]), flush=True)
    return rows


if __name__ == "__main__":
    main()
