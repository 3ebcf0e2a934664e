"""Render a Mitsuba 3 scene folder in independent passes (run as a child process).

    python batch/backends/mitsuba_worker.py --xml scene.xml --variant llvm_ad_spectral --spp 64 \
        --passes 1 --seed 0 --out render.exr --result result.json

Writes the mean image (R, G, B) and, with two or more passes, the standard error of that mean
per pixel (stderr.R, stderr.G, stderr.B) from the pass-to-pass spread. ``time_s`` counts the
render calls only; ``wall_s`` includes loading the scene and JIT compilation.
"""
import argparse
import json
import math
import sys
import time
from pathlib import Path

MAX_WAVEFRONT = 1 << 24


def flat_spectrum_rgb():
    """Linear sRGB of the flat spectrum whose luminance is 1."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.exporters import colorimetry
    rgb = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz({"type": "constant", "value": 1.0}))
    return rgb / colorimetry.spectrum_xyz({"type": "constant", "value": 1.0})[1]


def channel_names(scene, count):
    """Channel names of the film's output (R, G, B or Y, then S0.R ... S3.B for Stokes)."""
    bitmap = scene.sensors()[0].film().bitmap()
    names = [bitmap.struct_()[i].name for i in range(bitmap.channel_count())]
    names = [n for n in names if n not in ("A", "W")]
    if len(names) != count:
        raise RuntimeError(f"film channels {names} do not match the image's {count} channels")
    return names


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--xml", required=True)
    ap.add_argument("--variant", required=True)
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--passes", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--result", required=True)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch import exr
    from spectral_bench.exporters import camera_filter, mitsuba_plugins
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant(args.variant)
    mitsuba_plugins.register_exported(Path(args.xml).parent)  # the plugins the exported folder carries
    scene = mi.load_file(args.xml)
    per_pass = math.ceil(args.spp / args.passes)
    # The LLVM variants trace all samples of a render call as one wavefront: keep each call
    # under MAX_WAVEFRONT samples (memory), averaging equal chunks of distinct seeds.
    width, height = scene.sensors()[0].film().size()
    chunks = max(1, math.ceil(per_pass * width * height / MAX_WAVEFRONT))
    while per_pass % chunks:
        chunks += 1
    images, render_s, seed = [], 0.0, args.seed
    for _k in range(args.passes):
        acc = None
        for _j in range(chunks):
            t = time.perf_counter()
            img = mi.render(scene, spp=per_pass // chunks, seed=seed)
            dr.eval(img)
            arr = np.array(img, dtype=np.float64)
            render_s += time.perf_counter() - t
            seed += 1
            acc = arr if acc is None else acc + arr
        images.append(acc / chunks)
    names = channel_names(scene, images[0].shape[-1])
    stack = np.stack(images)
    if names[0] == "Y":
        # Monochrome variants are chosen only when every spectrum is constant, so the radiance at
        # every pixel is a flat spectrum times the luminance Y: its RGB is Y times the RGB of the
        # flat spectrum of Y = 1 (equal-energy white is not D65 white). Stokes channels alike.
        tint = flat_spectrum_rgb()
        stack = np.concatenate([stack[..., :1] * tint, stack[..., 1:]], axis=-1)
        names = ["R", "G", "B"] + names[1:]
        for i, n in enumerate(names):
            if "." in n:
                stack[..., i] *= tint["RGB".index(n[-1])]
    camera = camera_filter.read(Path(args.xml).parent)
    if camera:  # the IR's ideal polariser, on every pass (so the noise is the filtered image's)
        names, stack = camera_filter.apply(camera, names, stack)
    mean = stack.mean(axis=0)
    extra = {}
    if args.passes > 1:
        stderr = stack.std(axis=0, ddof=1) / math.sqrt(args.passes)
        extra = {f"stderr.{n}": stderr[..., i].astype(np.float32) for i, n in enumerate(names)}
    exr.write_image(args.out, names, mean, extra)
    result = {"variant": args.variant, "spp": per_pass * args.passes, "passes": args.passes,
              "seed": args.seed, "chunks_per_pass": chunks, "time_s": render_s, "wall_s": time.perf_counter() - t0,
              "resolution": [int(mean.shape[1]), int(mean.shape[0])], "channels": names,
              "versions": {"mitsuba": mi.__version__, "drjit": dr.__version__, "numpy": np.__version__,
                           "python": sys.version.split()[0]}}
    Path(args.result).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
