"""scripts/build_art.sh and scripts/build_pbrt.sh as the tests drive them: what each one builds
(the shape of its source, the words of its messages, its CI step) and the tarballs, stand-in tools
and runs the tests of both share (tests/backends/test_build_scripts.py, tests/project/test_ci_run.py,
the second-run tests of tests/backends/test_art.py and test_pbrt.py)."""
import io
import os
import shutil
import subprocess
import tarfile
from dataclasses import dataclass

from conftest import ROOT


@dataclass(frozen=True)
class Program:
    name: str           # the test id; scripts/build_<name>.sh, .ci/<name>
    source_name: str    # how the script's messages name its source ("ART's source")
    env_variable: str   # where the script writes its env file (the runner reads it)
    env_key: str        # the executable's entry in the env file
    packages: str       # the start of the apt-get command the script names when packages are missing
    ci_prefix: str      # .ci/<name>'s variables: <ci_prefix>_SRC, _PREFIX, _CI_ENV
    top: str            # the folder its source tarball unpacks to
    cmake: bytes        # the source's top CMakeLists.txt
    folders: tuple      # the source's folders below top (parents first)
    files: dict         # the source's files below top besides CMakeLists.txt: {path: bytes}; the first is the executable's

    @property
    def script(self):
        return ROOT / "scripts" / f"build_{self.name}.sh"

    @property
    def ci_step(self):
        return f".ci/{self.name}"


ART = Program("art", "ART's source", "SPECTRAL_BENCH_ART_ENV", "artist", "cmake ninja-build pkg-config", "ART",
              top="ART-src", cmake=b"project (ART)\n", folders=("Source", "ART_Resources"),
              files={"Source/tool": b"#!/bin/sh\n"})
PBRT = Program("pbrt", "pbrt-v4's source", "SPECTRAL_BENCH_PBRT_ENV", "pbrt", "cmake ninja-build g++", "PBRT",
               top="src", cmake=b"cmake_minimum_required (VERSION 3.12)\n\nproject (PBRT-V4 LANGUAGES CXX C)\n",
               folders=("src", "src/pbrt", "src/pbrt/cmd"),
               files={"src/pbrt/cmd/pbrt.cpp": b"int main() {}\n", "src/pbrt/film.cpp": b"//\n"})
PROGRAMS = (ART, PBRT)

# what the scripts run up to cmake (a PATH of these only: the script stops where cmake is missing)
BEFORE_CMAKE = ("dirname", "basename", "mkdir", "sha256sum", "cut", "cat", "rm", "tar", "head", "tr", "grep", "mv")


def run(program, *args, **kw):
    """scripts/build_<name>.sh ARGS... (subprocess.run's result, text)."""
    return subprocess.run(["bash", str(program.script), *map(str, args)], capture_output=True, text=True,
                          timeout=120, **kw)


def tarball(path, files, top):
    """A gzipped tarball of ``files`` {relative path: bytes} under the folder ``top`` (no folder entries)."""
    with tarfile.open(path, "w:gz") as t:
        for name, data in files.items():
            info = tarfile.TarInfo(f"{top}/{name}")
            info.size = len(data)
            t.addfile(info, io.BytesIO(data))
    return path


def not_source_tarball(path):
    """A tarball of another CMake project (under other/)."""
    return tarball(path, {"CMakeLists.txt": b"project (NOTTHIS)\n"}, top="other")


def truncated_tarball(path):
    """The first half of a gzipped tarball (a download cut short): tar cannot read it."""
    whole = tarball(path.with_name("whole-" + path.name), {"CMakeLists.txt": bytes(range(256)) * 64}, top="x").read_bytes()
    path.write_bytes(whole[: len(whole) // 2])
    return path


def shaped_tarball(program, path, owner=None, setuid=False):
    """A tarball (uncompressed, with folder entries) with the shape of ``program``'s source under
    its top folder; ``owner``: its entries' uid and gid; ``setuid``: the executable's source file
    has setuid and setgid bits."""
    with tarfile.open(path, "w") as t:
        def add(name, data=None, mode=0o644):
            info = tarfile.TarInfo(f"{program.top}/{name}" if name else program.top)
            if owner is not None:
                info.uid = info.gid = owner
                info.uname = info.gname = "stranger"
            if data is None:
                info.type, info.mode = tarfile.DIRTYPE, 0o755
                t.addfile(info)
            else:
                info.mode, info.size = mode, len(data)
                t.addfile(info, io.BytesIO(data))
        for folder in ("", *program.folders):
            add(folder)
        add("CMakeLists.txt", program.cmake)
        for i, (name, data) in enumerate(program.files.items()):
            add(name, data, mode=0o6755 if setuid and i == 0 else 0o644)
    return path


def tools_only(tmp_path, tools):
    """tmp_path/bin holding links to ``tools`` only (a PATH without the rest)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    for tool in tools:
        (bin_dir / tool).symlink_to(shutil.which(tool))
    return str(bin_dir)


def ci_step(program, tmp_path, src, path=None):
    """.ci/<name> as .ci/run runs it (sourced under ``set -euo pipefail`` in the repository root),
    with the source ``src``, building into tmp_path/prefix and naming tmp_path/ci-env.json (there
    from an earlier CI run) to the tests; what the tests would get is printed after it."""
    (tmp_path / "ci-env.json").write_text(f'{{"{program.env_key}": "/an/earlier/build/bin/{program.env_key}"}}\n')
    env = dict(os.environ, **{f"{program.ci_prefix}_SRC": str(src), f"{program.ci_prefix}_PREFIX": str(tmp_path / "prefix"),
                              f"{program.ci_prefix}_CI_ENV": str(tmp_path / "ci-env.json")})
    if path is not None:
        env["PATH"] = path
    return subprocess.run([shutil.which("bash"), "-c",
                           f'set -euo pipefail; . {program.ci_step}; echo "tests get: ${program.env_variable}"'],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
