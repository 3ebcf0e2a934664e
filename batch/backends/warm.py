"""Warm worker processes of the RGB backends (Cycles, LuxCore; issue 23: no per-job import), kept idle in a
pool across jobs as the Mitsuba backend keeps its own (batch/backends/mitsuba/backend.py).

A worker is a child process (it dies with this one: child.popen_kwargs) that answers one JSON
line ``{"ready": true, ...}`` once started, then one JSON reply line per JSON request line; a
request carries ``"log": path``, the file the worker appends what it prints while serving it.
A worker that overruns a request's time limit (PassTimeout), dies (BackendFailure), or answers
``{"ok": false, "error": ...}`` (BackendFailure; with ``"timed_out": true`` PassTimeout) is killed and never returned to the pool: that
request's pass or job fails alone, and the next request gets a fresh worker. Idle workers are
closed at exit.
"""
import atexit
import json
import threading

from . import child
from .passes import BackendFailure, PassTimeout, tail


class Worker(child.KeptChild):
    """One started worker process (``cmd``, environment ``env``), named ``label`` in errors; the
    reply to its start is ``ready``. Mitsuba's workers are these too (batch/backends/mitsuba/
    backend.py), with their own replies (``exchange``)."""
    log_hint = "the log"  # where what it printed while serving a request went

    def __init__(self, key, cmd, label, timeout, env=None):
        super().__init__(cmd, env=env)
        self.key, self.label = key, label
        self.asking = None  # what the request under way is (None: idle)
        self.ready = self._reply(timeout, "starting")

    @property
    def pid(self):
        return self.proc.pid if self.proc is not None else None

    def exchange(self, request, timeout, what):
        """Send ``request`` and return its reply (any JSON) within ``timeout`` seconds; a worker
        that overruns (PassTimeout), dies or cannot be written to (BackendFailure) is killed."""
        self.asking = what
        try:
            try:
                self.proc.stdin.write((json.dumps(request) + "\n").encode())
                self.proc.stdin.flush()
            except (OSError, AttributeError) as exc:
                self.kill()
                raise BackendFailure(f"{self.label} worker stopped before {what}: {exc}") from exc
            return self._reply(timeout, what)
        finally:
            self.asking = None

    def ask(self, request, timeout, what):
        """``exchange``, where the reply says ``ok`` (batch/backends/serve_requests.py): a reply that
        is not ok fails the request too (``timed_out``: PassTimeout), and the worker is killed."""
        reply = self.exchange(request, timeout, what)
        try:
            if reply.get("timed_out"):  # the worker stopped itself at the request's own limit
                raise PassTimeout(f"{self.label} worker: {what}: {reply.get('error', 'timed out')}")
            if not reply.get("ok"):
                raise BackendFailure(f"{self.label} worker failed {what}: {reply.get('error', reply)}")
        except BackendFailure:
            self.kill()
            raise
        return reply

    def _reply(self, timeout, what):
        line = self.read_line(timeout)
        if line is None:
            self.kill()
            raise PassTimeout(f"{self.label} worker: {what} took longer than {timeout} s")
        if not line:
            code = self.proc.wait()
            early = self.early_output()
            self.kill()
            raise BackendFailure(f"{self.label} worker exited with {code} while {what}"
                                 + (f": {tail(early)}" if early.strip() else f" (its output is in {self.log_hint})"))
        try:
            return json.loads(line)
        except ValueError as exc:
            self.kill()
            raise BackendFailure(f"{self.label} worker answered {line[:200]!r} while {what}") from exc


_POOL = {}  # key -> idle Worker (a local run renders one job at a time)
_BUSY = {}  # id -> Worker taken from the pool or started, not yet given back (tests kill these)
_LOCK = threading.Lock()


def take(key, cmd, label, timeout):
    """The idle worker of ``key`` if it is alive, else a new one (``cmd``)."""
    with _LOCK:
        worker = _POOL.pop(key, None)
    if worker is not None and not worker.alive():
        worker.kill()
        worker = None
    if worker is None:
        worker = Worker(key, cmd, label, timeout)
    with _LOCK:
        _BUSY[id(worker)] = worker
    return worker


def give(worker):
    """Keep ``worker`` idle for the next request of its key (if it is alive; one per key)."""
    with _LOCK:
        _BUSY.pop(id(worker), None)
        if not worker.alive():
            old = None
        else:
            old = _POOL.pop(worker.key, None)
            _POOL[worker.key] = worker
    if old is not None:
        old.close()


def drop(worker):
    """Kill ``worker`` (a failed one) and forget it."""
    with _LOCK:
        _BUSY.pop(id(worker), None)
    worker.kill()


def busy():
    """The workers taken now (a copy)."""
    with _LOCK:
        return list(_BUSY.values())


def idle(key):
    """The idle worker of ``key`` in the pool, or None."""
    with _LOCK:
        return _POOL.get(key)


def call(key, cmd, label, request, timeout, what):
    """One request on a warm worker of ``key``: taken, asked, given back (killed on failure)."""
    worker = take(key, cmd, label, timeout)
    try:
        reply = worker.ask(request, timeout, what)
    except BaseException:
        drop(worker)
        raise
    give(worker)
    return reply


@atexit.register
def close_pool():
    """Stop the idle workers, all told at once, then waited for (they also die with this process)."""
    with _LOCK:
        workers = list(_POOL.values())
        _POOL.clear()
    for w in workers:
        try:
            w.proc.stdin.close()
        except (OSError, AttributeError):
            pass
    for w in workers:
        w.close()
