"""Find a libLLVM that Dr.Jit's LLVM backend accepts, once per process.

Mitsuba's llvm_ad_* variants JIT-compile through libLLVM. Measured here (../shared/notes):
Debian's libllvm19 works; LLVM 14 and 16 crash Dr.Jit; llvmlite's copy does not work. The
probe renders a tiny scene in a child process, so a crash cannot take the runner down.
"""
import functools
import glob
import os
import subprocess
import sys
import threading
from functools import lru_cache

CANDIDATES = ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", "/usr/lib/llvm-19/lib/libLLVM.so",
              "/usr/lib/x86_64-linux-gnu/libLLVM-20.so", "/usr/lib/llvm-20/lib/libLLVM.so",
              "/usr/lib/x86_64-linux-gnu/libLLVM-18.so", "/usr/lib/llvm-18/lib/libLLVM.so",
              "/usr/lib/aarch64-linux-gnu/libLLVM-19.so", "/opt/homebrew/opt/llvm/lib/libLLVM.dylib")

_PROBE = ("import mitsuba as mi; mi.set_variant('llvm_ad_rgb'); "
          "s = mi.load_dict(mi.cornell_box()); mi.render(s, spp=1); print('ok')")


def candidates():
    found = [os.environ["DRJIT_LIBLLVM_PATH"]] if os.environ.get("DRJIT_LIBLLVM_PATH") else []
    found += [c for c in CANDIDATES if os.path.exists(c)]
    found += sorted(glob.glob("/usr/lib/*/libLLVM-1[89].so"))
    return list(dict.fromkeys(found))


def probed_once(fn):
    """``fn()`` computed once per process (functools.lru_cache); a second thread asking meanwhile
    (runner.probe_early probes from a thread while the scenes load) waits for the first.
    ``.cache_clear()`` lets tests probe again."""
    cached, lock = lru_cache(maxsize=1)(fn), threading.Lock()

    @functools.wraps(fn)
    def once():
        with lock:
            return cached()
    once.cache_clear = cached.cache_clear
    return once


@probed_once
def find():
    """(path or None, message). The path works for llvm_ad_* variants in a child process."""
    tried = []
    for path in candidates():
        env = dict(os.environ, DRJIT_LIBLLVM_PATH=path)
        try:
            proc = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=120)
        except subprocess.TimeoutExpired:
            tried.append(f"{path}: probe timed out")
            continue
        if proc.returncode == 0 and proc.stdout.strip().endswith("ok"):
            return path, f"LLVM variants use {path}"
        tried.append(f"{path}: {(proc.stderr.strip().splitlines() or ['exit %d' % proc.returncode])[-1][:200]}")
    why = "; ".join(tried) if tried else "no libLLVM 18-20 found (Debian: apt-get install libllvm19)"
    return None, f"LLVM variants unavailable ({why}); falling back to the scalar variants"


def env():
    """Environment for a child process that renders with Mitsuba."""
    path, _ = find()
    return dict(os.environ, DRJIT_LIBLLVM_PATH=path) if path else dict(os.environ)
