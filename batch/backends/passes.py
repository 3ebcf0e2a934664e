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
    record.update({"variant": mode, "spp": int(round(sum(taken))), "passes": passes, "seed": seed,
                   "time_s": sum(times), "wall_s": acc.wall_s, "pass_times": list(times),
                   "resolution": [int(shape[1]), int(shape[0])], "channels": names})
    if any(t != per_pass for t in taken):
        record.update(spp_asked=per_pass * passes, samples_per_pixel_per_pass=[round(float(t), 3) for t in taken])
    if retried:
        record["retried"] = list(retried)
    return record


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


def run_command(cmd, timeout, log, what, env=None, cwd=None):
    """Run one child process (dies with this one) under ``timeout`` seconds, its command line and
    output appended to ``log``; returns its wall seconds. PassTimeout past the limit,
    BackendFailure on a non-zero exit (with the tail of its output) or a program not found."""
    import subprocess
    from . import child
    t0 = time.perf_counter()
    log.write(f"$ {' '.join(map(str, cmd))}{f'   (in {cwd})' if cwd else ''}\n")
    log.flush()
    try:
        proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, errors="replace", timeout=timeout,
                              env=env, cwd=cwd, stdin=subprocess.DEVNULL, **child.popen_kwargs())
    except subprocess.TimeoutExpired as exc:
        log.write(f"(timed out after {timeout} s)\n{_text(exc.stdout)}\n{_text(exc.stderr)}\n")
        raise PassTimeout(f"{what} timed out after {timeout} s") from exc
    except OSError as exc:
        raise BackendFailure(f"{what} could not start: {exc.strerror or exc}: {cmd[0]}") from exc
    log.write(f"{proc.stdout}\n{proc.stderr}\n")
    log.flush()
    if proc.returncode != 0:
        raise BackendFailure(f"{what} exited with {proc.returncode}: {tail(proc.stderr) or tail(proc.stdout)}")
    return time.perf_counter() - t0


def _text(data):
    return data.decode(errors="replace") if isinstance(data, bytes) else (data or "")
