# The steps scripts/build_art.sh and scripts/build_pbrt.sh share, sourced by both (not run on its
# own). Each script sets, before calling them:
#   BUILD_PROG  its name in messages (build_art, build_pbrt)
#   PROGRAM     what it builds, as its messages name it (ART, pbrt-v4)
#   PACKAGES    the Debian packages it needs (build_install_packages)
# and keeps its own header, its source detection (a function: is the folder $1 the program's top
# level?) and what it does after the source and the packages are known good.
# The helpers set globals the scripts then read: SRC and PREFIX (absolute), BUILD, TOP, STAMP.

say() { echo "$BUILD_PROG: $*" >&2; }
die() { local code=$1; shift; say "error: $*"; exit "$code"; }

# build_args USAGE DEFAULT_PREFIX SOURCE_NAME ARGS...: the command line SRC [PREFIX] -> SRC and
# PREFIX, absolute, PREFIX created. SOURCE_NAME words the missing source ("ART source").
build_args() {
  local usage=$1 default_prefix=$2 source_name=$3 arg
  shift 3
  [ $# -ge 1 ] && [ $# -le 2 ] || die 2 "$usage"
  SRC=$1
  PREFIX=${2:-$default_prefix}
  # names are data: a path beginning with '-' that exists is a path (every command below gets it after
  # --); one that does not exist is an option this script does not take (a usage error, exit 2)
  for arg in "$SRC" "${2:-}"; do
    case $arg in
      -*) [ -e "$arg" ] || die 2 "'$arg' is not an option of this script, and no such file ($usage; a file whose name begins with '-': ./$arg)";;
    esac
  done
  [ -e "$SRC" ] || die 2 "$source_name '$SRC' does not exist (give the path of $PROGRAM's source tarball or folder; this script never downloads it)"
  SRC=$(cd -- "$(dirname -- "$SRC")" && pwd -P)/$(basename -- "$SRC")
  mkdir -p -- "$PREFIX" || die 2 "cannot create PREFIX '$PREFIX'"
  PREFIX=$(cd -- "$PREFIX" && pwd -P)
}

