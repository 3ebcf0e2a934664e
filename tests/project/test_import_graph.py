"""Imports flow one way (issue 31): scripts/import_graph.py reads every import of addon/, batch/ and
exporters/ with ast and fails on a circle between packages or an import up the declared layers."""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "import_graph.py"


def graph(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=60)


def test_the_project_has_no_circle_and_no_upward_import():
    proc = graph()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "batch.jobs -> batch.studies" in proc.stdout and "no circle, no upward import" in proc.stdout


def _tree(root, files):
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    for pkg in ("addon", "batch", "exporters", "batch/verdict", "batch/report", "batch/jobs", "batch/studies",
                "batch/backends"):
        (root / pkg).mkdir(parents=True, exist_ok=True)
        (root / pkg / "__init__.py").touch()


def test_a_planted_circle_and_upward_imports_fail_naming_file_and_line(tmp_path):
    """The old house: verdict/baseline.py and report/summary.py importing each other (one of the
    two imports inside a function), a study importing the runner's jobs, batch importing addon."""
    _tree(tmp_path, {
        "batch/verdict/baseline.py": "import math\n\n\ndef section():\n    from ..report.summary import cell\n",
        "batch/report/summary.py": "from ..verdict import baseline\n",
        "batch/studies/stability.py": "from spectral_bench.batch.jobs import job\n",
        "batch/jobs/job.py": "",
        "batch/blend_input.py": "def f():\n    from ..addon import properties\n",
        "addon/properties.py": "",
    })
    proc = graph("--root", tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    out = proc.stdout
    assert "upward import batch.verdict -> batch.report: batch/verdict/baseline.py:5" in out, out
    assert "upward import batch.studies -> batch.jobs: batch/studies/stability.py:1" in out, out
    assert "upward import batch:base -> addon: batch/blend_input.py:2" in out, out
    assert "package circle batch.report <-> batch.verdict" in out, out
    assert "5 problems" in out and "module circle batch.report.summary <-> batch.verdict.baseline" in out, out


def test_a_circle_within_one_layer_fails(tmp_path):
    _tree(tmp_path, {"batch/verdict/a.py": "from ..backends import b\n",
                     "batch/backends/b.py": "from ..verdict import a\n"})
    proc = graph("--root", tmp_path)
    assert proc.returncode == 1 and "package circle batch.backends <-> batch.verdict" in proc.stdout, proc.stdout
