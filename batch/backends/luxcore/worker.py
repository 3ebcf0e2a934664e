"""LuxCoreRender (pyluxcore) as a child process: render an exported render.cfg in independent
passes and save them (the backend writes their mean and standard error as EXR).

    python batch/backends/luxcore/worker.py --cfg render.cfg --spp 64 --passes 2 --seed 0 \
        --timeout 1800 --out passes.npy --result result.json
    python batch/backends/luxcore/worker.py serve    # warm: JSON requests on stdin (``serve``)

This process imports nothing but pyluxcore and numpy, pyluxcore first: pyluxcore 2.11.2 bundles
its own OpenEXR/TBB (tbbmalloc_proxy replaces malloc), and with the OpenEXR Python package loaded
first the process aborted at start ("free(): invalid pointer", measured).

Process model (shared/notes/luxcore-facts.md): no Python log callback is ever registered
(``pyluxcore.Init()`` keeps LuxCore's own logger; a Python handler left registered aborted the
interpreter at exit), and ``RenderSession.WaitForDone`` is never called (it did not return with a
halt condition): the session is polled with UpdateStats()/HasDone() and stopped at the deadline,
which makes this process exit with status 3 (the backend also kills it after its own limit).

Samples: PATHCPU with the RANDOM sampler (independent uniform samples in each pixel; seeded,
so passes with distinct seeds are independent). Its ``batch.haltspp`` is checked only when the
session is polled, so a render overshoots by what it renders between two polls: polled every
millisecond, 16 spp asked gave 16.7 samples per pixel on average, 64 gave 65.2 (measured at
32x32). LuxCore normalises each pixel by its own sample count, so every pixel stays an unbiased
mean; the samples actually taken (total sample count / pixels) are reported as the spp.
(TILEPATHCPU renders an exact a^2 samples per pixel, but its sampler ignores the seed: two passes
are identical, measured.)
"""
import argparse
import json
import math
import sys
import time
from pathlib import Path

POLL_S = 0.001
TIMEOUT_EXIT = 3


class TimedOut(RuntimeError):
    """The render ran past its time limit (the process exits with TIMEOUT_EXIT; ``serve`` says so)."""


def render(args):
    """Render ``args.cfg`` in ``args.passes`` passes; save them (``args.out``, .npy) and the result
    (``args.result``); returns the result. TimedOut past ``args.timeout`` seconds."""
    t0 = time.perf_counter()
    deadline = t0 + args.timeout
    import pyluxcore
    import numpy as np

    folder = Path(args.cfg).resolve().parent
    pyluxcore.ClearFileNameResolverPaths()
    pyluxcore.AddFileNameResolverPath(str(folder))
    base = pyluxcore.Properties(str(folder / Path(args.cfg).name))
    scene_props = pyluxcore.Properties(str(folder / base.Get("scene.file").GetString()))
    scene = pyluxcore.Scene()  # parsed anew for every render: a warm worker keeps nothing of a scene
    scene.Parse(scene_props)
    width, height = base.Get("film.width").GetInt(), base.Get("film.height").GetInt()
    per_pass = math.ceil(args.spp / max(1, args.passes))  # as mitsuba/worker.py
    images, taken, render_s = [], [], 0.0
    for k in range(args.passes):
        props = pyluxcore.Properties(base)
        props.Set(pyluxcore.Property("renderengine.seed", args.seed + k + 1))  # LuxCore's seeds start at 1
        props.Set(pyluxcore.Property("batch.haltspp", per_pass))
        config = pyluxcore.RenderConfig(props, scene)
        session = pyluxcore.RenderSession(config)
        t = time.perf_counter()
        session.Start()
        timed_out = False
        while True:
            time.sleep(POLL_S)
            session.UpdateStats()
            if session.HasDone():
                break
            if time.perf_counter() > deadline:
                timed_out = True
                break
        session.Stop()
        render_s += time.perf_counter() - t
        if timed_out:
            del session, config, scene
            raise TimedOut(f"luxcore_worker: timed out after {args.timeout} s")
        taken.append(session.GetStats().Get("stats.renderengine.total.samplecount").GetFloat() / (width * height))
        buf = np.zeros(width * height * 3, dtype=np.float32)
        session.GetFilm().GetOutputFloat(pyluxcore.FilmOutputType.RGB, buf)
        images.append(buf.reshape(height, width, 3)[::-1].astype(np.float64))  # LuxCore's rows run bottom to top
        del session, config
    del scene
    np.save(args.out, np.stack(images))
    result = {"variant": args.mode, "spp": int(round(sum(taken))), "spp_asked": per_pass * args.passes,
              "samples_per_pixel_per_pass": [round(t, 3) for t in taken], "passes": args.passes, "seed": args.seed,
              "time_s": render_s,
              "wall_s": time.perf_counter() - t0, "resolution": [width, height],
              "versions": {"pyluxcore": pyluxcore.Version(), "numpy": np.__version__,
                           "python": sys.version.split()[0]}}
    Path(args.result).write_text(json.dumps(result, indent=1))
    return result


def serve():
    """A warm worker (batch/backends/luxcore/backend.py keeps one across jobs; batch/backends/warm.py):
    pyluxcore is imported and initialised once, then every ``{"render": {"cfg", "mode", "spp",
    "passes", "seed", "timeout", "out", "result"}, "log": path}`` request runs what the command
    line runs (a new Scene parsed from the request's files: nothing is kept between requests),
    answered ``timed_out`` past its time limit; the loop, replies and logs:
    batch/backends/serve_requests.py (loaded by path: this process imports pyluxcore first)."""
    loop = _serve_requests()

    def start():
        import pyluxcore
        import numpy  # noqa: F401 - after pyluxcore (module docstring)
        pyluxcore.Init()  # LuxCore's own logger (stdout); no Python callback
        return {"pyluxcore": pyluxcore.Version()}

    def render_request(r):
        return render(argparse.Namespace(
            cfg=r["cfg"], mode=r.get("mode", "rgb"), spp=int(r["spp"]), passes=int(r.get("passes", 1)),
            seed=int(r.get("seed", 0)), timeout=float(r.get("timeout", 1800)), out=r["out"], result=r["result"]))
    loop.serve(start, {"render": render_request}, timed_out=(TimedOut,))


def _serve_requests():
    """batch/backends/serve_requests.py, by path (it imports nothing of the project)."""
    import importlib.util
    path = Path(__file__).resolve().parents[1] / "serve_requests.py"
    spec = importlib.util.spec_from_file_location("serve_requests", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["serve"]:
        return serve()
    ap = argparse.ArgumentParser()
    ap.add_argument("--cfg", required=True)
    ap.add_argument("--mode", default="rgb")
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--passes", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=1800)
    ap.add_argument("--out", required=True)
    ap.add_argument("--result", required=True)
    args = ap.parse_args(argv)
    import pyluxcore
    pyluxcore.Init()  # LuxCore's own logger (stdout); no Python callback
    try:
        render(args)
    except TimedOut as exc:
        print(exc, file=sys.stderr)
        sys.exit(TIMEOUT_EXIT)

if __name__ == "__main__":
    main()
