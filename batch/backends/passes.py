"""The one pass loop every backend renders through (built-in and declared renderers alike).

A backend only knows how to render *one pass*: ``backend.session(path, mode, log)`` opens a
session (a context manager; for most backends nothing more than the exported file, for the
Mitsuba Python route a warm child process that has loaded the scene and compiled its kernels
once) and ``session.render_pass(spp, seed, out_exr, timeout)`` renders one pass with one seed in
a child process under a time limit and returns::

    {"names": [channel, ...], "image": H x W x C array, "time_s": render seconds,
     "info": {anything the backend reports once: versions, chunks_per_pass, approximated, ...}}

This module does the rest, once for every backend: pass k renders ``ceil(spp / passes)`` samples
per pixel with seed ``seed + k * SEED_STRIDE`` (a backend splitting a pass into chunks uses the
seeds up to the next stride); a pass that fails is retried once with the same seed (a time-out is
not retried: it would time out again), and a second failure fails the render with that pass's
error and the tail of its output; every pass must have the same channels and size; the mean and
the standard error of the mean per pixel (the pass-to-pass spread, Welford's online update:
B. P. Welford, Technometrics 4(3), 1962) are written as the render's EXR (R, G, B, further channels,
then ``stderr.<channel>`` with two or more passes; half floats as batch/exr.py ``stored_render``
rounds them), and the render record lists each pass's time.

``accumulation`` (an Accumulation, issue 20 ``--detect``): passes are added to those already
rendered into it (its Welford sums), so a render continued to more passes renders no pass twice:
pass k keeps seed ``seed + k * SEED_STRIDE`` and the samples per pixel of the first call.
"""
import math
import os
import re
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import exr

SEED_STRIDE = 1000  # pass k seeds from seed + k * SEED_STRIDE (chunks of a pass: the seeds below the next)


class BackendFailure(RuntimeError):
    """A render (or one pass of it) that failed; the message says why, with the renderer's output tail."""


class PassTimeout(BackendFailure):
    """A pass that ran past its time limit (not retried)."""


class PassStopped(BackendFailure):
    """A pass ended because the run was interrupted (``stop_all``; not retried)."""


# terminal control: escape sequences (ART colours its errors even without a terminal) and other
# control characters, which a reason (metrics.json, summary.md, the report) must not carry
TERMINAL_CONTROL = re.compile(r"\x1b\[[0-?]*[ -/]*[@-~]|\x1b[@-_]|[\x00-\x08\x0b-\x1f\x7f]")


def tail(text, lines=3, chars=600):
    """The last lines of a renderer's output that say something (errors first), for a reason."""
    all_lines = [l for l in TERMINAL_CONTROL.sub("", (text or "").replace("\r", "\n")).strip().splitlines() if l.strip()]
    errors = [l for l in all_lines if "error" in l.lower() or "exception" in l.lower()][-lines:]
    return " | ".join(errors or all_lines[-lines:])[-chars:]


@dataclass
class Accumulation:
    """The passes rendered so far (plain data): samples per pixel per pass, Welford's running mean
    and sum of squared deviations per pixel, and each pass's record."""
    per_pass: int
    count: int = 0
    names: list = None
    shape: tuple = None
    mean: np.ndarray = field(default=None, repr=False)
    m2: np.ndarray = field(default=None, repr=False)
    info: dict = field(default_factory=dict)
    # a spectral renderer's S0 bands, accumulated like the image (its own Accumulation), and what
    # they are (wavelengths, band model: batch/spectral_exr.py pass_bands without the cube)
    spectral: "Accumulation" = field(default=None, repr=False)
    bands: dict = None
    times: list = field(default_factory=list)
    taken: list = field(default_factory=list)
    retried: list = field(default_factory=list)
    wall_s: float = 0.0

    def add(self, img):
        """One more pass's image into the running mean and sum of squared deviations (Welford 1962)."""
        if self.mean is None:
            self.shape, self.mean, self.m2 = img.shape, np.zeros(img.shape), np.zeros(img.shape)
        self.count += 1
        delta = img - self.mean
        self.mean += delta / self.count
        self.m2 += delta * (img - self.mean)

    def var_of_mean(self):
        """Per pixel: the variance of the mean estimated from the passes' spread (two or more passes)."""
        return self.m2 / (self.count - 1) / self.count


