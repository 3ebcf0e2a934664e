"""pbrt-v4: scripts/build_pbrt.sh's refusals and its env file, the backend's reading of pbrt's
spectral film, and, where pbrt is built, renders judged like any other backend's (issue 43).

The render tests need pbrt-v4 (not in any package registry): scripts/build_pbrt.sh SRC builds it
from its source into .pbrt/ (.ci/run does when ../shared/pbrt/ holds the source) and writes
.pbrt/env.json, which the runner reads (SPECTRAL_BENCH_PBRT_ENV names another: .ci/run's
.pbrt/ci-env.json); a ``pbrt`` on PATH also serves. Without one they skip with a visible reason.

pbrt's renders are taken as random from machine to machine (its build is -march=native, its film
sums in threads): every judgement here takes its share of the suite's false-alarm budget
(tests/conftest.py RANDOM_TEST_ALPHA)."""
import io
import json
import os
import shutil
import subprocess
import sys
import tarfile

import numpy as np
import pytest

from conftest import ROOT, metrics, run_batch, write_scene
from spectral_bench.batch import exr, spectral_exr
from spectral_bench.batch.backends.pbrt import backend as pbrt_backend

PBRT = pbrt_backend.find_pbrt()
needs_pbrt = pytest.mark.skipif(not PBRT, reason=(
    f"no pbrt-v4: no {pbrt_backend.ENV_FILE} (scripts/build_pbrt.sh SRC builds pbrt from its source; .ci/run does "
    "when ../shared/pbrt/ holds it) and no pbrt on PATH: pbrt renders not run"))
BUILD_PBRT = ROOT / "scripts" / "build_pbrt.sh"


# -- scripts/build_pbrt.sh: a wrong source is a clear error (exit 2), before anything is installed ----------------------
def _build_pbrt(*args, **kw):
    return subprocess.run(["bash", str(BUILD_PBRT), *map(str, args)], capture_output=True, text=True, timeout=120, **kw)


def _tarball(path, files, top="src"):
    """A tarball of ``files`` {relative path: bytes} under the folder ``top``."""
    with tarfile.open(path, "w:gz") as t:
        for name, data in files.items():
            info = tarfile.TarInfo(f"{top}/{name}")
            info.size = len(data)
            t.addfile(info, io.BytesIO(data))
    return path


PBRT_CMAKE = b"cmake_minimum_required (VERSION 3.12)\n\nproject (PBRT-V4 LANGUAGES CXX C)\n"


