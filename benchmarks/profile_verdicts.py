"""The verdicts phase of a kept default run, judged again job by job under cProfile (issue 45 item 1).

    .venv/bin/python benchmarks/profile_verdicts.py RUN_FOLDER [--top 25] [-s SCENE ...] [--out DIR]
    .venv/bin/python benchmarks/profile_verdicts.py --smoke   # one tiny run, judged again, compared

RUN_FOLDER is a run kept by ``bench_fixed_cost.py --default --keep DIR``. Its renders (and
exports) are copied into a new folder (``--out``, default a temporary one) and each render job
of the default plan (``batch/run.py -r mitsuba``, in the suite's order, so that what one verdict
leaves for the next, e.g. the Fresnel probe's geometry, is left as in the run) is judged again
through the runner's own ``_judge_render``, FLIP as the run's default (``auto``: where the verdict
is not ``ok``) computed in this process. Prints each job's CPU seconds (process time) and, with
``--top``, the functions with most cumulative and own time over all jobs; writes the entries
judged again as the folder's metrics.json (``compare_records.py`` compares two such folders, or
one with the run: the same verdicts), ``--save FILE`` the profile for pstats.
"""
import argparse
import cProfile
import io
import json
import pstats
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
from spectral_bench.batch import cli  # noqa: E402
from spectral_bench.batch.jobs import job as job_mod, plan as planning, runner  # noqa: E402
from spectral_bench.batch.report import results as report_results  # noqa: E402


def smoke():
    """One tiny run of the runner (as a user runs it), judged again and compared with itself."""
    import subprocess
    import compare_records
    root = Path(__file__).resolve().parents[1]
    tiny = ["-r", "mitsuba", "--scale", "0.25", "--spp", "4", "-s", "ggx_copper_50"]
    with tempfile.TemporaryDirectory() as tmp:
        run, again = Path(tmp) / "run", Path(tmp) / "again"
        subprocess.run([sys.executable, str(root / "batch" / "run.py"), *tiny, "-o", str(run)], cwd=root, check=True,
                       stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
        main([str(run), "--out", str(again), "--top", "5", "--run-args", " ".join(tiny)])
        return compare_records.main([__file__, str(run), str(again)])


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv == ["--smoke"]:
        return smoke()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--run-args", default="-r mitsuba",
                    help="the batch/run.py options the run was made with (default: the default suite's)")
    ap.add_argument("--top", type=int, default=0)
    ap.add_argument("-s", "--scene", action="append", default=[])
    ap.add_argument("--out", type=Path)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--save", type=Path, help="the cProfile statistics, for pstats")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="rejudge-"))
    metrics = json.loads((args.run / "metrics.json").read_text())
    entries = {r["job"]: r for r in metrics["runs"] if isinstance(r, dict) and r.get("job")}
    opts = cli.parse([*args.run_args.split(), "--out", str(out)])
    _, scenes = runner.plan(opts)
    made = {"mitsuba": runner.make_backend("mitsuba", opts)}
    jobs, _ = planning.main_jobs(scenes, made, opts, out, planning.verdict_settings(opts))
    deviations = runner.load_known(opts.get("known"))
    from spectral_bench.batch.jobs import job as _j  # noqa: F401
    job_mod.warm(jobs)  # the verdict modules and colour-science, as the runner's verdict thread does first
    prof = cProfile.Profile(time.process_time)  # CPU seconds: the figure the benchmark's judging share counts
    results, total = [], 0.0
    for job in jobs:
        if args.scene and job["scene_name"] not in args.scene:
            continue
        e = entries[job["id"]]
        src, dst = args.run / job["folder"], out / job["folder"]
        dst.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src / "render.exr", dst / "render.exr")
        record = {"job": job["id"], "kind": "render", "scene": job["scene_name"], "backend": "mitsuba",
                  "mode": job["mode"], "status": "rendered", "reason": "", "image": e["image"],
                  "image_path": str(out / e["image"])}
        record.update({k: e[k] for k in ("time_s", "wall_s", "spp", "passes", "pass_times", "versions", "spectral")
                       if k in e})
        c0 = time.process_time()
        prof.enable()
        result = job_mod._judge_render(job, record, deviations)
        prof.disable()
        cpu = time.process_time() - c0
        total += cpu
        results.append(report_results.label_judged_by(result))  # as the runner stores it
        print(f"{job['scene_name']:32s} {result['status']:8s} {cpu:7.2f} s", flush=True)
    print(f"{'total':32s} {'':8s} {total:7.2f} s")
    if args.top:
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats("cumulative").print_stats(args.top)
        print(s.getvalue())
        s = io.StringIO()
        pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(args.top)
        print(s.getvalue())
    if args.save:
        prof.dump_stats(str(args.save))
    if args.json:
        args.json.write_text(json.dumps(results, default=str))
    from spectral_bench.batch import records
    records.write(out, metrics.get("started", ""), opts, results)  # compare_records.py reads it
    print(f"judged again into {out} (metrics.json: benchmarks/compare_records.py {args.run} {out})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
