#!/usr/bin/env bash
# Build pbrt-v4 from a source the user has, and make `batch/run.py -r pbrt` find it with no other
# step (issue 43, item 1).
#
#   scripts/build_pbrt.sh SRC [PREFIX]
#
# SRC    pbrt-v4's source with its submodules: a tarball (.tar, .tar.gz, .tgz, .tar.xz, .tar.bz2) or
#        a folder holding pbrt-v4's top-level CMakeLists.txt (one level of wrapping folder is fine,
#        e.g. the workplace's tarball unpacks to src/).
# PREFIX where to install (default: .pbrt/ in this repository, ignored by git).
#
# Never downloads pbrt. As root it installs the Debian packages pbrt needs (apt-get); otherwise it
# names them and stops. It builds out of tree (cmake + ninja, -j from nproc) in PREFIX/.build, and
# only the target the backend runs (`ninja pbrt_exe`: not the tests, imgtool or the GPU build),
# copies the executable to PREFIX/bin/pbrt and writes .pbrt/env.json in this repository
# (SPECTRAL_BENCH_PBRT_ENV overrides where): the runner reads it for the pbrt executable. A second
# run over a finished build of the same source only checks it (seconds).
#
# SRC and PREFIX are paths, whatever their names: one beginning with '-' that exists is a path; one
# that does not is taken for an option, which this script has none of (exit 2). A tarball unpacks as
# the user's files (never its owners or setuid bits, as root too); a failed unpack leaves nothing.
#
# Exit codes (as scripts/build_art.sh): 0 built (or already built); 2 usage or source error
# (missing, not pbrt-v4, corrupt); 3 packages missing and not root (or apt-get failed);
# 4 configure/build failed.
set -euo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
BUILD_PROG=build_pbrt
PROGRAM=pbrt-v4
# say, die and the steps both build scripts share (argument checks, unpacking, packages, cmake, ninja)
# shellcheck source=scripts/build_common.sh
. "$REPO/scripts/build_common.sh"

build_args "usage: scripts/build_pbrt.sh SRC [PREFIX]  (SRC: pbrt-v4's source tarball or folder)" "$REPO/.pbrt" "pbrt source" "$@"

# ---- the source: a folder is used in place; a tarball is unpacked once into PREFIX/.build/src
is_pbrt_tree() {  # $1: a folder; true when it is pbrt-v4's source top level
  [ -f "$1/CMakeLists.txt" ] && grep -qE '^[[:space:]]*project[[:space:]]*\([[:space:]]*PBRT-V4([[:space:]]|\))' "$1/CMakeLists.txt" \
    && [ -f "$1/src/pbrt/cmd/pbrt.cpp" ] && [ -f "$1/src/pbrt/film.cpp" ]
}
# a build of another source leaves its executable too
build_source is_pbrt_tree "no CMakeLists.txt with project(PBRT-V4) beside src/pbrt/cmd/pbrt.cpp and src/pbrt/film.cpp" \
  "$PREFIX/bin/pbrt"

# ---- Debian packages, once the source is known good (a wrong source fails before any install):
# the toolchain, the system OpenEXR/Imath/libdeflate/zlib pbrt links, and the X11/GL headers its
# bundled GLFW needs to configure (pbrt_exe links GLFW for its interactive viewer)
PACKAGES="cmake ninja-build g++ zlib1g-dev libopenexr-dev libimath-dev libdeflate-dev libx11-dev libxext-dev libgl-dev libxrandr-dev libxinerama-dev libxcursor-dev libxi-dev"
build_install_packages cmake ninja g++

# ---- configure and build the executable only
JOBS=$(nproc 2>/dev/null || echo 1)
# Git off: pbrt's CMake checks each submodule's commit with git, which fails in a tree unpacked
# inside another git checkout; Wayland off: GLFW's Wayland backend needs packages the executable
# does not use here
build_configure -DGLFW_BUILD_WAYLAND=OFF -DBUILD_TESTING=OFF -DCMAKE_DISABLE_FIND_PACKAGE_Git=ON
say "building pbrt_exe with ninja -j$JOBS (log: $BUILD/build.log)"
build_ninja build ninja -j "$JOBS" pbrt_exe
[ -x "$BUILD/cmake/pbrt" ] || die 4 "the build has no $BUILD/cmake/pbrt"
mkdir -p "$PREFIX/bin"
if ! cmp -s -- "$BUILD/cmake/pbrt" "$PREFIX/bin/pbrt"; then
  cp -- "$BUILD/cmake/pbrt" "$PREFIX/bin/pbrt.new" && mv -- "$PREFIX/bin/pbrt.new" "$PREFIX/bin/pbrt"
fi
PBRT=$PREFIX/bin/pbrt
# the executable runs: --help exits 0 and names pbrt's own options
HELP=$("$PBRT" --help 2>&1) || die 4 "$PBRT --help failed: $(echo "$HELP" | head -c 300)"
echo "$HELP" | grep -q -- "--spp" || die 4 "$PBRT --help does not list --spp: not the pbrt-v4 the backend drives"

# ---- the env file the runner reads (batch/backends/pbrt/backend.py)
mkdir -p "$REPO/.pbrt"
ENV_FILE=${SPECTRAL_BENCH_PBRT_ENV:-$REPO/.pbrt/env.json}
build_env_file "$ENV_FILE" pbrt "$PBRT" source "$SRC"
say "pbrt installed as $PBRT; $ENV_FILE written (batch/run.py -r pbrt uses it)"