def test_build_pbrt_refuses_a_missing_or_wrong_source_naming_it(tmp_path):
    """Missing; not pbrt-v4 (a folder or tarball of another CMake project; one that says
    project(PBRT-V4) without pbrt's sources); a truncated or noise tarball: exit 2 with a message
    naming the source; the given PREFIX gets no executable and no env file is written."""
    other = tmp_path / "other"
    (other / "src" / "pbrt").mkdir(parents=True)
    (other / "CMakeLists.txt").write_text("cmake_minimum_required(VERSION 3.0)\nproject (NOTPBRT)\n")
    _tarball(tmp_path / "other.tar.gz", {"CMakeLists.txt": b"project (NOTPBRT)\n"})
    _tarball(tmp_path / "hollow.tar.gz", {"CMakeLists.txt": PBRT_CMAKE, "src/pbrt/film.cpp": b"//\n"})
    good_start = _tarball(tmp_path / "whole.tar.gz", {"CMakeLists.txt": PBRT_CMAKE + bytes(range(256)) * 64}).read_bytes()
    (tmp_path / "corrupt.tar.gz").write_bytes(good_start[: len(good_start) // 2])  # a truncated copy
    (tmp_path / "noise.tar.gz").write_bytes(bytes(range(256)) * 8)
    cases = {tmp_path / "missing.tar.gz": "does not exist", other: "is not pbrt-v4's source",
             tmp_path / "other.tar.gz": "does not hold pbrt-v4's source",
             tmp_path / "hollow.tar.gz": "does not hold pbrt-v4's source",
             tmp_path / "corrupt.tar.gz": "not a readable tarball", tmp_path / "noise.tar.gz": "not a readable tarball"}
    env = dict(os.environ, SPECTRAL_BENCH_PBRT_ENV=str(tmp_path / "env.json"))
    for src, words in cases.items():
        proc = _build_pbrt(src, tmp_path / "prefix", env=env)
        assert proc.returncode == 2, (src, proc.stderr)
        assert words in proc.stderr and str(src.name) in proc.stderr, (src, proc.stderr)
        assert not (tmp_path / "prefix" / "bin").exists() and not (tmp_path / "env.json").exists()
        assert not (tmp_path / "prefix" / ".build" / "src").exists()
    assert _build_pbrt().returncode == 2 and "usage" in _build_pbrt().stderr


def test_build_pbrt_a_name_beginning_with_a_dash_is_data_and_a_failed_unpack_leaves_nothing(tmp_path):
    """SRC beginning with '-': a file of that name is a source like any (here not pbrt's: exit 2
    naming it), a name that is no file is an option the script does not take (exit 2, usage), and
    so is such a PREFIX; a tarball tar cannot read leaves no half-unpacked PREFIX/.build/src.new."""
    _tarball(tmp_path / "-other.tar.gz", {"CMakeLists.txt": b"project (NOTPBRT)\n"}, top="other")
    prefix = tmp_path / "prefix"
    proc = subprocess.run(["bash", str(BUILD_PBRT), "-other.tar.gz", prefix], capture_output=True, text=True,
                          timeout=120, cwd=tmp_path)
    assert proc.returncode == 2 and "does not hold pbrt-v4's source" in proc.stderr and "-other.tar.gz" in proc.stderr, proc.stderr
    for args, named in ((["--help"], "--help"), (["-x", prefix], "-x"), ([tmp_path / "-other.tar.gz", "--prefix"], "--prefix")):
        proc = _build_pbrt(*args)
        assert proc.returncode == 2 and "usage" in proc.stderr and f"'{named}' is not an option" in proc.stderr, (args, proc.stderr)
    assert not (tmp_path / "--prefix").exists()
    whole = (tmp_path / "-other.tar.gz").read_bytes()
    (tmp_path / "cut.tar.gz").write_bytes(whole[: len(whole) // 2])
    proc = _build_pbrt(tmp_path / "cut.tar.gz", prefix)
    assert proc.returncode == 2 and "not a readable tarball" in proc.stderr, proc.stderr
    assert not (prefix / ".build" / "src.new").exists(), sorted(p.name for p in (prefix / ".build").iterdir())


def _pbrt_shaped_tarball(path, owner=None, setuid=False):
    """A tarball with pbrt-v4's shape (top CMakeLists.txt with project(PBRT-V4), src/pbrt/cmd/pbrt.cpp,
    src/pbrt/film.cpp) under src/, as the workplace's is; ``owner``: its files' uid and gid."""
    with tarfile.open(path, "w") as t:
        def add(name, data=None, mode=0o644):
            info = tarfile.TarInfo(name)
            if owner is not None:
                info.uid = info.gid = owner
                info.uname = info.gname = "stranger"
            if data is None:
                info.type, info.mode = tarfile.DIRTYPE, 0o755
                t.addfile(info)
            else:
                info.mode, info.size = mode, len(data)
                t.addfile(info, io.BytesIO(data))
        for folder in ("src", "src/src", "src/src/pbrt", "src/src/pbrt/cmd"):
            add(folder)
        add("src/CMakeLists.txt", PBRT_CMAKE)
        add("src/src/pbrt/cmd/pbrt.cpp", b"int main() {}\n", mode=0o6755 if setuid else 0o644)
        add("src/src/pbrt/film.cpp", b"//\n")
    return path


def _tools_only(tmp_path, tools):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    for tool in tools:
        (bin_dir / tool).symlink_to(shutil.which(tool))
    return str(bin_dir)


BEFORE_CMAKE = ("dirname", "basename", "mkdir", "sha256sum", "cut", "cat", "rm", "tar", "head", "tr", "grep", "mv")


@pytest.mark.skipif(os.geteuid() != 0, reason="only root's tar keeps a tarball's owners and setuid bits")
def test_build_pbrt_unpacks_a_tarball_as_its_own_files_not_the_tarballs_owners(tmp_path):
    """As root, a source tarball whose files belong to uid 12345 with setuid and setgid bits
    unpacks as root's files without them. The script then stops where a machine without dpkg and
    cmake stops it (exit 3, naming cmake), leaving the unpacked source to look at."""
    src = _pbrt_shaped_tarball(tmp_path / "pbrt-v4-src.tar", owner=12345, setuid=True)
    proc = subprocess.run([shutil.which("bash"), str(BUILD_PBRT), src, tmp_path / "prefix"], capture_output=True,
                          text=True, timeout=120, env={"PATH": _tools_only(tmp_path, BEFORE_CMAKE)})
    assert proc.returncode == 3 and "'cmake' is missing" in proc.stderr, proc.stderr
    unpacked = tmp_path / "prefix" / ".build" / "src" / "src"
    for path in (unpacked, unpacked / "src" / "pbrt" / "cmd", unpacked / "src" / "pbrt" / "cmd" / "pbrt.cpp", unpacked / "CMakeLists.txt"):
        st = path.lstat()
        assert (st.st_uid, st.st_gid) == (0, 0), (path, st.st_uid, st.st_gid)
        assert not st.st_mode & 0o7000, (path, oct(st.st_mode))


def test_build_pbrt_without_root_names_the_packages_and_stops(tmp_path):
    """Not root and a package missing: exit 3, naming the apt-get command to run, before any
    configure (a dpkg-query that knows no package stands in for a machine without them; id says
    uid 1000)."""
    src = _pbrt_shaped_tarball(tmp_path / "pbrt-v4-src.tar")
    path = _tools_only(tmp_path, BEFORE_CMAKE)
    for name, body in (("dpkg-query", "exit 1"), ("id", "echo 1000")):
        (tmp_path / "bin" / name).write_text(f"#!{shutil.which('bash')}\n{body}\n")
        (tmp_path / "bin" / name).chmod(0o755)
    proc = subprocess.run([shutil.which("bash"), str(BUILD_PBRT), src, tmp_path / "prefix"], capture_output=True,
                          text=True, timeout=120, env={"PATH": path})
    assert proc.returncode == 3, proc.stderr
    assert "apt-get install cmake ninja-build g++" in proc.stderr and "libopenexr-dev" in proc.stderr, proc.stderr
    assert not (tmp_path / "prefix" / ".build" / "cmake").exists()


@pytest.mark.skipif(not (pbrt_backend.built_pbrt() and pbrt_backend.ENV_FILE.is_file()),
                    reason=f"pbrt not built with scripts/build_pbrt.sh here ({pbrt_backend.ENV_FILE}): nothing to rebuild")
def test_build_pbrt_second_run_over_a_finished_build_does_no_work():
    """Idempotent: rerun on the source the env file records, ninja has nothing to compile, the
    executable is not rewritten, and the env file names the same pbrt."""
    record = json.loads(pbrt_backend.ENV_FILE.read_text())
    if not os.path.exists(record["source"]):
        pytest.skip(f"the source pbrt was built from ({record['source']}) is gone")
    exe = record["pbrt"]
    prefix = os.path.dirname(os.path.dirname(exe))
    before = os.stat(exe).st_mtime_ns
    proc = _build_pbrt(record["source"], prefix, env=dict(os.environ, SPECTRAL_BENCH_PBRT_ENV=str(pbrt_backend.ENV_FILE)))
    assert proc.returncode == 0, proc.stderr
    assert "no work to do" in open(os.path.join(prefix, ".build", "build.log")).read()
    assert os.stat(exe).st_mtime_ns == before
    assert json.loads(pbrt_backend.ENV_FILE.read_text()) == record


def test_env_file_gives_the_pbrt_to_run(tmp_path, monkeypatch):
    """The env file scripts/build_pbrt.sh writes: its pbrt is found without -e or PATH; one given
    with -e wins; a missing pbrt or a broken file is as if there were none (PATH is searched), and
    the backend then says how to build it."""
    exe = tmp_path / "prefix" / "bin" / "pbrt"
    exe.parent.mkdir(parents=True)
    exe.write_text("#!/bin/sh\nexit 0\n")
    exe.chmod(0o755)
    env_file = tmp_path / "env.json"
    env_file.write_text(json.dumps({"pbrt": str(exe), "source": "x"}))
    monkeypatch.setattr(pbrt_backend, "ENV_FILE", env_file)
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    assert pbrt_backend.find_pbrt() == exe and pbrt_backend.PbrtBackend().availability() == (True, "")
    other = tmp_path / "other-pbrt"
    shutil.copy(exe, other)
    assert pbrt_backend.find_pbrt(str(other)) == other
    exe.unlink()
    assert pbrt_backend.find_pbrt() is None
    ok, why = pbrt_backend.PbrtBackend().availability()
    assert not ok and "scripts/build_pbrt.sh" in why and "env.json" in why
    env_file.write_text("{not json")
    assert pbrt_backend.built_pbrt() is None


def test_the_env_file_path_comes_from_the_environment(tmp_path):
    """SPECTRAL_BENCH_PBRT_ENV names the env file the backend reads (.ci/run names its own to the
    tests only), read when the backend is imported."""
    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); import pkg_bootstrap; pkg_bootstrap.package(); "
            "from spectral_bench.batch.backends.pbrt import backend as b; print(b.ENV_FILE)")
    proc = subprocess.run([sys.executable, "-c", code],
                          capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, SPECTRAL_BENCH_PBRT_ENV=str(tmp_path / "x.json")))
    assert proc.returncode == 0 and proc.stdout.strip() == str(tmp_path / "x.json"), proc.stderr
