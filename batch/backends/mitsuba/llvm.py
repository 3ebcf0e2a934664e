"""Find a libLLVM that Dr.Jit's LLVM backend accepts, once per process tree.

Mitsuba's llvm_ad_* variants JIT-compile through libLLVM. Measured here (../shared/notes):
Debian's libllvm19 works; LLVM 14 and 16 crash Dr.Jit; llvmlite's copy does not work. The
probe renders a tiny scene in a child process, so a crash cannot take the runner down.

The answer is handed down to this process's children through the environment (``INHERITED``):
a child asking the same question with the same inputs (the interpreter, the candidate libraries
in order, for CUDA also its test hook and the LLVM found) takes the parent's answer instead of
probing again. The probe costs about 0.7 s of CPU (this one 0.5, cuda.py's 0.2: two Python
children importing Mitsuba); a test session or a benchmark starts hundreds of runners, each of
which would otherwise probe anew. Changed inputs (another DRJIT_LIBLLVM_PATH, another
interpreter) probe again; an unreadable or malformed value is ignored.
"""
import functools
import glob
import json
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


INHERITED = "SPECTRAL_BENCH_MITSUBA_PROBED"  # JSON {kind: [key, answer]}: what a parent process probed
_ENV_LOCK = threading.Lock()


def inherited(kind, key):
    """The answer (a pair) a parent process handed down for ``kind`` probed with ``key``, or None."""
    try:
        got = json.loads(os.environ.get(INHERITED) or "{}").get(kind)
    except (ValueError, AttributeError):
        return None
    if not (isinstance(got, list) and len(got) == 2 and got[0] == key):
        return None
    answer = got[1]
    if (isinstance(answer, list) and len(answer) == 2 and isinstance(answer[1], str)
            and (answer[0] is None or isinstance(answer[0], (bool, str)))):
        return tuple(answer)
    return None


def hand_down(kind, key, answer):
    """Put ``answer`` for ``kind`` into this process's environment, which its children inherit."""
    with _ENV_LOCK:
        try:
            data = json.loads(os.environ.get(INHERITED) or "{}")
        except ValueError:
            data = {}
        if not isinstance(data, dict):
            data = {}
        data[kind] = [key, list(answer)]
        os.environ[INHERITED] = json.dumps(data)


def probed_once(kind, key):
    """``fn()`` computed once per process tree: the answer a parent handed down for ``kind`` with
    the same ``key()`` (module docstring), else probed here (functools.lru_cache) and handed down
    to the children. A second thread asking meanwhile (runner.probe_early probes from a thread
    while the scenes load) waits for the first. ``.cache_clear()`` lets tests probe again (a
    handed-down answer with the same key still stands)."""
    def wrap(fn):
        @lru_cache(maxsize=1)
        def cached():
            k = key()
            answer = inherited(kind, k)
            if answer is None:
                answer = tuple(fn())
                hand_down(kind, k, answer)
            return answer
        lock = threading.Lock()

        @functools.wraps(fn)
        def once():
            with lock:
                return cached()
        once.cache_clear = cached.cache_clear
        return once
    return wrap


@probed_once("llvm", lambda: [sys.executable, candidates()])
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
