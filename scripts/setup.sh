#!/usr/bin/env bash
# Set up everything the project needs on a fresh Debian machine (idempotent):
#   - a virtual environment .venv with the pinned packages of requirements.txt
#   - Debian's libllvm19, the LLVM library Mitsuba's llvm_ad_* variants need (root only;
#     without it the runner says so once and falls back to the scalar variants)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
if ! ls /usr/lib/*/libLLVM-19.so >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing libllvm19 (Debian) for Mitsuba's LLVM variants" >&2
    (apt-get install -y -qq libllvm19 >/dev/null 2>&1 || { apt-get update -qq >/dev/null && apt-get install -y -qq libllvm19 >/dev/null; }) \
      || echo "setup: could not install libllvm19; Mitsuba will use its scalar variants" >&2
  else
    echo "setup: libLLVM-19 not found and not root; Mitsuba will use its scalar variants" >&2
  fi
fi
# headless Chromium checks the HTML report in the tests (tests/report/test_report.py skips visibly without it)
if ! command -v chromium >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "setup: installing chromium (Debian) for the report test" >&2
  (apt-get install -y -qq chromium >/dev/null 2>&1 || { apt-get update -qq >/dev/null && apt-get install -y -qq chromium >/dev/null; }) \
    || echo "setup: could not install chromium; the report test will be skipped" >&2
fi
[ -x .venv/bin/python ] || "$PY" -m venv .venv
if ! .venv/bin/python -m pip install -q --disable-pip-version-check -r requirements.txt; then
  echo "setup: pip install failed" >&2
  exit 1
fi
