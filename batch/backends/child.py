"""Child processes of a render die with the process that started them (Linux: PR_SET_PDEATHSIG),
so a killed runner or Dask worker leaves no orphaned render writing into a job's folder while the
job is retried elsewhere."""
import ctypes
import selectors
import signal
import subprocess
import sys
import tempfile


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


class KeptChild:
    """A child kept warm across requests (Mitsuba's, Cycles' and LuxCore's render workers, the FLIP
    child): started with ``popen_kwargs`` (it dies with this process), stdin and stdout piped for
    requests and replies, what it prints outside them kept in a temporary file (``early_output``)."""

    def __init__(self, cmd, env=None):
        self.stderr = tempfile.TemporaryFile()
        self.proc = subprocess.Popen([str(c) for c in cmd], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self.stderr, env=env, **popen_kwargs())

    def alive(self):
        return self.proc is not None and self.proc.poll() is None

    def read_line(self, timeout):
        """Its next line of output within ``timeout`` seconds: bytes (b"" once it has exited), or
        None when it wrote nothing in time (the caller kills it)."""
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        ready = sel.select(timeout)
        sel.close()
        return self.proc.stdout.readline() if ready else None

    def early_output(self):
        """What it printed to stderr outside requests, as text."""
        self.stderr.seek(0)
        return self.stderr.read().decode(errors="replace")

    def kill(self):
        kill(self.proc)
        self.proc = None

    def close(self):
        close(self.proc)
        self.proc = None