def render(backend, path, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None, accumulation=None):
    """Render ``spp`` samples per pixel in ``passes`` independent passes of ``backend`` and write
    their mean (and standard error) to ``out_exr``; returns the render record (variant, spp,
    passes, seed, time_s: the passes' render time, wall_s, resolution, channels, versions,
    pass_times, retried). Raises BackendFailure naming the pass that failed twice.
    ``accumulation``: continue it up to ``passes`` passes in all (module docstring); its
    ``per_pass`` samples per pixel are kept, ``spp`` is then unused."""
    passes = max(1, int(passes))
    acc = accumulation if accumulation is not None else Accumulation(per_pass=math.ceil(spp / passes))
    per_pass = acc.per_pass
    out_exr = Path(out_exr)
    work = out_exr.parent / f".{out_exr.stem}.passes"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    t0 = time.perf_counter()
    times, taken, retried, info = acc.times, acc.taken, acc.retried, acc.info
    if log_path and acc.count == 0:
        Path(log_path).write_text("")  # this render's log; children append to it (a warm worker too)
    with open(log_path or os.devnull, "a", encoding="utf-8") as log:
        with backend.session(path, mode, log) as session:
            for k in range(acc.count, passes):
                s = seed + k * SEED_STRIDE
                result = _one_pass(session, k, passes, per_pass, s, work / f"pass{k}.exr", timeout, log, retried)
                img = np.asarray(result["image"], dtype=np.float64)
                if acc.names is None:
                    acc.names = list(result["names"])
                    info.update(result.get("info") or {})
                elif list(result["names"]) != acc.names or img.shape != acc.shape:
                    raise BackendFailure(f"pass {k + 1}/{passes} (seed {s}) wrote channels {result['names']} of "
                                         f"shape {img.shape}, the first pass {acc.names} of shape {acc.shape}")
                acc.add(img)
                _add_bands(acc, result.get("spectral"), k, passes, s)
                times.append(float(result["time_s"]))
                taken.append(result.get("spp", per_pass))  # a renderer may take other than it was asked
    shutil.rmtree(work, ignore_errors=True)
    acc.wall_s += time.perf_counter() - t0
    names, shape, mean, passes = acc.names, acc.shape, acc.mean, acc.count
    extra = {}
    # issue 21: mean and standard error stored as half floats, the mean rounded stochastically with
    # its rounding variance in the standard error (batch/exr.py stored_render): a run folder of a
    # reasonable size, every reader judging an unbiased mean with its whole uncertainty
    mean, stderr = exr.stored_render(mean, np.sqrt(acc.var_of_mean()) if passes > 1 else None, seed)
    if stderr is not None:
        extra = {f"stderr.{n}": stderr[..., i] for i, n in enumerate(names)}
    exr.write_image(out_exr, names, mean, extra)
    record = dict(info)
    if acc.spectral is not None:
        from .. import spectral_passes
        record["spectral"] = spectral_passes.write(out_exr.parent, acc.bands, acc.spectral.mean,
                                                   acc.spectral.var_of_mean() if acc.spectral.count > 1 else None)
    record.update({"variant": mode, "spp": int(round(sum(taken))), "passes": passes, "seed": seed,
                   "time_s": sum(times), "wall_s": acc.wall_s, "pass_times": list(times),
                   "resolution": [int(shape[1]), int(shape[0])], "channels": names})
    if any(t != per_pass for t in taken):
        record.update(spp_asked=per_pass * passes, samples_per_pixel_per_pass=[round(float(t), 3) for t in taken])
    if retried:
        record["retried"] = list(retried)
    return record


