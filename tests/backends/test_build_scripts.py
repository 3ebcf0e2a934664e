"""scripts/build_art.sh and scripts/build_pbrt.sh (their shared steps: scripts/build_common.sh): a
wrong source is a clear error (exit 2) before anything is installed, names are data, a tarball
unpacks as the user's files, missing packages are named. Each test runs over both scripts
(tests/build_scripts.py says what each builds); the second run over a finished build, which
differs, stays in tests/backends/test_art.py and test_pbrt.py."""
import os
import shutil
import subprocess

import pytest

from build_scripts import (BEFORE_CMAKE, PROGRAMS, not_source_tarball, run, shaped_tarball, tarball, tools_only,
                           truncated_tarball)

by_program = pytest.mark.parametrize("program", PROGRAMS, ids=lambda p: p.name)


@by_program
def test_build_refuses_a_missing_or_wrong_source_naming_it(program, tmp_path):
    """Missing; not the program's (a folder or tarball of another CMake project with the program's
    files; a tarball that names the program's project without its files); a truncated or noise
    tarball: exit 2 with a message naming the source; the given PREFIX gets no executable, no
    unpacked source, and no env file is written."""
    other = tmp_path / "other"
    for folder in program.folders:
        (other / folder).mkdir(parents=True)
    for name, data in program.files.items():
        (other / name).write_bytes(data)
    (other / "CMakeLists.txt").write_text("cmake_minimum_required(VERSION 3.0)\nproject (NOTTHIS)\n")
    tarball(tmp_path / "other.tar.gz", {"CMakeLists.txt": b"project (NOTTHIS)\n", **program.files}, top="other")
    tarball(tmp_path / "hollow.tar.gz", {"CMakeLists.txt": program.cmake, **dict(list(program.files.items())[1:])}, top="src")
    truncated_tarball(tmp_path / "corrupt.tar.gz")
    (tmp_path / "noise.tar.gz").write_bytes(bytes(range(256)) * 8)
    cases = {tmp_path / "missing.tar.gz": "does not exist", other: f"is not {program.source_name}",
             tmp_path / "other.tar.gz": f"does not hold {program.source_name}",
             tmp_path / "hollow.tar.gz": f"does not hold {program.source_name}",
             tmp_path / "corrupt.tar.gz": "not a readable tarball", tmp_path / "noise.tar.gz": "not a readable tarball"}
    env = dict(os.environ, **{program.env_variable: str(tmp_path / "env.json")})
    for src, words in cases.items():
        proc = run(program, src, tmp_path / "prefix", env=env)
        assert proc.returncode == 2, (src, proc.stderr)
        assert words in proc.stderr and str(src.name) in proc.stderr, (src, proc.stderr)
        assert not (tmp_path / "prefix" / "bin").exists() and not (tmp_path / "env.json").exists()
        assert not (tmp_path / "prefix" / ".build" / "src").exists()
    assert run(program).returncode == 2 and "usage" in run(program).stderr


@by_program
def test_build_a_name_beginning_with_a_dash_is_data_and_a_failed_unpack_leaves_nothing(program, tmp_path):
    """SRC beginning with '-': a file of that name is a source like any (here not the program's:
    exit 2 naming it), a name that is no file is an option the script does not take (exit 2,
    usage), and so is such a PREFIX; a tarball tar cannot read leaves no half-unpacked
    PREFIX/.build/src.new."""
    not_source_tarball(tmp_path / "-other.tar.gz")
    prefix = tmp_path / "prefix"
    proc = run(program, "-other.tar.gz", prefix, cwd=tmp_path)
    assert proc.returncode == 2 and f"does not hold {program.source_name}" in proc.stderr and "-other.tar.gz" in proc.stderr, proc.stderr
    for args, named in ((["--help"], "--help"), (["-x", prefix], "-x"), ([tmp_path / "-other.tar.gz", "--prefix"], "--prefix")):
        proc = run(program, *args)
        assert proc.returncode == 2 and "usage" in proc.stderr and f"'{named}' is not an option" in proc.stderr, (args, proc.stderr)
    assert not (tmp_path / "--prefix").exists()
    whole = (tmp_path / "-other.tar.gz").read_bytes()
    (tmp_path / "cut.tar.gz").write_bytes(whole[: len(whole) // 2])
    proc = run(program, tmp_path / "cut.tar.gz", prefix)
    assert proc.returncode == 2 and "not a readable tarball" in proc.stderr, proc.stderr
    assert not (prefix / ".build" / "src.new").exists(), sorted(p.name for p in (prefix / ".build").iterdir())


@by_program
@pytest.mark.skipif(os.geteuid() != 0, reason="only root's tar keeps a tarball's owners and setuid bits")
def test_build_unpacks_a_tarball_as_its_own_files_not_the_tarballs_owners(program, tmp_path):
    """As root, a source tarball whose files belong to uid 12345 with setuid and setgid bits
    unpacks as root's files without them. The script then stops where a machine without dpkg and
    cmake stops it (exit 3, naming cmake), leaving the unpacked source to look at: PATH holds only
    the tools it needs up to there."""
    src = shaped_tarball(program, tmp_path / "source.tar", owner=12345, setuid=True)
    proc = subprocess.run([shutil.which("bash"), str(program.script), src, tmp_path / "prefix"], capture_output=True,
                          text=True, timeout=120, env={"PATH": tools_only(tmp_path, BEFORE_CMAKE)})
    assert proc.returncode == 3 and "'cmake' is missing" in proc.stderr, proc.stderr
    unpacked = tmp_path / "prefix" / ".build" / "src" / program.top
    for name in ("", *program.folders, "CMakeLists.txt", *program.files):
        st = (unpacked / name).lstat()
        assert (st.st_uid, st.st_gid) == (0, 0), (name, st.st_uid, st.st_gid)
        assert not st.st_mode & 0o7000, (name, oct(st.st_mode))


@by_program
def test_build_without_root_names_the_packages_and_stops(program, tmp_path):
    """Not root and a package missing: exit 3, naming the apt-get command to run, before any
    configure (a dpkg-query that knows no package stands in for a machine without them; id says
    uid 1000)."""
    src = shaped_tarball(program, tmp_path / "source.tar")
    path = tools_only(tmp_path, BEFORE_CMAKE)
    for name, body in (("dpkg-query", "exit 1"), ("id", "echo 1000")):
        (tmp_path / "bin" / name).write_text(f"#!{shutil.which('bash')}\n{body}\n")
        (tmp_path / "bin" / name).chmod(0o755)
    proc = subprocess.run([shutil.which("bash"), str(program.script), src, tmp_path / "prefix"], capture_output=True,
                          text=True, timeout=120, env={"PATH": path})
    assert proc.returncode == 3, proc.stderr
    assert f"apt-get install {program.packages}" in proc.stderr and "libopenexr-dev" in proc.stderr, proc.stderr
    assert not (tmp_path / "prefix" / ".build" / "cmake").exists()
