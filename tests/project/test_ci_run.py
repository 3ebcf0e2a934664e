""".ci/run is the README's two commands (issue 31): setup and the test command exactly, then the
main command, whose exit status fails CI (``set -e``): the cases' default-settings promise is the
main command's."""
import re
from pathlib import Path

import pytest

import build_scripts

ROOT = Path(__file__).resolve().parents[2]
by_program = pytest.mark.parametrize("program", build_scripts.PROGRAMS, ids=lambda p: p.name)


def _readme_commands():
    block = re.search(r"```sh\n(.*?)```", (ROOT / "README.md").read_text(), re.S).group(1)
    return [line.split("#")[0].strip() for line in block.splitlines() if line.strip()]


def test_ci_runs_the_test_command_then_the_main_command_and_fails_on_its_exit():
    main, tests = _readme_commands()
    assert main.endswith(".venv/bin/python batch/run.py") and tests.endswith("-m pytest -q tests"), (main, tests)
    lines = _ci_lines()
    assert "set -euo pipefail" in lines
    assert tests in lines, "the README's test command, exactly"
    run_main = main.split("&&")[-1].strip()  # setup has run already
    assert run_main in lines and lines.index(run_main) > lines.index(tests), lines
    assert lines.index("set -euo pipefail") < lines.index(tests)


def _ci_lines():
    """.ci/run's lines, stripped, without blank lines and comments."""
    return [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()
            if line.strip() and not line.lstrip().startswith("#")]


# -- the ART (issue 32, .ci/art) and pbrt-v4 (issue 43, .ci/pbrt) steps: the same rules ------------------------------
@by_program
def test_ci_sources_its_step_before_the_tests_and_names_none_to_the_main_command(program):
    """.ci/<name> is sourced before the tests (which get its env variable); the env variable is
    unset before the main command, which then finds no ART or pbrt where it looks by default and
    keeps the fresh machine's promise (skipped, with the reason)."""
    lines = _ci_lines()
    main, tests = _readme_commands()
    assert f". {program.ci_step}" in lines and lines.index(f". {program.ci_step}") < lines.index(tests), lines
    unset = [i for i, line in enumerate(lines) if line.startswith("unset ") and program.env_variable in line.split()]
    run_main = main.split("&&")[-1].strip()
    assert unset and unset[0] > lines.index(tests) and unset[0] < lines.index(run_main), lines


@by_program
def test_a_broken_source_goes_on_with_its_tests_skipped_saying_why(program, tmp_path):
    """A truncated source tarball (build script exit 2): CI goes on to the tests, saying the source
    is broken and the program's render tests skip, and the env file of an earlier build is gone (no
    build of another source tested in its place)."""
    proc = build_scripts.ci_step(program, tmp_path, build_scripts.truncated_tarball(tmp_path / "truncated-src.tar.gz"))
    assert proc.returncode == 0, proc.stderr
    assert f"tests get: {tmp_path / 'ci-env.json'}" in proc.stdout
    assert "not a readable tarball" in proc.stderr and "is broken" in proc.stderr and "will skip" in proc.stderr, proc.stderr
    assert not (tmp_path / "ci-env.json").exists()


@by_program
def test_a_good_source_whose_build_breaks_fails_ci(program, tmp_path):
    """A source with the program's shape (tests/build_scripts.py) on a machine that cannot build it
    (no dpkg, no cmake: PATH holds only what the step needs up to there): the build script exits 3
    and so does the step, before the tests, saying CI fails."""
    src = build_scripts.shaped_tarball(program, tmp_path / "source.tar")
    proc = build_scripts.ci_step(program, tmp_path, src,
                                 path=build_scripts.tools_only(tmp_path, (*build_scripts.BEFORE_CMAKE, "bash", "ls")))
    assert proc.returncode == 3, (proc.stdout, proc.stderr)
    assert "tests get" not in proc.stdout and "'cmake' is missing" in proc.stderr and "CI fails" in proc.stderr, proc.stderr
