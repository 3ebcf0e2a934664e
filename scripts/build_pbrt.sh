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
say() { echo "build_pbrt: $*" >&2; }
die() { local code=$1; shift; say "error: $*"; exit "$code"; }

USAGE="usage: scripts/build_pbrt.sh SRC [PREFIX]  (SRC: pbrt-v4's source tarball or folder)"
[ $# -ge 1 ] && [ $# -le 2 ] || die 2 "$USAGE"
SRC=$1
PREFIX=${2:-$REPO/.pbrt}
# names are data: a path beginning with '-' that exists is a path (every command below gets it after
# --); one that does not exist is an option this script does not take (a usage error, exit 2)
for arg in "$SRC" "${2:-}"; do
  case $arg in
    -*) [ -e "$arg" ] || die 2 "'$arg' is not an option of this script, and no such file ($USAGE; a file whose name begins with '-': ./$arg)";;
  esac
done
[ -e "$SRC" ] || die 2 "pbrt source '$SRC' does not exist (give the path of pbrt-v4's source tarball or folder; this script never downloads it)"
SRC=$(cd -- "$(dirname -- "$SRC")" && pwd -P)/$(basename -- "$SRC")
mkdir -p -- "$PREFIX" || die 2 "cannot create PREFIX '$PREFIX'"
PREFIX=$(cd -- "$PREFIX" && pwd -P)

# ---- the source: a folder is used in place; a tarball is unpacked once into PREFIX/.build/src
is_pbrt_tree() {  # $1: a folder; true when it is pbrt-v4's source top level
  [ -f "$1/CMakeLists.txt" ] && grep -qE '^[[:space:]]*project[[:space:]]*\([[:space:]]*PBRT-V4([[:space:]]|\))' "$1/CMakeLists.txt" \
    && [ -f "$1/src/pbrt/cmd/pbrt.cpp" ] && [ -f "$1/src/pbrt/film.cpp" ]
}
pbrt_top() {  # $1: a folder; prints pbrt's top level inside it (itself or one level down)
  local d
  if is_pbrt_tree "$1"; then echo "$1"; return 0; fi
  for d in "$1"/*/; do
    d=${d%/}
    if is_pbrt_tree "$d"; then echo "$d"; return 0; fi
  done
  return 1
}
NOT_PBRT="no CMakeLists.txt with project(PBRT-V4) beside src/pbrt/cmd/pbrt.cpp and src/pbrt/film.cpp"
BUILD=$PREFIX/.build
mkdir -p "$BUILD"
if [ -d "$SRC" ]; then
  TOP=$(pbrt_top "$SRC") || die 2 "'$SRC' is not pbrt-v4's source: $NOT_PBRT"
  STAMP="dir:$TOP"
else
  SUM=$(sha256sum -- "$SRC" | cut -d' ' -f1) || die 2 "cannot read '$SRC'"
  STAMP="tar:$SUM"
  if [ "$(cat "$BUILD/source.stamp" 2>/dev/null)" = "$STAMP" ] && TOP=$(pbrt_top "$BUILD/src"); then
    say "source already unpacked ($BUILD/src)"
  else
    rm -rf "$BUILD/src.new" && mkdir -p "$BUILD/src.new"
    # the tarball is anyone's: as root, tar would keep its owners (any uid) and its modes (setuid
    # bits); the files are ours, with the umask's permissions
    tar --no-same-owner --no-same-permissions -xf "$SRC" -C "$BUILD/src.new" 2>"$BUILD/tar.log" \
      || { rm -rf "$BUILD/src.new"; die 2 "'$SRC' is not a readable tarball ($(head -c 300 "$BUILD/tar.log" | tr '\n' ' '))"; }
    pbrt_top "$BUILD/src.new" >/dev/null || { rm -rf "$BUILD/src.new"; die 2 "'$SRC' does not hold pbrt-v4's source: $NOT_PBRT"; }
    # a new source: start the build from scratch so nothing of an older tree survives
    rm -rf "$BUILD/src" "$BUILD/cmake" "$BUILD/source.stamp"
    mv "$BUILD/src.new" "$BUILD/src"
    TOP=$(pbrt_top "$BUILD/src")
  fi
fi
if [ "$(cat "$BUILD/source.stamp" 2>/dev/null)" != "$STAMP" ]; then rm -rf "$BUILD/cmake" "$PREFIX/bin/pbrt"; fi

# ---- Debian packages, once the source is known good (a wrong source fails before any install):
# the toolchain, the system OpenEXR/Imath/libdeflate/zlib pbrt links, and the X11/GL headers its
# bundled GLFW needs to configure (pbrt_exe links GLFW for its interactive viewer)
PACKAGES="cmake ninja-build g++ zlib1g-dev libopenexr-dev libimath-dev libdeflate-dev libx11-dev libxext-dev libgl-dev libxrandr-dev libxinerama-dev libxcursor-dev libxi-dev"
missing_packages() {
  local p out=""
  for p in $PACKAGES; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || out="$out $p"
  done
  echo "${out# }"
}
if command -v dpkg-query >/dev/null; then
  MISSING=$(missing_packages)
  if [ -n "$MISSING" ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      say "installing Debian packages: $MISSING"
      # shellcheck disable=SC2086
      apt-get install -y -qq --no-install-recommends $MISSING >/dev/null 2>&1 \
        || { apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq --no-install-recommends $MISSING >/dev/null; } \
        || die 3 "apt-get could not install: $MISSING"
    else
      die 3 "pbrt-v4 needs these Debian packages; install them as root, then rerun:
  apt-get install $MISSING"
    fi
  fi
else
  for tool in cmake ninja g++; do
    command -v "$tool" >/dev/null || die 3 "not a Debian system and '$tool' is missing; pbrt-v4 needs: $PACKAGES (or your system's equivalents)"
  done
fi

# ---- configure and build the executable only
JOBS=$(nproc 2>/dev/null || echo 1)
if [ ! -f "$BUILD/cmake/build.ninja" ]; then
  say "configuring $TOP"
  # Git off: pbrt's CMake checks each submodule's commit with git, which fails in a tree unpacked
  # inside another git checkout; Wayland off: GLFW's Wayland backend needs packages the executable
  # does not use here
  cmake -S "$TOP" -B "$BUILD/cmake" -G Ninja -DCMAKE_BUILD_TYPE=Release -DGLFW_BUILD_WAYLAND=OFF \
    -DBUILD_TESTING=OFF -DCMAKE_DISABLE_FIND_PACKAGE_Git=ON \
    >"$BUILD/configure.log" 2>&1 || { tail -n 30 "$BUILD/configure.log" >&2; die 4 "cmake failed (log: $BUILD/configure.log)"; }
fi
echo "$STAMP" >"$BUILD/source.stamp"
say "building pbrt_exe with ninja -j$JOBS (log: $BUILD/build.log)"
ninja -C "$BUILD/cmake" -j "$JOBS" pbrt_exe >"$BUILD/build.log" 2>&1 || { tail -n 30 "$BUILD/build.log" >&2; die 4 "ninja failed (log: $BUILD/build.log)"; }
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
PBRT="$PBRT" SRC="$SRC" ENV_FILE="$ENV_FILE" python3 - <<'EOF'
import json, os
record = {"pbrt": os.environ["PBRT"], "source": os.environ["SRC"]}
tmp = os.environ["ENV_FILE"] + ".tmp"
with open(tmp, "w") as f:
    json.dump(record, f, indent=2)
    f.write("\n")
os.replace(tmp, os.environ["ENV_FILE"])
EOF
say "pbrt installed as $PBRT; $ENV_FILE written (batch/run.py -r pbrt uses it)"