def _add_bands(acc, spectral, k, passes, seed):
    """One pass's spectral bands (or None) into the accumulation; every pass must bring the same."""
    if spectral is None:
        if acc.spectral is not None:
            raise BackendFailure(f"pass {k + 1}/{passes} (seed {seed}) wrote no spectral bands; the first pass did")
        return
    cube = np.asarray(spectral["cube"], dtype=np.float64)
    meta = {key: v for key, v in spectral.items() if key != "cube"}
    if acc.spectral is None:
        if acc.count > 1:
            raise BackendFailure(f"pass {k + 1}/{passes} (seed {seed}) wrote spectral bands; the first pass did not")
        acc.spectral, acc.bands = Accumulation(per_pass=acc.per_pass), meta
    elif meta != acc.bands or cube.shape != acc.spectral.shape:
        raise BackendFailure(f"pass {k + 1}/{passes} (seed {seed}) wrote other spectral bands than the first pass")
    acc.spectral.add(cube)


def _one_pass(session, k, passes, spp, seed, out, timeout, log, retried):
    """One pass, retried once after a failure (not after a time-out)."""
    what = f"pass {k + 1}/{passes} (seed {seed})"
    for attempt in (1, 2):
        try:
            result = session.render_pass(spp, seed, out, timeout)
            _check(result, what)
            return result
        except PassTimeout as exc:
            raise BackendFailure(f"{what} timed out: {exc}") from exc
        except PassStopped:
            raise
        except BackendFailure as exc:
            log.write(f"\n# {what} failed (attempt {attempt}): {exc}\n")
            log.flush()
            if attempt == 2:
                raise BackendFailure(f"{what} failed twice: {exc}") from exc
            retried.append({"pass": k, "seed": seed, "error": str(exc)[:600]})


def _check(result, what):
    """A pass's image: finite, H x W x C with as many channel names, R, G, B among them."""
    img = np.asarray(result["image"])
    names = list(result["names"])
    if img.ndim != 3 or img.shape[-1] != len(names):
        raise BackendFailure(f"{what}: an image of shape {img.shape} for channels {names}")
    missing = [c for c in "RGB" if c not in names]
    if missing:
        raise BackendFailure(f"{what}: no channel {', '.join(missing)} (wrote {names})")
    bad = int(np.count_nonzero(~np.isfinite(img)))
    if bad:
        raise BackendFailure(f"{what}: {bad} values are NaN or infinite")


