"""Engines run jobs (batch/jobs/job.py) and hand each result to the caller as it finishes.

- LocalEngine (the default): this machine, no extra service. Renders run one at a time (each
  render uses every core: Mitsuba's LLVM variants and artist are multi-threaded) while the
  previous render is judged in a second thread (reading EXRs, the noise test, probes, previews;
  FLIP in a warm child process that computes while the probes run: batch/verdict/flip_isolated.py):
  a render never waits for a verdict. While the first job renders, the verdict thread loads what
  the verdicts need (job.warm: the verdict modules, colour-science, the FLIP child) and the warm
  render workers of every variant the run needs start in the background (job.prestart_workers),
  so a job's fixed cost is its own work (issue 23; benchmarks/bench_fixed_cost.py measures it per
  phase). Jobs come in the order the runner gives (batch/jobs/plan.py ``overlap_order``).
- DaskEngine (``--cluster ADDRESS`` or ``--cluster local:N``): the jobs go to a Dask distributed
  scheduler, each job (render and verdict) on one worker; ``local:N`` starts a LocalCluster of N
  single-threaded worker processes, listening on 127.0.0.1 only and over TLS with credentials made
  for the run (``Security.temporary()``: a connection without a certificate of its CA is refused, so
  other users of the machine cannot run code in the workers), without a dashboard unless
  ``--dashboard`` asks for one (its HTTP page is not behind TLS). A worker needs the same repository checkout and Python
  environment, and this project importable: workers load batch/jobs/dask_preload.py (docs/running.md,
  "Running on a cluster"). A Dask scheduler runs whatever its clients send (pickled functions):
  a scheduler that is not on this machine and not reached over tls:// is warned about. A
  scheduler that cannot be reached, or that no worker joins, within ``--cluster-timeout`` seconds
  is a ClusterError (a usage error, exit 2), never a wait without end. TLS settings (CA, client
  certificate and key) come from Dask's own configuration: ``distributed.comm.tls.*`` in a Dask
  config file or the DASK_DISTRIBUTED__COMM__TLS__... environment variables.

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


DEFAULT_TIMEOUT = 60.0
LOCAL_HOSTS = ("localhost", "127.0.0.1", "[::1]")


class ClusterError(RuntimeError):
    """A Dask cluster that cannot be used (unreachable, no workers, workers without this project)."""


class Interrupted(KeyboardInterrupt):
    """Raised by an engine after reporting the jobs under way as interrupted."""


def _test_stop_after(count):
    """Test hook (tests/jobs/test_engines.py): with SPECTRAL_BENCH_TEST_SIGINT_AFTER=N in the environment,
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
        """(result, what finishes its FLIP: job.judge_deferring)."""
        if error is not None:
            return jobs.failure(job, error), []
        try:
            return jobs.judge_deferring(job, record, self.deviations)
        except Exception as exc:  # noqa: BLE001 - a broken verdict fails the job, not the batch
            log.exception("verdict of %s failed", job["label"])
            return jobs.failure(job, f"verdict failed: {exc!r}", record), []

    @staticmethod
    def _finish(job, judged):
        """The verdict's result once its FLIP is in (a FLIP that fails is recorded in the result)."""
        result, pending = judged.result()
        for finish in pending:
            finish()
        return result

    @staticmethod
    def _warm(job_list):
        try:
            jobs.warm(job_list)
        except Exception:  # noqa: BLE001 - only a head start: each verdict loads what it needs itself
            log.debug("warming the verdicts failed", exc_info=True)

    def map(self, job_list, on_result):
        """Run every job; on_result(job, result) in this thread as each finishes."""
        done = queue.Queue()
        renders = cf.ThreadPoolExecutor(1, thread_name_prefix="render")
        verdicts = cf.ThreadPoolExecutor(1, thread_name_prefix="verdict")
        finishers = cf.ThreadPoolExecutor(1, thread_name_prefix="finish")  # FLIP k while verdict k+1 runs; in order
        started = {}
        verdicts.submit(self._warm, job_list)  # a head start while the first job renders
        try:
            jobs.prestart_workers(job_list)  # the other variants' warm workers start beside the first job
        except Exception:  # noqa: BLE001 - only a head start: each job starts what it needs itself
            log.debug("starting the render workers early failed", exc_info=True)

        def rendered(job, fut):
            if fut.cancelled():
                return
            try:
                record, error = fut.result()
            except Exception as exc:  # noqa: BLE001 - an export that raises is one failed job
                record, error = None, jobs.describe(exc)
            vf = verdicts.submit(self._judge, job, record, error)
            vf.add_done_callback(lambda f: finishers.submit(self._finish, job, f).add_done_callback(
                lambda ff: done.put((job, ff))))

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
                    result = jobs.failure(job, jobs.describe(exc))
                on_result(job, result)
                _test_stop_after(len(job_list) - len(remaining))
        except KeyboardInterrupt:
            from ..backends import passes
            passes.stop_all()  # a pass in its own session does not see the terminal's Ctrl-C
            renders.shutdown(wait=False, cancel_futures=True)
            verdicts.shutdown(wait=False, cancel_futures=True)
            finishers.shutdown(wait=False, cancel_futures=True)
            for j in job_list:
                if id(j) in remaining:
                    on_result(j, interrupted(j))
            raise Interrupted() from None
        renders.shutdown()
        verdicts.shutdown()
        finishers.shutdown()

    def close(self):
        pass


