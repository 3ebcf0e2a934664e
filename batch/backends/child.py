"""Child processes of a render die with the process that started them (Linux: PR_SET_PDEATHSIG),
so a killed runner or Dask worker leaves no orphaned render writing into a job's folder while the
job is retried elsewhere."""
import ctypes
import signal
import sys


def _die_with_parent():
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG = 1
    except OSError:
        pass


def popen_kwargs():
    """Keyword arguments for subprocess.run/Popen of a render child."""
    return {"preexec_fn": _die_with_parent} if sys.platform.startswith("linux") else {}
