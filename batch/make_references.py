"""Render reference images (an explicit request: this is the only thing that changes references/).

    .venv/bin/python batch/make_references.py [-s SCENE ...] [--spp 4096 | --factor F] [--passes 8]

Each reference is rendered with the Mitsuba backend at the scene's resolution with ``spp``
samples per pixel (or ``factor`` x the scene's own), in ``passes`` independent passes (distinct
seeds); the
pass-to-pass spread gives the per-pixel standard error stored beside the mean.
"""
import argparse
import datetime as dt
import os
import platform
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402


def main(argv=None):
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, exr, scene_sources
    from spectral_bench.batch.verdict import references

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-i", "--input", nargs="+", default=[str(scene_sources.DEFAULT_BLEND)])
    ap.add_argument("-s", "--scene", action="append")
    ap.add_argument("--spp", type=int, default=4096, help="reference samples per pixel (default 4096)")
    ap.add_argument("--factor", type=int, help="reference spp = factor x the scene's spp (instead of --spp)")
    ap.add_argument("--passes", type=int, default=8)
    ap.add_argument("--seed", type=int, default=1000, help="first seed (distinct from the runner's default 0)")
    ap.add_argument("--out", default=str(references.REFERENCE_DIR))
    args = ap.parse_args(argv)
    backend = backends.get("mitsuba")
    print(backend.llvm_message())
    failed = 0
    for name, scene in scene_sources.load(args.input):
        if args.scene and name not in args.scene:
            continue
        if isinstance(scene, Exception):
            print(f"{name}: {scene}")
            failed += 1
            continue
        mode, why = backend.mode_for(scene)
        if mode is None:
            print(f"{name}: unsupported: {why}")
            continue
        spp = scene["render"]["spp"] * args.factor if args.factor else args.spp
        with tempfile.TemporaryDirectory() as tmp:
            xml = backend.export(scene, Path(tmp) / "mitsuba")
            image = Path(tmp) / "ref.exr"
            info = backend.render(xml, mode, spp, image, passes=args.passes, seed=args.seed, timeout=6 * 3600,
                                  log_path=Path(tmp) / "render.log")
            names, mean, stderr = exr.read_image_and_stderr(image)
            prov = {"backend": "mitsuba", "mode": mode, "spp": info["spp"], "passes": info["passes"],
                    "seed": args.seed, "resolution": info["resolution"], "time_s": round(info["time_s"], 2),
                    "wall_s": round(info["wall_s"], 2), "date": dt.datetime.now().isoformat(timespec="seconds"),
                    "versions": info["versions"],
                    "machine": f"{platform.machine()} {platform.system()}, {os.cpu_count()} cores",
                    "command": "batch/make_references.py " + " ".join(argv if argv is not None else sys.argv[1:])}
            path = references.save(scene, names, mean, stderr, prov, args.out)
        print(f"{name}: {info['spp']} spp in {info['time_s']:.1f} s -> {path} "
              f"(mean stderr / mean = {float(stderr.mean() / max(mean.mean(), 1e-12)):.2e})")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