# build_top IS_TREE DIR: prints the program's top level inside DIR (DIR itself or one level down),
# IS_TREE being the script's test of a folder
build_top() {
  local is_tree=$1 d
  if "$is_tree" "$2"; then echo "$2"; return 0; fi
  for d in "$2"/*/; do
    d=${d%/}
    if "$is_tree" "$d"; then echo "$d"; return 0; fi
  done
  return 1
}

# build_source IS_TREE SHAPE [STALE...]: the source, a folder used in place or a tarball unpacked
# once into PREFIX/.build/src -> BUILD, TOP and STAMP. SHAPE says what the program's source has
# (the message when it has not); STALE: what a build of another source leaves besides
# PREFIX/.build/cmake, removed with it when the source changed.
build_source() {
  local is_tree=$1 shape=$2 sum
  shift 2
  BUILD=$PREFIX/.build
  mkdir -p "$BUILD"
  if [ -d "$SRC" ]; then
    TOP=$(build_top "$is_tree" "$SRC") || die 2 "'$SRC' is not $PROGRAM's source: $shape"
    STAMP="dir:$TOP"
  else
    sum=$(sha256sum -- "$SRC" | cut -d' ' -f1) || die 2 "cannot read '$SRC'"
    STAMP="tar:$sum"
    if [ "$(cat "$BUILD/source.stamp" 2>/dev/null)" = "$STAMP" ] && TOP=$(build_top "$is_tree" "$BUILD/src"); then
      say "source already unpacked ($BUILD/src)"
    else
      rm -rf "$BUILD/src.new" && mkdir -p "$BUILD/src.new"
      # the tarball is anyone's: as root, tar would keep its owners (any uid) and its modes (setuid
      # bits); the files are ours, with the umask's permissions
      tar --no-same-owner --no-same-permissions -xf "$SRC" -C "$BUILD/src.new" 2>"$BUILD/tar.log" \
        || { rm -rf "$BUILD/src.new"; die 2 "'$SRC' is not a readable tarball ($(head -c 300 "$BUILD/tar.log" | tr '\n' ' '))"; }
      build_top "$is_tree" "$BUILD/src.new" >/dev/null || { rm -rf "$BUILD/src.new"; die 2 "'$SRC' does not hold $PROGRAM's source: $shape"; }
      # a new source: start the build from scratch so nothing of an older tree survives
      rm -rf "$BUILD/src" "$BUILD/cmake" "$BUILD/source.stamp"
      mv "$BUILD/src.new" "$BUILD/src"
      TOP=$(build_top "$is_tree" "$BUILD/src")
    fi
  fi
  if [ "$(cat "$BUILD/source.stamp" 2>/dev/null)" != "$STAMP" ]; then rm -rf "$BUILD/cmake" "$@"; fi
}

# build_install_packages TOOL...: the Debian packages PACKAGES, installed as root (apt-get) or named
# and exit 3; not a Debian system: the TOOLs must be on PATH (exit 3 naming the first missing)
build_install_packages() {
  local p missing="" tool
  if command -v dpkg-query >/dev/null; then
    for p in $PACKAGES; do
      dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
    done
    missing=${missing# }
    if [ -n "$missing" ]; then
      if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        say "installing Debian packages: $missing"
        # shellcheck disable=SC2086
        apt-get install -y -qq --no-install-recommends $missing >/dev/null 2>&1 \
          || { apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq --no-install-recommends $missing >/dev/null; } \
          || die 3 "apt-get could not install: $missing"
      else
        die 3 "$PROGRAM needs these Debian packages; install them as root, then rerun:
  apt-get install $missing"
      fi
    fi
  else
    for tool in "$@"; do
      command -v "$tool" >/dev/null || die 3 "not a Debian system and '$tool' is missing; $PROGRAM needs: $PACKAGES (or your system's equivalents)"
    done
  fi
}

# build_configure CMAKE_OPTION...: configures TOP into PREFIX/.build/cmake (Ninja, Release) unless
# it is configured already (exit 4 on failure, with the log's tail); then stamps the source
build_configure() {
  if [ ! -f "$BUILD/cmake/build.ninja" ]; then
    say "configuring $TOP"
    cmake -S "$TOP" -B "$BUILD/cmake" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" \
      >"$BUILD/configure.log" 2>&1 || { tail -n 30 "$BUILD/configure.log" >&2; die 4 "cmake failed (log: $BUILD/configure.log)"; }
  fi
  echo "$STAMP" >"$BUILD/source.stamp"
}

# build_ninja STEP WHAT NINJA_ARGUMENT...: ninja in PREFIX/.build/cmake, its output in
# PREFIX/.build/STEP.log; failed: the log's tail and exit 4, "WHAT failed" ("ninja install failed")
build_ninja() {
  local step=$1 what=$2
  shift 2
  ninja -C "$BUILD/cmake" "$@" >"$BUILD/$step.log" 2>&1 || { tail -n 30 "$BUILD/$step.log" >&2; die 4 "$what failed (log: $BUILD/$step.log)"; }
}

# build_env_file FILE KEY VALUE [KEY VALUE...]: writes the JSON record {KEY: VALUE, ...} to FILE
# (through FILE.tmp, so a reader never sees half of it); a KEY with a '.' nests ("env.PATH": the
# PATH entry of the object "env"). Values travel as arguments, never as code.
build_env_file() {
  python3 - "$@" <<'EOF'
import json, os, sys
path, items = sys.argv[1], sys.argv[2:]
record = {}
for key, value in zip(items[::2], items[1::2]):
    *outer, last = key.split(".")
    place = record
    for name in outer:
        place = place.setdefault(name, {})
    place[last] = value
tmp = path + ".tmp"
with open(tmp, "w") as f:
    json.dump(record, f, indent=2)
    f.write("\n")
os.replace(tmp, path)
EOF
}
