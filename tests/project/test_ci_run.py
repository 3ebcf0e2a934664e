""".ci/run is the README's two commands (issue 31): setup and the test command exactly, then the
main command, whose exit status fails CI (``set -e``): the cases' default-settings promise is the
main command's."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


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


def test_ci_sources_its_art_step_before_the_tests():
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    main, tests = _readme_commands()
    assert ". .ci/art" in lines and lines.index(". .ci/art") < lines.index(tests), lines


def _art_step(tmp_path, src, path=None):
    """.ci/art as .ci/run runs it (sourced under ``set -euo pipefail`` in the repository root), with
    the ART source ``src``, building into tmp_path/prefix and naming tmp_path/ci-env.json (there
    from an earlier CI run) to the tests; what the tests would get is printed after it."""
    import os
    import subprocess
    (tmp_path / "ci-env.json").write_text('{"artist": "/an/earlier/build/bin/artist"}\n')
    env = dict(os.environ, ART_SRC=str(src), ART_PREFIX=str(tmp_path / "prefix"), ART_CI_ENV=str(tmp_path / "ci-env.json"))
    if path is not None:
        env["PATH"] = path
    import shutil
    return subprocess.run([shutil.which("bash"), "-c", 'set -euo pipefail; . .ci/art; echo "tests get: $SPECTRAL_BENCH_ART_ENV"'],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)


def test_a_broken_art_source_goes_on_with_art_skipped_saying_why(tmp_path):
    """A truncated ART tarball (build_art.sh exit 2): CI goes on to the tests, saying the source is
    broken and the ART tests skip, and the env file of an earlier build is gone (no ART of another
    source tested in its place)."""
    import io
    import tarfile
    with tarfile.open(tmp_path / "whole.tar.gz", "w:gz") as t:
        data = bytes(range(256)) * 64
        info = tarfile.TarInfo("ART-src/CMakeLists.txt")
        info.size = len(data)
        t.addfile(info, io.BytesIO(data))
    whole = (tmp_path / "whole.tar.gz").read_bytes()
    (tmp_path / "ART-2.1.2-src.tar.gz").write_bytes(whole[: len(whole) // 2])
    proc = _art_step(tmp_path, tmp_path / "ART-2.1.2-src.tar.gz")
    assert proc.returncode == 0, proc.stderr
    assert f"tests get: {tmp_path / 'ci-env.json'}" in proc.stdout
    assert "not a readable tarball" in proc.stderr and "is broken" in proc.stderr and "will skip" in proc.stderr, proc.stderr
    assert not (tmp_path / "ci-env.json").exists()


def test_a_good_art_source_whose_build_breaks_fails_ci(tmp_path):
    """A source that is ART's (project(ART) beside Source/ and ART_Resources/) on a machine that
    cannot build it (no dpkg, no cmake: PATH holds only what the step needs up to there):
    build_art.sh exits 3 and so does the step, before the tests, saying CI fails."""
    import io
    import shutil
    import tarfile
    src = tmp_path / "ART-2.1.2-src.tar"
    with tarfile.open(src, "w") as t:
        for folder in ("ART-src", "ART-src/Source", "ART-src/ART_Resources"):
            info = tarfile.TarInfo(folder)
            info.type, info.mode = tarfile.DIRTYPE, 0o755
            t.addfile(info)
        info = tarfile.TarInfo("ART-src/CMakeLists.txt")
        info.size = len(b"project (ART)\n")
        t.addfile(info, io.BytesIO(b"project (ART)\n"))
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("bash", "dirname", "basename", "mkdir", "sha256sum", "cut", "cat", "rm", "tar", "head", "tr", "grep", "mv", "ls"):
        (bin_dir / tool).symlink_to(shutil.which(tool))
    proc = _art_step(tmp_path, src, path=str(bin_dir))
    assert proc.returncode == 3, (proc.stdout, proc.stderr)
    assert "tests get" not in proc.stdout and "'cmake' is missing" in proc.stderr and "CI fails" in proc.stderr, proc.stderr


# -- the pbrt-v4 step (issue 43, .ci/pbrt): the same rules as ART's ----------------------------------------------------
def test_ci_sources_its_pbrt_step_before_the_tests_and_names_no_pbrt_to_the_main_command():
    """.ci/pbrt is sourced before the tests (which get SPECTRAL_BENCH_PBRT_ENV); the env variable is
    unset before the main command, which then finds no pbrt where it looks by default and keeps
    the fresh machine's promise (pbrt skipped, with the reason)."""
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    main, tests = _readme_commands()
    assert ". .ci/pbrt" in lines and lines.index(". .ci/pbrt") < lines.index(tests), lines
    unset = [i for i, line in enumerate(lines) if line.startswith("unset ") and "SPECTRAL_BENCH_PBRT_ENV" in line.split()]
    run_main = main.split("&&")[-1].strip()
    assert unset and unset[0] > lines.index(tests) and unset[0] < lines.index(run_main), lines


