"""What this machine has for the tests that need more than Python: ART, pbrt-v4 and Chromium,
found as the runner finds them, and the markers that skip a test without them (each skip names
what builds or installs the missing tool). Shared by every room that renders with ART or pbrt or
looks at the report in a browser."""
import os
import shutil
import subprocess

import pytest

from spectral_bench.batch.backends.art import backend as art_backend
from spectral_bench.batch.backends.pbrt import backend as pbrt_backend

# ART as the runner finds it (.art/env.json, PATH), or ART_ARTIST (then named to the runner with -e)
ARTIST = os.environ.get("ART_ARTIST") or (str(art_backend.find_artist()) if art_backend.find_artist() else None)
ART_EXEC = ["-e", f"art={ARTIST}"] if os.environ.get("ART_ARTIST") else []  # else the runner finds it itself
needs_artist = pytest.mark.skipif(not ARTIST, reason=(
    "no ART: no .art/env.json (scripts/build_art.sh SRC builds ART from its source; .ci/run does when "
    "../shared/art/ holds it), no artist on PATH, no ART_ARTIST: ART renders not run"))

# pbrt-v4 as the runner finds it (.pbrt/env.json, SPECTRAL_BENCH_PBRT_ENV, PATH)
PBRT = pbrt_backend.find_pbrt()
needs_pbrt = pytest.mark.skipif(not PBRT, reason=(
    f"no pbrt-v4: no {pbrt_backend.ENV_FILE} (scripts/build_pbrt.sh SRC builds pbrt from its source; .ci/run does "
    "when ../shared/pbrt/ holds it) and no pbrt on PATH: pbrt renders not run"))

# headless Chromium for the report (scripts/setup.sh installs it as root)
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
NO_CHROMIUM = "no chromium: report not checked in a browser (scripts/setup.sh installs it as root)"
needs_chromium = pytest.mark.skipif(not CHROMIUM, reason=NO_CHROMIUM)


def chromium(*args, timeout=120):
    """Headless Chromium on ``args`` in a 1400 x 1000 window, 30 s of virtual time; its stdout."""
    proc = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=30000",
                           "--window-size=1400,1000", *args], capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-1000:]
    return proc.stdout


def dump_dom(url):
    """The page at ``url`` as headless Chromium leaves it after 5 s of virtual time (--dump-dom)."""
    proc = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000",
                           "--dump-dom", url], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-1000:]
    return proc.stdout
