"""Render reference images (an explicit request: this is the only thing that changes references/).

    .venv/bin/python batch/make_references.py [-s SCENE ...] [--spp 4096 | --factor F] [--passes 8]
                                              [--cluster ADDRESS | local:N] [--replace]

References change only on request: a scene whose reference (its .exr or .json) is already in the
output folder is left alone and named, with what is wrong with it if anything (stale, broken), unless
``--replace`` asks to render it again. Two makers never write one scene's reference at once: each
holds the scene's lock (references/.work/<scene>.lock) from planning to writing; a scene locked by
another maker is skipped and named (exit status 1).

Each reference is rendered with the Mitsuba backend at the scene's resolution with ``spp`` samples
per pixel in all (or ``factor`` x the scene's own), in ``passes`` independent passes (distinct
seeds). Every pass is a job (batch/jobs/job.py) on the chosen engine (this machine, or a Dask
cluster: passes of one scene run on several workers at once); each finished pass is kept in
references/.work/, so a run that is stopped resumes where it was. When every pass of a scene is
there, their mean and the standard error of that mean (the pass-to-pass spread) are written as
the reference with its provenance, and the passes are removed. The reference is saved as one step
(batch/verdict/references.py ``save``: unique temporary files, synced, the record carrying the
image's sha256 and renamed first, so an interrupted save is seen as a broken reference, never as a
new image with an old record).
"""
import argparse
import contextlib
import datetime as dt
import json
import math
import os
import platform
import shutil
import sys
from pathlib import Path

import filelock

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

SEED_STRIDE = 1000  # pass k renders with seeds seed + k * SEED_STRIDE + chunk (chunks < 1000)


def pass_jobs(name, scene, mode, spp, passes, seed, work):
    """One job per pass; passes already in ``work`` (same scene, mode and samples) are skipped."""
    from spectral_bench.batch.jobs import job as jobs
    per_pass = math.ceil(spp / passes)
    todo = []
    for k in range(passes):
        j = jobs.make("reference", name, scene, "mitsuba", mode, per_pass, work, f"pass{k}", passes=1,
                      seed=seed + k * SEED_STRIDE, timeout=6 * 3600, label=f"{name} pass {k + 1}/{passes}",
                      extra={"pass": k})
        done = work / f"pass{k}" / "done.json"
        if not (done.is_file() and json.loads(done.read_text()).get("job") == jobs.job_id(j)):
            todo.append(j)
    return todo, per_pass


def merge(work, passes):
    """(names, mean, standard error of the mean, summed render seconds, versions) of the passes."""
    import numpy as np
    from spectral_bench.batch import exr
    images, seconds, versions = [], 0.0, None
    for k in range(passes):
        names, img = exr.read_image(work / f"pass{k}" / "render.exr")
        record = json.loads((work / f"pass{k}" / "done.json").read_text())
        seconds += record["time_s"]
        versions = record.get("versions")
        images.append(img.astype(np.float64))
    stack = np.stack(images)
    return names, stack.mean(axis=0), stack.std(axis=0, ddof=1) / math.sqrt(passes), seconds, versions


def main(argv=None):
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, scene_sources
    from spectral_bench.batch.verdict import references

    from spectral_bench.batch import cli
    from spectral_bench.batch.jobs import engines
    T = cli.TYPES  # the runner's checked option types: a bad value exits 2 naming the option
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-i", "--input", nargs="+", action="extend", type=T["input"],
                    help="scenes.blend or scene IR JSON files (repeatable; default: scenes.blend)")
    ap.add_argument("-s", "--scene", action="append", type=T["scene"])
    ap.add_argument("--spp", type=T["spp"], default=4096, help="reference samples per pixel in all (default 4096)")
    ap.add_argument("--factor", type=cli.int_in(1, 1 << 16), help="reference spp = factor x the scene's spp (instead of --spp)")
    ap.add_argument("--passes", type=cli.int_in(2, cli.MAX_PASSES), default=8,
                    help="independent passes (at least 2: their spread is the reference's noise; default 8)")
    ap.add_argument("--seed", type=T["seed"], default=1000, help="first seed (distinct from the runner's default 0)")
    ap.add_argument("--out", type=T["out"], default=str(references.REFERENCE_DIR))
    ap.add_argument("--cluster", metavar="ADDRESS", type=T["cluster"], help="a Dask scheduler, or local:N (default: this machine)")
    ap.add_argument("--replace", action="store_true",
                    help="render again scenes whose reference is already in the output folder (default: leave them)")
    args = ap.parse_args(argv)
    args.input = args.input or [str(scene_sources.DEFAULT_BLEND)]
    print(backends.get("mitsuba").llvm_message(), flush=True)
    out = Path(args.out)
    with contextlib.ExitStack() as held:  # the scenes' locks, released however this ends
        return _make(args, argv, out, held)


