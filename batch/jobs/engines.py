"""Engines run jobs (batch/jobs/job.py) and hand each result to the caller as it finishes.

- LocalEngine (the default): this machine, no extra service. Renders run one at a time (each
  render uses every core: Mitsuba's LLVM variants and artist are multi-threaded) while the
  previous render is judged in a second thread (reading EXRs, the noise test, probes, previews,
  FLIP in its own process): a render never waits for a verdict.
- DaskEngine (``--cluster ADDRESS`` or ``--cluster local:N``): the jobs go to a Dask distributed
  scheduler, each job (render and verdict) on one worker; ``local:N`` starts a LocalCluster of N
  single-threaded worker processes. A worker needs the same repository checkout and Python
  environment, and this project importable: workers load batch/jobs/dask_preload.py (README,
  "Running on a cluster").

Failures: a render that crashes is retried once (on another worker where there is one), then
reported failed with the reason; so is a job whose worker dies. Ctrl-C stops the engine: jobs
under way are reported as interrupted, the rest never start, and ``--resume`` finishes them.
"""
import concurrent.futures as cf
import logging
import os
import queue
import signal
from pathlib import Path

from . import job as jobs

log = logging.getLogger("spectral_bench")
PRELOAD = str(Path(__file__).resolve().parent / "dask_preload.py")


class Interrupted(KeyboardInterrupt):
    """Raised by an engine after reporting the jobs under way as interrupted."""


def _test_stop_after(count):
    """Test hook (tests/test_engines.py): with SPECTRAL_BENCH_TEST_SIGINT_AFTER=N in the environment,
    the runner sends itself SIGINT, as Ctrl-C does, once N results are handed on: an interrupt at a
    defined point instead of a signal racing the renders. Unset (always, outside that test): nothing."""
    if str(count) == os.environ.get("SPECTRAL_BENCH_TEST_SIGINT_AFTER"):
        os.kill(os.getpid(), signal.SIGINT)


def interrupted(job):
    result = jobs.failure(job, "interrupted before it finished (Ctrl-C or a stopped runner): "
                               "batch/run.py --resume finishes it")
    result["interrupted"] = True
    return result


class LocalEngine:
    name = "local"

    def __init__(self, deviations=None):
        self.deviations = deviations

    def _render(self, job):
        error = None
        for _attempt in range(2):
            try:
                return jobs.execute(job), None
            except jobs.RenderCrashed as exc:
                error = exc
                log.info("render of %s crashed (%s); retrying once", job["label"], exc)
        return None, f"{error} (after one retry)"

    def _judge(self, job, record, error):
        if error is not None:
            return jobs.failure(job, error)
        try:
            return jobs.judge(job, record, self.deviations)
        except Exception as exc:  # noqa: BLE001 - a broken verdict fails the job, not the batch
            log.exception("verdict of %s failed", job["label"])
            return jobs.failure(job, f"verdict failed: {exc!r}", record)

    def map(self, job_list, on_result):
        """Run every job; on_result(job, result) in this thread as each finishes."""
        done = queue.Queue()
        renders = cf.ThreadPoolExecutor(1, thread_name_prefix="render")
        verdicts = cf.ThreadPoolExecutor(1, thread_name_prefix="verdict")
        started = {}

        def rendered(job, fut):
            if fut.cancelled():
                return
            try:
                record, error = fut.result()
            except Exception as exc:  # noqa: BLE001 - an export that raises is one failed job
                record, error = None, f"internal error: {exc!r}"
            vf = verdicts.submit(self._judge, job, record, error)
            vf.add_done_callback(lambda f: done.put((job, f)))

        for j in job_list:
            f = renders.submit(self._render, j)
            started[id(j)] = j
            f.add_done_callback(lambda fut, j=j: rendered(j, fut))
        remaining = {id(j) for j in job_list}
        try:
            while remaining:
                job, fut = done.get()
                remaining.discard(id(job))
                try:
                    result = fut.result()
                except Exception as exc:  # noqa: BLE001
                    result = jobs.failure(job, f"internal error: {exc!r}")
                on_result(job, result)
                _test_stop_after(len(job_list) - len(remaining))
        except KeyboardInterrupt:
            renders.shutdown(wait=False, cancel_futures=True)
            verdicts.shutdown(wait=False, cancel_futures=True)
            for j in job_list:
                if id(j) in remaining:
                    on_result(j, interrupted(j))
            raise Interrupted() from None
        renders.shutdown()
        verdicts.shutdown()

    def close(self):
        pass


class DaskEngine:
    def __init__(self, address):
        import dask
        from distributed import Client, LocalCluster
        # a job whose worker dies is tried once more on another worker, then reported failed
        dask.config.set({"distributed.scheduler.allowed-failures": 1})
        self.cluster = None
        if address.startswith("local:"):
            n = int(address.split(":", 1)[1])
            self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                        preload=[PRELOAD])
            self.client = Client(self.cluster)
        else:
            self.client = Client(address)
        missing = [w for w, ok in self.client.run(_has_project).items() if not ok]
        if missing:
            self.close()
            raise RuntimeError(f"Dask workers {', '.join(missing)} cannot import this project: start them with "
                               f"--preload {PRELOAD} (same checkout and environment as here)")
        self.name = f"dask {address}"

    def map(self, job_list, on_result):
        from distributed import as_completed
        futures = {}
        for j in job_list:
            f = self.client.submit(jobs.run, j, retries=1, pure=False,
                                   key=f"{j['kind']}-{j['scene_name']}-{jobs.job_id(j)}")
            futures[f] = j
        remaining = set(futures)
        try:
            for fut in as_completed(list(futures)):
                job = futures[fut]
                remaining.discard(fut)
                try:
                    result = fut.result()
                except Exception as exc:  # noqa: BLE001 - crashed twice, or its worker died twice
                    result = jobs.failure(job, f"failed on the cluster after one retry: {exc!r}")
                on_result(job, result)
        except KeyboardInterrupt:
            for fut in remaining:
                fut.cancel()
                on_result(futures[fut], interrupted(futures[fut]))
            raise Interrupted() from None

    def close(self):
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def _has_project():
    import sys
    return "spectral_bench" in sys.modules


def make(cluster=None, deviations=None):
    """The engine for ``--cluster`` (None: this machine)."""
    return DaskEngine(cluster) if cluster else LocalEngine(deviations)
