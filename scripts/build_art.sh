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
say() { echo "build_art: $*" >&2; }
die() { local code=$1; shift; say "error: $*"; exit "$code"; }

USAGE="usage: scripts/build_art.sh SRC [PREFIX]  (SRC: ART's source tarball or folder)"
[ $# -ge 1 ] && [ $# -le 2 ] || die 2 "$USAGE"
SRC=$1
PREFIX=${2:-$REPO/.art}
# names are data: a path beginning with '-' that exists is a path (every command below gets it after
# --); one that does not exist is an option this script does not take (a usage error, exit 2)
for arg in "$SRC" "${2:-}"; do
  case $arg in
    -*) [ -e "$arg" ] || die 2 "'$arg' is not an option of this script, and no such file ($USAGE; a file whose name begins with '-': ./$arg)";;
  esac
done
[ -e "$SRC" ] || die 2 "ART source '$SRC' does not exist (give the path of ART's source tarball or folder; this script never downloads it)"
SRC=$(cd -- "$(dirname -- "$SRC")" && pwd -P)/$(basename -- "$SRC")
mkdir -p -- "$PREFIX" || die 2 "cannot create PREFIX '$PREFIX'"
PREFIX=$(cd -- "$PREFIX" && pwd -P)

# ---- the source: a folder is used in place; a tarball is unpacked once into PREFIX/.build/src
is_art_tree() {  # $1: a folder; true when it is ART's source top level
  [ -f "$1/CMakeLists.txt" ] && grep -qE '^[[:space:]]*project[[:space:]]*\([[:space:]]*ART[[:space:]]*\)' "$1/CMakeLists.txt" \
    && [ -d "$1/Source" ] && [ -d "$1/ART_Resources" ]
}
art_top() {  # $1: a folder; prints ART's top level inside it (itself or one level down)
  local d
  if is_art_tree "$1"; then echo "$1"; return 0; fi
  for d in "$1"/*/; do
    d=${d%/}
    if is_art_tree "$d"; then echo "$d"; return 0; fi
  done
  return 1
}
BUILD=$PREFIX/.build
mkdir -p "$BUILD"
if [ -d "$SRC" ]; then
  TOP=$(art_top "$SRC") || die 2 "'$SRC' is not ART's source: no CMakeLists.txt with project(ART) beside Source/ and ART_Resources/"
  STAMP="dir:$TOP"
else
  SUM=$(sha256sum -- "$SRC" | cut -d' ' -f1) || die 2 "cannot read '$SRC'"
  STAMP="tar:$SUM"
  if [ "$(cat "$BUILD/source.stamp" 2>/dev/null)" = "$STAMP" ] && TOP=$(art_top "$BUILD/src"); then
    say "source already unpacked ($BUILD/src)"
  else
    rm -rf "$BUILD/src.new" && mkdir -p "$BUILD/src.new"
    # the tarball is anyone's: as root, tar would keep its owners (any uid) and its modes (setuid
    # bits); the files are ours, with the umask's permissions
    tar --no-same-owner --no-same-permissions -xf "$SRC" -C "$BUILD/src.new" 2>"$BUILD/tar.log" \
      || { rm -rf "$BUILD/src.new"; die 2 "'$SRC' is not a readable tarball ($(head -c 300 "$BUILD/tar.log" | tr '\n' ' '))"; }
    art_top "$BUILD/src.new" >/dev/null || { rm -rf "$BUILD/src.new"; die 2 "'$SRC' does not hold ART's source: no CMakeLists.txt with project(ART) beside Source/ and ART_Resources/"; }
    # a new source: start the build from scratch so nothing of an older tree survives
    rm -rf "$BUILD/src" "$BUILD/cmake" "$BUILD/source.stamp"
    mv "$BUILD/src.new" "$BUILD/src"
    TOP=$(art_top "$BUILD/src")
  fi
fi
if [ "$(cat "$BUILD/source.stamp" 2>/dev/null)" != "$STAMP" ]; then rm -rf "$BUILD/cmake"; fi

# ---- Debian packages, once the source is known good (a wrong source fails before any install):
# the list of ART's own .gitlab-ci.yml; gcc, gobjc and GNUstep stay needed at render time (artist
# compiles every .arm scene)
PACKAGES="cmake ninja-build pkg-config make gcc g++ gobjc gobjc++ libtiff-dev liblcms2-dev libgnustep-base-dev libgsl-dev libopenexr-dev"
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
      die 3 "ART needs these Debian packages; install them as root, then rerun:
  apt-get install $MISSING"
    fi
  fi
else
  for tool in cmake ninja gcc pkg-config; do
    command -v "$tool" >/dev/null || die 3 "not a Debian system and '$tool' is missing; ART needs: $PACKAGES (or your system's equivalents)"
  done
fi

# ---- configure, build, install
JOBS=$(nproc 2>/dev/null || echo 1)
if [ ! -f "$BUILD/cmake/build.ninja" ]; then
  say "configuring $TOP"
  cmake -S "$TOP" -B "$BUILD/cmake" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX="$PREFIX" \
    >"$BUILD/configure.log" 2>&1 || { tail -n 30 "$BUILD/configure.log" >&2; die 4 "cmake failed (log: $BUILD/configure.log)"; }
fi
echo "$STAMP" >"$BUILD/source.stamp"
say "building with ninja -j$JOBS (log: $BUILD/build.log)"
ninja -C "$BUILD/cmake" -j "$JOBS" >"$BUILD/build.log" 2>&1 || { tail -n 30 "$BUILD/build.log" >&2; die 4 "ninja failed (log: $BUILD/build.log)"; }
ninja -C "$BUILD/cmake" install >"$BUILD/install.log" 2>&1 || { tail -n 30 "$BUILD/install.log" >&2; die 4 "ninja install failed (log: $BUILD/install.log)"; }
ARTIST=$PREFIX/bin/artist
[ -x "$ARTIST" ] || die 4 "the install has no $ARTIST"
[ -d "$PREFIX/lib/ART_Resources" ] || die 4 "the install has no $PREFIX/lib/ART_Resources"

# ---- the env file the runner reads (applied to artist's child process only)
mkdir -p "$REPO/.art"
ENV_FILE=${SPECTRAL_BENCH_ART_ENV:-$REPO/.art/env.json}  # where the runner reads it (batch/backends/art/backend.py)
PREFIX="$PREFIX" ARTIST="$ARTIST" SRC="$SRC" ENV_FILE="$ENV_FILE" python3 - <<'EOF'
import json, os
prefix = os.environ["PREFIX"]
record = {
    "artist": os.environ["ARTIST"],
    "source": os.environ["SRC"],
    "env": {
        "PATH": os.path.join(prefix, "bin"),
        "LD_LIBRARY_PATH": os.path.join(prefix, "lib"),
        "ART_LIBRARY_PATH": os.path.join(prefix, "lib"),
        "ART_RESOURCE_PATH": os.path.join(prefix, "lib", "ART_Resources"),
        "LC_NUMERIC": "C",
        "ART_VIEWER": "true",
    },
}
tmp = os.environ["ENV_FILE"] + ".tmp"
with open(tmp, "w") as f:
    json.dump(record, f, indent=2)
    f.write("\n")
os.replace(tmp, os.environ["ENV_FILE"])
EOF
say "ART installed in $PREFIX; $ENV_FILE written (batch/run.py -r art uses it)"