class OneProcessPerPass:
    """A session whose every pass is one run of a child process (ART, Cycles, LuxCore, declared
    renderers, the mitsuba executable): the backend gives ``run_pass(spp, seed, out, timeout,
    log) -> result``; there is nothing to start or stop."""

    def __init__(self, run_pass, log, info=None):
        self._run_pass, self.log, self.info = run_pass, log, info or {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def render_pass(self, spp, seed, out, timeout):
        result = self._run_pass(spp, seed, out, timeout, self.log)
        result.setdefault("info", {})
        for key, value in self.info.items():
            result["info"].setdefault(key, value)
        return result


# A pass's child process: its output is kept up to OUTPUT_HEAD bytes from the start and OUTPUT_TAIL
# from the end (the rest counted, said in render.log); after it exits, what its children still write
# to its pipes is read for DRAIN_S at most (nothing for DRAIN_IDLE_S ends it sooner); its process
# group is then asked to stop (SIGTERM) and killed (SIGKILL) after STOP_GRACE_S.
OUTPUT_HEAD = OUTPUT_TAIL = 64 * 1024
DRAIN_S, DRAIN_IDLE_S, STOP_GRACE_S = 5.0, 0.5, 2.0


class CappedOutput:
    """What a child wrote to one pipe, in bounded memory: the first ``head`` and the last ``tail``
    bytes, and how many bytes between them were dropped."""

    def __init__(self, head=OUTPUT_HEAD, tail=OUTPUT_TAIL):
        self.head_max, self.tail_max = head, tail
        self.head, self.tail, self.dropped = bytearray(), bytearray(), 0

    def add(self, data):
        room = self.head_max - len(self.head)
        if room > 0:
            self.head += data[:room]
            data = data[room:]
        self.tail += data
        over = len(self.tail) - self.tail_max
        if over > 0:
            del self.tail[:over]
            self.dropped += over

    def text(self):
        middle = (f"\n[... {self.dropped} bytes of output dropped: the first {self.head_max} and the last "
                  f"{self.tail_max} bytes are kept ...]\n") if self.dropped else ""
        return self.head.decode(errors="replace") + middle + self.tail.decode(errors="replace")


_RUNNING, _STOPPED = set(), set()  # the pass processes under way; those stop_all ended (on Ctrl-C)


def stop_all():
    """Kill the process group of every pass under way (the runner was interrupted: a pass in its own
    session does not get the terminal's SIGINT, and the thread waiting on it would wait on)."""
    import signal
    for proc in list(_RUNNING):
        _STOPPED.add(proc)
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def _group_alive(pgid):
    """True while a process of group ``pgid`` other than a zombie is left (read from /proc)."""
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat", "rb") as f:
                stat = f.read()
        except OSError:
            continue
        fields = stat[stat.rindex(b")") + 2:].split()  # state, ppid, pgrp, ... after "(comm)"
        if int(fields[2]) == pgid and fields[0] != b"Z":
            return True
    return False


def stop_group(proc):
    """End the process group of ``proc`` (started with start_new_session: its group id is its pid):
    SIGTERM to every member, SIGKILL after STOP_GRACE_S to whatever is left; ``proc`` is reaped."""
    import signal
    import subprocess
    if not hasattr(os, "killpg"):  # Windows: no process groups; the child alone
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        return
    pgid = proc.pid
    try:
        os.killpg(pgid, signal.SIGTERM)
    except (ProcessLookupError, PermissionError):
        pass
    deadline = time.monotonic() + STOP_GRACE_S
    try:
        proc.wait(timeout=STOP_GRACE_S)
    except subprocess.TimeoutExpired:
        pass
    while time.monotonic() < deadline and os.path.isdir("/proc") and _group_alive(pgid):
        time.sleep(0.02)
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()


def _collect_threads(proc, timeout):
    """``_collect`` where pipes cannot be selected (Windows): a reader thread per pipe, the same
    bounded drain after the child's exit."""
    import subprocess
    import threading
    outs = {proc.stdout: CappedOutput(), proc.stderr: CappedOutput()}
    last_data = [time.monotonic()]

    def read(pipe):
        try:
            for data in iter(lambda: pipe.read1(1 << 16), b""):
                outs[pipe].add(data)
                last_data[0] = time.monotonic()
        except (OSError, ValueError):  # closed under it once the pass is over
            pass
    readers = [threading.Thread(target=read, args=(pipe,), daemon=True) for pipe in outs]
    for t in readers:
        t.start()
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        return outs[proc.stdout], outs[proc.stderr], False
    exited = last_data[0] = time.monotonic()
    for t in readers:
        while t.is_alive():
            now = time.monotonic()
            limit = min(exited + DRAIN_S, last_data[0] + DRAIN_IDLE_S)
            if now >= limit:
                break
            t.join(min(0.05, limit - now))
    return outs[proc.stdout], outs[proc.stderr], True


def _collect(proc, timeout):
    """Read the child's stdout and stderr (CappedOutput each) until it exits and its pipes are
    drained (DRAIN_S at most after the exit: a child of the child may hold them open) or until
    ``timeout`` seconds; returns (stdout, stderr, exited in time)."""
    import selectors
    outs = {proc.stdout: CappedOutput(), proc.stderr: CappedOutput()}
    sel = selectors.DefaultSelector()
    for pipe in outs:
        os.set_blocking(pipe.fileno(), False)
        sel.register(pipe, selectors.EVENT_READ)
    pidfd = None
    if hasattr(os, "pidfd_open"):
        try:
            pidfd = os.pidfd_open(proc.pid)
            sel.register(pidfd, selectors.EVENT_READ)
        except OSError:
            pidfd = None
    start = time.monotonic()
    exited = last_data = None
    try:
        while True:
            now = time.monotonic()
            if exited is None and proc.poll() is not None:
                exited = last_data = now
                if pidfd is not None:
                    sel.unregister(pidfd)
            open_pipes = [k for k in sel.get_map().values() if k.fileobj in outs]
            if exited is not None and (not open_pipes or now >= min(exited + DRAIN_S, last_data + DRAIN_IDLE_S)):
                break
            if exited is None and now >= start + timeout:
                break
            limit = min(exited + DRAIN_S, last_data + DRAIN_IDLE_S) if exited is not None else start + timeout
            # without a pidfd to wake on the child's exit, look at it every 50 ms
            wait = limit - now if pidfd is not None or exited is not None else min(limit - now, 0.05)
            for key, _ in sel.select(max(0.0, wait)):
                if key.fileobj is pidfd:
                    continue  # its exit: seen by poll() above
                try:
                    data = os.read(key.fileobj.fileno(), 1 << 16)
                except BlockingIOError:
                    continue
                if data:
                    outs[key.fileobj].add(data)
                    last_data = time.monotonic()
                else:
                    sel.unregister(key.fileobj)
    finally:
        sel.close()
        if pidfd is not None:
            os.close(pidfd)
    return outs[proc.stdout], outs[proc.stderr], exited is not None


COLLECT = _collect if os.name == "posix" else _collect_threads


def run_captured(cmd, timeout, env=None, cwd=None):
    """Run ``cmd`` (a list) in its own session (process group; it dies with this process) under
    ``timeout`` seconds and end its whole group once it exits or runs past the limit
    (``stop_group``): nothing it started outlives it. Returns (its exit status, or None past the
    limit; stdout and stderr as CappedOutput: bounded memory, read until its exit and a bounded
    drain, whatever its children still hold open). OSError when it cannot start; PassStopped when
    ``stop_all`` ended it."""
    import subprocess
    from . import child
    proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, cwd=cwd,
                            stdin=subprocess.DEVNULL, start_new_session=True, **child.popen_kwargs())
    _RUNNING.add(proc)
    try:
        out, err, finished = COLLECT(proc, timeout)
    finally:
        stop_group(proc)
        _RUNNING.discard(proc)
        if COLLECT is _collect:  # (a reader thread may still hold a pipe of a child's child: left to it)
            proc.stdout.close()
            proc.stderr.close()
    if proc in _STOPPED:
        _STOPPED.discard(proc)
        raise PassStopped("the run was interrupted", out, err)
    return (proc.returncode if finished else None), out, err