def plaintext_remote(address):
    """True for a scheduler address that is neither on this machine nor reached over TLS."""
    from urllib.parse import urlsplit
    scheme, _, rest = address.rpartition("://")
    if (scheme or "tcp") != "tcp":
        return scheme not in ("tls", "wss", "inproc")
    host = urlsplit("//" + rest).hostname or ""
    return host not in ("localhost", "127.0.0.1", "::1")


class DaskEngine:
    def __init__(self, address, timeout=None, dashboard=None):
        import dask
        from distributed import Client, LocalCluster
        timeout = float(timeout or DEFAULT_TIMEOUT)
        # a job whose worker dies is tried once more on another worker, then reported failed
        dask.config.set({"distributed.scheduler.allowed-failures": 1})
        self.cluster, self.client = None, None
        if address.startswith("local:"):
            try:
                n = int(address.split(":", 1)[1])
            except ValueError:
                n = 0
            if n < 1:
                raise ClusterError(f"--cluster {address}: a local cluster needs at least one worker (local:N, N >= 1)")
            # TLS with credentials made for this run only (a self-signed CA, in memory): the scheduler
            # and the workers accept no connection without a certificate of that CA, so another user
            # of this machine cannot send them code (a plain 127.0.0.1 port would run anyone's pickles)
            from distributed.security import Security
            security = Security.temporary()
            self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                                        protocol="tls://", security=security, dashboard_address=dashboard,
                                        preload=[PRELOAD])
            self.client = Client(self.cluster, timeout=timeout, security=security)
        else:
            if plaintext_remote(address):
                log.warning("warning: the Dask scheduler at %s runs whatever code it receives (pickles) and this "
                            "connection is not encrypted: on a shared network use tls:// with Dask's TLS settings "
                            "(docs/running.md, \"Running on a cluster\")", address)
            try:
                self.client = Client(address, timeout=timeout)
            except Exception as exc:  # noqa: BLE001 - unreachable, refused, TLS not configured: named, exit 2
                raise ClusterError(f"--cluster {address}: cannot reach the Dask scheduler within {timeout:g} s "
                                   f"(--cluster-timeout): {type(exc).__name__}: {exc}") from None
        try:
            self.client.wait_for_workers(1, timeout=timeout)
        except (OSError, TimeoutError):
            self.close()
            raise ClusterError(f"--cluster {address}: no Dask worker joined within {timeout:g} s "
                               "(--cluster-timeout); start workers with dask worker ... --preload "
                               f"{PRELOAD}") from None
        missing = [w for w, ok in self.client.run(_has_project).items() if not ok]
        if missing:
            self.close()
            raise ClusterError(f"Dask workers {', '.join(missing)} cannot import this project: start them with "
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
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def _has_project():
    import sys
    return "spectral_bench" in sys.modules


def make(cluster=None, deviations=None, timeout=None, dashboard=None):
    """The engine for ``--cluster`` (None: this machine); ``timeout``: seconds to reach the
    scheduler and its first worker; ``dashboard``: where a local cluster serves its dashboard
    (default: none)."""
    return DaskEngine(cluster, timeout, dashboard) if cluster else LocalEngine(deviations)