def existing_state(out, name, scene):
    """What the output folder holds for ``name``: current, stale or broken (naming the file)."""
    from spectral_bench.batch.verdict import references
    found = references.search(name, out, scene=scene)
    if found.ref is not None:
        return f"its reference {found.ref.path} exists and is current"
    return "its reference exists but is not usable: " + "; ".join(f"{p['file']}: {p['problem']}" for p in found.problems)


def _make(args, argv, out, held):
    from spectral_bench.batch import backends, scene_sources
    from spectral_bench.batch.jobs import engines, job as jobs
    from spectral_bench.batch.verdict import references
    backend = backends.get("mitsuba")
    plans, failed = [], 0
    for name, scene in scene_sources.load(args.input):
        if args.scene and name not in args.scene:
            continue
        if isinstance(scene, Exception):
            print(f"{name}: {scene}", flush=True)
            failed += 1
            continue
        mode, why = backend.mode_for(scene)
        if mode is None:
            print(f"{name}: unsupported: {why}", flush=True)
            continue
        lock = references.scene_lock(out, name)
        try:
            lock.acquire(timeout=0)
        except filelock.Timeout:
            print(f"{name}: another make_references is writing this reference (lock {lock.lock_file}); skipped",
                  flush=True)
            failed += 1
            continue
        held.callback(lock.release)
        # checked under the lock: a reference another maker has just written counts as existing
        if not args.replace and any(p.exists() for p in (out / f"{name}.exr", out / f"{name}.json")):
            print(f"{name}: {existing_state(out, name, scene)}; left as it is (--replace renders it again)",
                  flush=True)
            continue
        spp = scene["render"]["spp"] * args.factor if args.factor else args.spp
        work = out / ".work" / name
        todo, per_pass = pass_jobs(name, scene, mode, spp, args.passes, args.seed, work)
        plans.append((name, scene, mode, per_pass, work, todo))
        if len(todo) < args.passes:
            print(f"{name}: resuming, {args.passes - len(todo)} of {args.passes} passes already rendered", flush=True)
    remaining = {name: len(todo) for name, *_, todo in plans}

    def finished(job, record):
        work = Path(job["out"])
        if record.get("status") != "rendered":
            print(f"{job['scene_name']}: pass {job['extra']['pass']} failed: {record.get('reason')}", flush=True)
            return
        (work / job["folder"] / "done.json").write_text(json.dumps(dict(record, job=jobs.job_id(job)), default=str))
        remaining[job["scene_name"]] -= 1
        print(f"{job['label']}: {record['time_s']:.1f} s", flush=True)
        if remaining[job["scene_name"]] == 0:
            write_reference(next(p for p in plans if p[0] == job["scene_name"]))

    def write_reference(plan):
        name, scene, mode, per_pass, work, _todo = plan
        names, mean, stderr, seconds, versions = merge(work, args.passes)
        prov = {"backend": "mitsuba", "mode": mode, "spp": per_pass * args.passes, "passes": args.passes,
                "seed": args.seed, "resolution": [int(mean.shape[1]), int(mean.shape[0])],
                "time_s": round(seconds, 2), "date": dt.datetime.now().isoformat(timespec="seconds"),
                "versions": versions, "engine": args.cluster or "local",
                "machine": f"{platform.machine()} {platform.system()}, {os.cpu_count()} cores",
                "command": "batch/make_references.py " + " ".join(argv if argv is not None else sys.argv[1:])}
        path = references.save(scene, names, mean, stderr, prov, out)
        shutil.rmtree(work, ignore_errors=True)
        print(f"{name}: {prov['spp']} spp in {seconds:.1f} s -> {path} "
              f"(mean stderr / mean = {float(stderr.mean() / max(mean.mean(), 1e-12)):.2e})", flush=True)

    for plan in plans:
        if not plan[5]:
            write_reference(plan)  # every pass was already there
    try:
        engine = engines.make(args.cluster)
    except engines.ClusterError as exc:
        print(f"error: --cluster {args.cluster}: {exc}", file=sys.stderr, flush=True)
        return 2
    try:
        engine.map([j for p in plans for j in p[5]], finished)
    except engines.Interrupted:
        print("interrupted: the finished passes are kept in references/.work; run the same command to resume",
              flush=True)
        return 130
    finally:
        engine.close()
    return 1 if failed or any(remaining.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
