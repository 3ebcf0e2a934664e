#!/usr/bin/env bash
# Build ART (the Advanced Rendering Toolkit, 2.1.2) from a source the user has, and make
# `batch/run.py -r art` find it with no other step.
#
#   scripts/build_art.sh SRC [PREFIX]
#
# SRC    ART's source: a tarball (.tar, .tar.gz, .tgz, .tar.xz, .tar.bz2) or a folder holding
#        ART's top-level CMakeLists.txt (one level of wrapping folder is fine, e.g. artsrc/).
# PREFIX where to install (default: .art/ in this repository, ignored by git).
#
# Never downloads ART. As root it installs the Debian packages ART needs (apt-get); otherwise it
# names them and stops. It builds out of tree (cmake + ninja, -j from nproc) in PREFIX/.build,
# installs into PREFIX and writes .art/env.json in this repository: the runner reads it for the
# artist executable and the environment its child process gets (PATH, LD_LIBRARY_PATH,
# ART_RESOURCE_PATH, ART_LIBRARY_PATH, LC_NUMERIC=C, ART_VIEWER=true). A second run over a
# finished build of the same source only checks it (seconds).
#
# SRC and PREFIX are paths, whatever their names: one beginning with '-' that exists is a path; one
# that does not is taken for an option, which this script has none of (exit 2). A tarball unpacks as
# the user's files (never its owners or setuid bits, as root too); a failed unpack leaves nothing.
#
# Exit codes: 0 built (or already built); 2 usage or source error (missing, not ART, corrupt);
# 3 packages missing and not root (or apt-get failed); 4 configure/build/install failed.
set -euo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
BUILD_PROG=build_art
PROGRAM=ART
# say, die and the steps both build scripts share (argument checks, unpacking, packages, cmake, ninja)
# shellcheck source=scripts/build_common.sh
. "$REPO/scripts/build_common.sh"

build_args "usage: scripts/build_art.sh SRC [PREFIX]  (SRC: ART's source tarball or folder)" "$REPO/.art" "ART source" "$@"

# ---- the source: a folder is used in place; a tarball is unpacked once into PREFIX/.build/src
is_art_tree() {  # $1: a folder; true when it is ART's source top level
  [ -f "$1/CMakeLists.txt" ] && grep -qE '^[[:space:]]*project[[:space:]]*\([[:space:]]*ART[[:space:]]*\)' "$1/CMakeLists.txt" \
    && [ -d "$1/Source" ] && [ -d "$1/ART_Resources" ]
}
build_source is_art_tree "no CMakeLists.txt with project(ART) beside Source/ and ART_Resources/"

# ---- Debian packages, once the source is known good (a wrong source fails before any install):
# the list of ART's own .gitlab-ci.yml; gcc, gobjc and GNUstep stay needed at render time (artist
# compiles every .arm scene)
PACKAGES="cmake ninja-build pkg-config make gcc g++ gobjc gobjc++ libtiff-dev liblcms2-dev libgnustep-base-dev libgsl-dev libopenexr-dev"
build_install_packages cmake ninja gcc pkg-config

# ---- configure, build, install
JOBS=$(nproc 2>/dev/null || echo 1)
build_configure -DCMAKE_INSTALL_PREFIX="$PREFIX"
say "building with ninja -j$JOBS (log: $BUILD/build.log)"
build_ninja build ninja -j "$JOBS"
build_ninja install "ninja install" install
ARTIST=$PREFIX/bin/artist
[ -x "$ARTIST" ] || die 4 "the install has no $ARTIST"
[ -d "$PREFIX/lib/ART_Resources" ] || die 4 "the install has no $PREFIX/lib/ART_Resources"

# ---- the env file the runner reads (applied to artist's child process only)
mkdir -p "$REPO/.art"
ENV_FILE=${SPECTRAL_BENCH_ART_ENV:-$REPO/.art/env.json}  # where the runner reads it (batch/backends/art/backend.py)
build_env_file "$ENV_FILE" artist "$ARTIST" source "$SRC" \
  env.PATH "${PREFIX%/}/bin" env.LD_LIBRARY_PATH "${PREFIX%/}/lib" env.ART_LIBRARY_PATH "${PREFIX%/}/lib" \
  env.ART_RESOURCE_PATH "${PREFIX%/}/lib/ART_Resources" env.LC_NUMERIC C env.ART_VIEWER true
say "ART installed in $PREFIX; $ENV_FILE written (batch/run.py -r art uses it)"
