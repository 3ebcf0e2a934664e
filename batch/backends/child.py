"""Child processes of a render die with the process that started them (Linux: PR_SET_PDEATHSIG),
so a killed runner or Dask worker leaves no orphaned render writing into a job's folder while the
job is retried elsewhere."""
import ctypes
import signal
import subprocess
import sys


def _die_with_parent():
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG = 1
    except OSError:
        pass


def popen_kwargs():
    """Keyword arguments for subprocess.run/Popen of a render child."""
    return {"preexec_fn": _die_with_parent} if sys.platform.startswith("linux") else {}


def kill(proc):
    """End a kept child at once and reap it (nothing when it is None)."""
    if proc is not None:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def close(proc, wait_s=10):
    """Ask a kept child to finish (its stdin closed), wait up to ``wait_s``, then ``kill`` it."""
    if proc is not None:
        try:
            proc.stdin.close()
            proc.wait(timeout=wait_s)
        except (OSError, subprocess.TimeoutExpired):
            pass
        kill(proc)
