"""Import this repository as the package ``spectral_bench`` from scripts, tests and batch/run.py.

The repository root is a Blender extension (root __init__.py, relative imports inside); inside
Blender it is imported as ``bl_ext.<repo>.spectral_bench``. Outside, this loads the same files
under one fixed name so that every module has a single identity.
"""
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
NAME = "spectral_bench"


def package():
    if NAME in sys.modules:
        return sys.modules[NAME]
    spec = importlib.util.spec_from_file_location(NAME, ROOT / "__init__.py",
                                                  submodule_search_locations=[str(ROOT)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[NAME] = module
    spec.loader.exec_module(module)
    return module
