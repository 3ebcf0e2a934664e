"""The request loop of a warm worker process (batch/backends/warm.py keeps them idle across jobs;
the Cycles and LuxCore workers serve through it). Standalone: it imports nothing of the project,
so a worker that must control its own imports (LuxCore's: pyluxcore before anything that loads
OpenEXR) loads it by file path.

Protocol: once ``start()`` has imported what the worker needs, one JSON line ``{"ready": true,
...what start returned, "start_s": seconds}``; then every JSON request line on stdin names one
of the handlers' kinds, ``{KIND: body, "log": path}``, and is answered by one JSON line on the
original stdout: ``{"ok": true, "result": handler(body)}``, ``{"ok": false, "timed_out": true,
"error": ...}`` when the handler raised one of ``timed_out``, or ``{"ok": false, "error": ...}``.
What is printed during a request (Python, or C code writing to fds 1 and 2) goes to that
request's log, between requests to stderr. Ends when stdin closes."""
import ctypes
import json
import os
import sys
import time
import traceback


def redirect(target):
    """Point fds 1 and 2 at ``target`` (a path, appended to, or an open fd), after flushing what
    Python and C stdio still hold for the previous target."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        ctypes.CDLL(None).fflush(None)  # C stdio buffers (a renderer's printf) go to the old target
    except (OSError, AttributeError, TypeError):  # no C library to flush by that name (not Linux/macOS)
        pass
    fd = target if isinstance(target, int) else os.open(target, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    if fd != target:
        os.close(fd)


def serve(start, handlers, timed_out=()):
    """Run the loop (module docstring): ``start()`` -> dict for the ready line; ``handlers``:
    {kind: function of the request's body -> JSON-able result}; ``timed_out``: the exception
    classes that mean the request's own time limit passed."""
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    own_err = os.dup(2)
    os.dup2(2, 1)  # whatever else prints goes to stderr, never into the replies
    t0 = time.perf_counter()
    info = start()
    reply.write(json.dumps({"ready": True, **info, "start_s": time.perf_counter() - t0}) + "\n")
    for line in sys.stdin:
        if not line.strip():
            continue
        req = json.loads(line)
        kind = next((k for k in handlers if k in req), None)
        redirect(req.get("log") or os.devnull)
        try:
            if kind is None:
                raise ValueError(f"a request names none of {', '.join(handlers)}: {sorted(req)}")
            out = {"ok": True, "result": handlers[kind](req[kind])}
        except timed_out as exc:
            out = {"ok": False, "timed_out": True, "error": str(exc)}
        except Exception as exc:  # noqa: BLE001 - reported to the backend, which fails that pass or job
            traceback.print_exc()
            out = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        redirect(own_err)
        reply.write(json.dumps(out) + "\n")