def _pbrt_step(tmp_path, src, path=None):
    """.ci/pbrt as .ci/run runs it (sourced under ``set -euo pipefail`` in the repository root),
    with the pbrt source ``src``, building into tmp_path/prefix and naming tmp_path/ci-env.json
    (there from an earlier CI run) to the tests; what the tests would get is printed after it."""
    import os
    import shutil
    import subprocess
    (tmp_path / "ci-env.json").write_text('{"pbrt": "/an/earlier/build/bin/pbrt"}\n')
    env = dict(os.environ, PBRT_SRC=str(src), PBRT_PREFIX=str(tmp_path / "prefix"), PBRT_CI_ENV=str(tmp_path / "ci-env.json"))
    if path is not None:
        env["PATH"] = path
    return subprocess.run([shutil.which("bash"), "-c", 'set -euo pipefail; . .ci/pbrt; echo "tests get: $SPECTRAL_BENCH_PBRT_ENV"'],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)


def test_a_broken_pbrt_source_goes_on_with_pbrt_skipped_saying_why(tmp_path):
    """A truncated pbrt tarball (build_pbrt.sh exit 2): CI goes on to the tests, saying the source
    is broken and the pbrt tests skip, and the env file of an earlier build is gone."""
    import io
    import tarfile
    with tarfile.open(tmp_path / "whole.tar.gz", "w:gz") as t:
        data = bytes(range(256)) * 64
        info = tarfile.TarInfo("src/CMakeLists.txt")
        info.size = len(data)
        t.addfile(info, io.BytesIO(data))
    whole = (tmp_path / "whole.tar.gz").read_bytes()
    (tmp_path / "pbrt-v4-src-trimmed.tar.gz").write_bytes(whole[: len(whole) // 2])
    proc = _pbrt_step(tmp_path, tmp_path / "pbrt-v4-src-trimmed.tar.gz")
    assert proc.returncode == 0, proc.stderr
    assert f"tests get: {tmp_path / 'ci-env.json'}" in proc.stdout
    assert "not a readable tarball" in proc.stderr and "is broken" in proc.stderr and "will skip" in proc.stderr, proc.stderr
    assert not (tmp_path / "ci-env.json").exists()


def test_a_good_pbrt_source_whose_build_breaks_fails_ci(tmp_path):
    """A source with pbrt-v4's shape (project(PBRT-V4), src/pbrt/cmd/pbrt.cpp, src/pbrt/film.cpp)
    on a machine that cannot build it (no dpkg, no cmake: PATH holds only what the step needs up to
    there): build_pbrt.sh exits 3 and so does the step, before the tests, saying CI fails."""
    import io
    import shutil
    import tarfile
    src = tmp_path / "pbrt-v4-src.tar"
    with tarfile.open(src, "w") as t:
        for name, data in (("src/CMakeLists.txt", b"project (PBRT-V4 LANGUAGES CXX C)\n"),
                           ("src/src/pbrt/cmd/pbrt.cpp", b"int main() {}\n"), ("src/src/pbrt/film.cpp", b"//\n")):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            t.addfile(info, io.BytesIO(data))
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("bash", "dirname", "basename", "mkdir", "sha256sum", "cut", "cat", "rm", "tar", "head", "tr", "grep", "mv", "ls"):
        (bin_dir / tool).symlink_to(shutil.which(tool))
    proc = _pbrt_step(tmp_path, src, path=str(bin_dir))
    assert proc.returncode == 3, (proc.stdout, proc.stderr)
    assert "tests get" not in proc.stdout and "'cmake' is missing" in proc.stderr and "CI fails" in proc.stderr, proc.stderr

