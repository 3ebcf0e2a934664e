""".ci/run is the README's two commands (issue 31): setup and the test command exactly, then the
main command, whose exit status fails CI (``set -e``): the cases' default-settings promise is the
main command's."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_commands():
    block = re.search(r"```sh\n(.*?)```", (ROOT / "README.md").read_text(), re.S).group(1)
    return [line.split("#")[0].strip() for line in block.splitlines() if line.strip()]


def test_ci_runs_the_test_command_then_the_main_command_and_fails_on_its_exit():
    main, tests = _readme_commands()
    assert main.endswith(".venv/bin/python batch/run.py") and tests.endswith("-m pytest -q tests"), (main, tests)
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    assert "set -euo pipefail" in lines
    assert tests in lines, "the README's test command, exactly"
    run_main = main.split("&&")[-1].strip()  # setup has run already
    assert run_main in lines and lines.index(run_main) > lines.index(tests), lines
    assert lines.index("set -euo pipefail") < lines.index(tests)