def run_command(cmd, timeout, log, what, env=None, cwd=None):
    """Run one child process (``run_captured``) under ``timeout`` seconds, its command line and
    output appended to ``log``; returns its wall seconds. It is judged by its own exit status.
    PassTimeout past the limit, PassStopped when the run was interrupted, BackendFailure on a
    non-zero exit (with the tail of its output) or a program not found."""
    t0 = time.perf_counter()
    log.write(f"$ {' '.join(map(str, cmd))}{f'   (in {cwd})' if cwd else ''}\n")
    log.flush()
    try:
        code, out, err = run_captured(cmd, timeout, env, cwd)
    except OSError as exc:
        raise BackendFailure(f"{what} could not start: {exc.strerror or exc}: {cmd[0]}") from exc
    except PassStopped as exc:
        log.write(f"(stopped: the run was interrupted)\n{exc.args[1].text()}\n{exc.args[2].text()}\n")
        raise PassStopped(f"{what} was stopped: the run was interrupted") from None
    if code is None:
        log.write(f"(timed out after {timeout} s)\n{out.text()}\n{err.text()}\n")
        raise PassTimeout(f"{what} timed out after {timeout} s")
    stdout, stderr = out.text(), err.text()
    log.write(f"{stdout}\n{stderr}\n")
    log.flush()
    if code != 0:
        raise BackendFailure(f"{what} exited with {code}: {tail(stderr) or tail(stdout)}")
    return time.perf_counter() - t0
