"""Jobs as data on engines: a Dask LocalCluster gives the same images and verdicts as the default
engine; an interrupted run resumes rendering only what is missing; a killed worker loses nothing."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import ROOT, metrics, run_batch
from spectral_bench.batch import exr

SMALL = ["-s", "ggx_copper_50_isolated", "-s", "macbeth_chart_D65", "-r", "mitsuba", "--scale", 0.25, "--spp", 16,
         "--no-flip"]


def _runs(out):
    return {(r["scene"], r["backend"]): r for r in metrics(out)["runs"]}


@pytest.mark.slow
def test_local_cluster_gives_the_default_engines_images_and_verdicts(tmp_path):
    local, dask = tmp_path / "local", tmp_path / "dask"
    p1 = run_batch(*SMALL, "-o", local)
    p2 = run_batch(*SMALL, "--cluster", "local:2", "-o", dask)
    assert p1.returncode == p2.returncode, (p1.stderr[-2000:], p2.stderr[-2000:])
    a, b = _runs(local), _runs(dask)
    assert sorted(a) == sorted(b) and len(a) == 2
    for key in a:
        assert a[key]["job"] == b[key]["job"]  # the same job
        img_a = exr.read_image_and_stderr(local / a[key]["image"])
        img_b = exr.read_image_and_stderr(dask / b[key]["image"])
        assert all(np.array_equal(x, y) for x, y in zip(img_a[1:], img_b[1:])), key  # bit for bit
        assert a[key]["status"] == b[key]["status"]
        assert [(p["name"], p["pass"], p.get("z")) for p in a[key]["probes"]] == \
               [(p["name"], p["pass"], p.get("z")) for p in b[key]["probes"]]


@pytest.mark.slow
def test_an_interrupted_run_resumes_with_only_the_missing_jobs(tmp_path):
    """Stop the runner (SIGINT, as Ctrl-C) after its first finished job: metrics.json stays
    consistent and says which jobs were interrupted; --resume keeps what finished (its files are
    not touched) and renders only the rest. The runner sends itself the SIGINT once one result is
    handed on (the test hook SPECTRAL_BENCH_TEST_SIGINT_AFTER, batch/jobs/engines.py), so where the
    interrupt lands does not depend on how fast the machine is."""
    out = tmp_path / "out"
    scenes = ["ggx_copper_50_isolated", "ggx_copper_60_isolated", "ggx_copper_70_isolated", "ggx_copper_80_isolated"]
    args = [a for s in scenes for a in ("-s", s)] + ["-r", "mitsuba", "--scale", 0.125, "--spp", 1024, "--no-flip"]
    # the runner as a terminal starts it: Ctrl-C delivered. A background job of a non-interactive
    # shell (how CI may start the suite) inherits SIGINT ignored, and Python then never raises
    # KeyboardInterrupt; exec keeps an ignored signal ignored, so the child restores the default.
    proc = subprocess.run([sys.executable, str(ROOT / "batch" / "run.py"), *map(str, args), "-o", str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600,
                          env=dict(os.environ, SPECTRAL_BENCH_TEST_SIGINT_AFTER="1"),
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    err = proc.stderr
    assert proc.returncode == 130, err[-2000:]
    first = metrics(out)["runs"]
    finished = [r for r in first if not r.get("interrupted")]
    assert len(finished) == 1 and len(first) == len(scenes), [r["status"] for r in first]
    assert all(r["interrupted"] and r["status"] == "failed" for r in first if r not in finished)
    stamps = {r["scene"]: (out / r["image"]).stat().st_mtime_ns for r in finished}
    resumed = run_batch("--resume", out)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert f"{len(finished)} jobs kept, {len(scenes) - len(finished)} to run" in resumed.stderr
    runs = metrics(out)["runs"]
    assert sorted(r["scene"] for r in runs) == sorted(scenes)
    assert all(r["status"] in ("ok", "known") for r in runs), [(r["status"], r["reason"]) for r in runs]
    for r in runs:
        if r["scene"] in stamps:
            assert (out / r["image"]).stat().st_mtime_ns == stamps[r["scene"]]  # not rendered again


@pytest.mark.slow
def test_a_killed_worker_loses_no_job(golden, tmp_path):
    """SIGKILL a worker in the middle of its render: Dask gives the job to another worker (one
    retry) and every job still finishes."""
    import copy
    from spectral_bench.batch.jobs import engines, job as jobs, plan
    engine = engines.make("local:2")
    try:
        pids = engine.client.run(os.getpid)
        job_list = []
        for k, name in enumerate(["ggx_glass", "beckmann_glass", "ggx_copper_80_isolated"]):
            sc = copy.deepcopy(golden[name])
            sc["render"].update(width=128, height=128)
            job_list.append(jobs.make("render", name, sc, "mitsuba", "llvm_ad_spectral", 256, tmp_path,
                                      f"{name}/results/mitsuba", passes=2, source_scene=golden[name],
                                      verdict=plan.verdict_settings({"alpha": 0.01, "min_samples": 65536, "flip": False,
                                                                     "block": None, "references": None, "known": None})))
        results, killed = [], []
        victim = sorted(pids.values())[0]

        def kill_in_a_render():
            # the event, not a delay: the victim has a render child (batch/backends/mitsuba/worker.py)
            import psutil
            worker = psutil.Process(victim)
            while not results or len(results) < 3:
                try:
                    if any("mitsuba/worker.py" in " ".join(c.cmdline()) for c in worker.children()):
                        os.kill(victim, signal.SIGKILL)
                        killed.append(victim)
                        return
                except psutil.Error:
                    pass
                time.sleep(0.02)
        import threading
        threading.Thread(target=kill_in_a_render, daemon=True).start()
        engine.map(job_list, lambda j, r: results.append((j, r)))
    finally:
        engine.close()
    assert killed, "the victim worker never rendered"
    assert len(results) == 3
    assert all(r["status"] in ("ok", "known", "unjudged") for _, r in results), [(r["scene"], r["reason"]) for _, r in results]


@pytest.mark.parametrize("numpy_first", [False, True])
def test_the_runner_process_uses_one_blas_thread(numpy_first):
    """The default engine judges in a worker thread; OpenBLAS 0.3.23 (numpy 1.26.4) can spin
    forever in a threaded gemv there (pkg_bootstrap.single_threaded_blas). Whether numpy loads
    after the project (python batch/run.py) or before it (bpy, Blender, a Dask worker), the
    process ends with one BLAS thread, and its children inherit the limit."""
    code = ("import numpy\n" if numpy_first else "") + (
        "import os, sys; sys.path.insert(0, sys.argv[1]); import pkg_bootstrap, numpy, threadpoolctl\n"
        "print(sorted({i['num_threads'] for i in threadpoolctl.threadpool_info() if i['user_api'] == 'blas'}),"
        " os.environ.get('OPENBLAS_NUM_THREADS'))")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    proc = subprocess.run([sys.executable, "-c", code, str(ROOT)], capture_output=True, text=True, env=env, timeout=120)
    assert proc.stdout.split() == ["[1]", "1"], proc.stdout + proc.stderr

