"""Import this repository as the package ``spectral_bench`` from scripts, tests and batch/run.py.

The repository root is a Blender extension (root __init__.py, relative imports inside); inside
Blender it is imported as ``bl_ext.<repo>.spectral_bench``. Outside, this loads the same files
under one fixed name so that every module has a single identity.
"""
import importlib.util
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
NAME = "spectral_bench"


def single_threaded_blas():
    """One BLAS thread in this process. Its matrix products are small (verdicts; renders run in
    child processes), and OpenBLAS 0.3.23, which numpy 1.26.4's wheels carry, can spin forever in
    a threaded gemv called from a worker thread (numpy/numpy#17752; seen here in the default
    engine's verdict thread after ~450 jobs). The variable reaches numpy when it loads after this
    and every child; where numpy is loaded already (bpy, Blender's start-up), threadpoolctl sets
    the loaded library."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if "numpy" in sys.modules:
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:  # Blender's own Python without the project's packages
            return
        threadpool_limits(1, user_api="blas")


single_threaded_blas()


def package():
    if NAME in sys.modules:
        return sys.modules[NAME]
    spec = importlib.util.spec_from_file_location(NAME, ROOT / "__init__.py",
                                                  submodule_search_locations=[str(ROOT)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[NAME] = module
    spec.loader.exec_module(module)
    return module
