"""Dask worker preload: makes this project importable as ``spectral_bench`` in the worker, so it can
unpickle and run jobs (batch/jobs/job.py). LocalCluster workers load it automatically; workers of
your own cluster are started with it:

    dask worker tcp://SCHEDULER:8786 --nthreads 1 --preload /path/to/repo/batch/jobs/dask_preload.py

(the same checkout and Python environment as the client's: docs/running.md, "Running on a cluster")."""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()


def dask_teardown(worker):
    """The worker is closing (its cluster closed, Ctrl-C): the passes under way in it are ended with
    their whole process groups (a pass runs in its own session: batch/backends/passes.py)."""
    from spectral_bench.batch.backends import passes
    passes.stop_all()
