"""A warm Mitsuba 3 render process for one variant (started and kept by batch/backends/mitsuba/backend.py).

    python batch/backends/mitsuba/worker.py --variant llvm_ad_spectral

It imports Mitsuba once and says so with one JSON line ``{"ready": true, "versions": {...}}``,
then answers request lines read from stdin, one JSON line each: ``{"load": "scene.xml", "log":
"render.log"}`` loads a scene (registering the Python plugins its folder carries; what Mitsuba
prints from then on goes to that job's log), and ``{"spp": N, "seed": S, "out": "pass.exr"}``
renders one pass of the loaded scene (the variant's JIT kernels are compiled once and reused by
every later pass and scene of this process): the film's
raw channels (R, G, B or Y, then Stokes channels; no alpha or weight) as float32 EXR, answered by
``{"ok": true, "names": [...], "time_s": ..., "chunks": ...}`` (``time_s``: the render calls only).
Replies go to the original stdout; anything Mitsuba or a plugin prints goes to stderr (the
render log). The process ends when stdin closes. Converting the film's channels to the IR's
linear sRGB (monochrome variants, the camera polariser) is the backend's, for this route and the
mitsuba executable alike.
"""
import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

MAX_WAVEFRONT = 1 << 24


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
    ap.add_argument("--variant", required=True)
    args = ap.parse_args(argv)
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # whatever else prints goes to the log, never into the replies
    t0 = time.perf_counter()
    sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch import exr
    from spectral_bench.exporters import mitsuba_plugins
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant(args.variant)
    versions = {"mitsuba": mi.__version__, "drjit": dr.__version__, "numpy": np.__version__,
                "python": sys.version.split()[0]}
    reply.write(json.dumps({"ready": True, "versions": versions, "start_s": time.perf_counter() - t0}) + "\n")
    scene = None
    for line in sys.stdin:
        if not line.strip():
            continue
        req = json.loads(line)
        if "load" in req:  # a scene for the next passes; this job's log receives what is printed
            log = os.open(req.get("log") or os.devnull, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
            os.dup2(log, 1)
            os.dup2(log, 2)
            os.close(log)
            t = time.perf_counter()
            scene = None
            mitsuba_plugins.register_exported(Path(req["load"]).parent)  # the plugins the exported folder carries
            scene = mi.load_file(req["load"])
            reply.write(json.dumps({"ok": True, "load_s": time.perf_counter() - t}) + "\n")
            continue
        spp, seed = int(req["spp"]), int(req["seed"])
        width, height = scene.sensors()[0].film().size()
        # The LLVM variants trace all samples of a render call as one wavefront: keep each call
        # under MAX_WAVEFRONT samples (memory), averaging equal chunks of consecutive seeds.
        chunks = max(1, math.ceil(spp * width * height / MAX_WAVEFRONT))
        while spp % chunks:
            chunks += 1
        acc, render_s = None, 0.0
        for j in range(chunks):
            t = time.perf_counter()
            img = mi.render(scene, spp=spp // chunks, seed=seed + j)
            dr.eval(img)
            arr = np.array(img, dtype=np.float64)
            render_s += time.perf_counter() - t
            acc = arr if acc is None else acc + arr
        acc /= chunks
        names = channel_names(scene, acc.shape[-1])
        exr.write_channels(req["out"], {n: acc[..., i] for i, n in enumerate(names)}, exr.NO_COMPRESSION)
        reply.write(json.dumps({"ok": True, "names": names, "time_s": render_s, "chunks": chunks}) + "\n")


if __name__ == "__main__":
    main()
