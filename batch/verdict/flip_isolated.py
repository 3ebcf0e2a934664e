"""HDR-FLIP (Andersson et al. 2021, "Visualizing Errors in Rendered High Dynamic Range Images",
Eurographics short papers; the flip-evaluator package), run in a warm child process.

flip_evaluator calls sys.exit on bad arguments and is native code; a child process keeps that
from ever closing the batch runner or Blender. The child is started once per process (on the
first verdict that asks for FLIP: ``prestart``) and kept warm across jobs, so a job pays neither a
Python start nor the imports (issue 23: they were about 1 s of every job's verdict). Requests go
over its stdin: one JSON line ``{"shape": [H, W], "map": "flip.exr"}`` followed by the reference
and the test image as raw H x W x 3 float32 (no temporary files); it answers one JSON line
``{"flip": mean}`` or ``{"error": "..."}`` and writes the map as half floats
(batch/previews.py ``write_flip``: one channel Y). A child that dies, exits or overruns its time limit is killed
and fails only that job's FLIP (the reason is recorded); the next job starts a fresh one. The
time limit covers the whole exchange: writing the request (a child that stops reading, e.g.
stopped by a signal, would otherwise block a request above the pipe's 64 kB for ever, and every
request queued behind it), the computation and the reply.

``start`` queues a request and returns at once (a Pending: one thread hands the requests to the
child in order, and the child computes while the verdicts run their probes and the next jobs);
``flip_images`` waits for it; inside ``deferred`` a verdict hands the waiting to its caller (the
default engine collects FLIP k in a third thread while verdict k+1 runs).

Inputs are checked first, here: finite, and negative values (out-of-gamut linear RGB) clamped
to 0, since FLIP requires non-negative input.

    python batch/verdict/flip_isolated.py --serve         (the child; started by FlipWorker)
"""
import atexit
import contextlib
import concurrent.futures as cf
import json
import os
import queue
import selectors
import sys
import threading
import time
from pathlib import Path

import numpy as np

DEFAULT_TIMEOUT = 600
# flip-evaluator parallelises with OpenMP over every core: beside a render that uses every core
# too, on a busy machine its threads spin at barriers (measured on 2 cores at load 8: 5 FLIPs of
# 128x128 took 2.7 s with 2 threads, 0.6 s with 1). One thread, waiting passively: the mean is
# the same (measured: identical to the last digit with 1, 2 and 4 threads).
OPENMP = {"OMP_NUM_THREADS": "1", "OMP_WAIT_POLICY": "PASSIVE"}


def prepare(img):
    """RGB as contiguous float32, negatives clamped to 0; ValueError for NaN or Inf."""
    img = np.asarray(img, dtype=np.float32)[..., :3]
    if not np.all(np.isfinite(img)):
        raise ValueError("image has NaN or Inf values; FLIP is not defined for it")
    return np.ascontiguousarray(np.maximum(img, 0.0))


class FlipWorker:
    """One warm ``--serve`` child (dies with this process: batch/backends/child.py KeptChild)."""

    def __init__(self):
        from ..backends import child
        self.child = child.KeptChild([sys.executable, Path(__file__).resolve(), "--serve"],
                                     env=dict(os.environ, **OPENMP))
        self._pending, self._sent, self.timeout = b"", 0, DEFAULT_TIMEOUT  # bytes read past a line; bytes written

    @property
    def proc(self):
        return self.child.proc

    def alive(self):
        return self.child.alive()

    def send(self, ref, test, map_path, deadline):
        """Send one request (the reply is read by ``receive``) by ``deadline`` (time.monotonic):
        None, or the error when the child is gone or stopped reading (then it is killed: a child
        that stops reading would block a request above the pipe's buffer, 64 kB, for ever)."""
        head = json.dumps({"shape": list(ref.shape[:2]), "map": str(map_path)}) + "\n"
        data = memoryview(head.encode() + ref.tobytes() + test.tobytes())
        total = len(data)
        fd = self.proc.stdin.fileno()
        os.set_blocking(fd, False)  # written here in pieces the pipe takes, never waiting past the deadline
        try:
            with selectors.DefaultSelector() as sel:
                sel.register(fd, selectors.EVENT_WRITE)
                while data:
                    left = deadline - time.monotonic()
                    if left <= 0 or not sel.select(left):
                        self.kill()
                        return (f"FLIP timed out after {self.timeout:g} s: the child stopped reading its request "
                                f"({self._sent} of {total} bytes taken)")
                    try:
                        n = os.write(fd, data)
                    except BlockingIOError:
                        continue
                    data = data[n:]
                    self._sent += n
        except OSError as exc:
            return self._died(f"FLIP worker stopped: {exc}")
        finally:
            self._sent = 0
        return None

    def receive(self, deadline):
        """(mean, None) or (None, error) by ``deadline``; a child that dies or overruns is killed
        (``alive`` False)."""
        line = self._read_line(deadline)
        if line is None:
            self.kill()
            return None, f"FLIP timed out after {self.timeout:g} s"
        if not line:
            return None, self._died(f"FLIP failed (exit {self.proc.wait()})")
        try:
            reply = json.loads(line)
        except ValueError:
            return None, self._died(f"FLIP printed no result: {line[-300:]!r}")
        if "error" in reply:
            return None, f"FLIP failed: {reply['error'][-500:]}"
        return reply["flip"], None

    def _read_line(self, deadline):
        """The child's next line by ``deadline``: bytes (b"" once it has exited), or None when
        no whole line came in time. Read from the pipe as it comes (a child stopped halfway
        through a line cannot hold this past the deadline); bytes after the line are kept for the next."""
        fd = self.proc.stdout.fileno()
        with selectors.DefaultSelector() as sel:
            sel.register(fd, selectors.EVENT_READ)
            while b"\n" not in self._pending:
                left = deadline - time.monotonic()
                if left <= 0 or not sel.select(left):
                    return None
                chunk = os.read(fd, 1 << 16)
                if not chunk:
                    return b""
                self._pending += chunk
        line, _, self._pending = self._pending.partition(b"\n")
        return line + b"\n"

    def exchange(self, ref, test, map_path, timeout):
        """One request and its reply, the whole exchange bounded by ``timeout`` seconds: (mean or
        None, error or None); a child that overruns (stopped, stuck, or too slow) is killed."""
        self.timeout = timeout
        deadline = time.monotonic() + timeout
        error = self.send(ref, test, map_path, deadline)
        return (None, error) if error else self.receive(deadline)

    def _died(self, what):
        said = self.child.early_output().strip()
        self.kill()
        return what + (f": {said[-500:]}" if said else "")

    def kill(self):
        self.child.kill()

    def close(self):
        self.child.close()


_WORKER = []  # the process's one warm FlipWorker (at most)
_LOCK = threading.Lock()  # held while a request is in the child (and while a child is made)
# Requests wait here for the child (arrays of the next jobs; at most QUEUED, then ``start`` waits:
# a bound on memory when FLIP falls behind the verdicts), served in order by one thread.
QUEUED = 8
_QUEUE = queue.Queue(QUEUED)
_STARTER = cf.ThreadPoolExecutor(max_workers=1, thread_name_prefix="flip-start")  # see prestart
_SERVER, _SERVER_LOCK = [], threading.Lock()


def _worker():
    if not (_WORKER and _WORKER[0].alive()):
        _WORKER[:] = [FlipWorker()]
    return _WORKER[0]


def prestart():
    """Start the warm child now (it imports while the caller reads images and tests noise). A
    no-op when a child exists or is serving a request: waiting here for the previous job's FLIP
    would hold this verdict behind it (issue 23: 0.9 s of the tiny suite's verdict thread); the
    request after it replaces a child that died."""
    if _WORKER or not _LOCK.acquire(blocking=False):
        return
    try:
        # started from a thread that lives as long as this process: a kept child dies with the
        # thread that started it (batch/backends/child.py), and a caller's thread may be short-lived
        _STARTER.submit(_worker).result()
    finally:
        _LOCK.release()


def _serve_queue():
    """The thread that hands the queued requests to the child, one at a time, in order."""
    while True:
        ref, img, map_path, timeout, done = _QUEUE.get()
        try:
            with _LOCK:
                outcome = _worker().exchange(ref, img, map_path, timeout)
        except Exception as exc:  # noqa: BLE001 - a child that cannot be started fails this request
            outcome = (None, f"FLIP failed: {type(exc).__name__}: {exc}")
        done.set_result(outcome)


@atexit.register
def close():
    """Stop the warm child (it also dies with this process). Waits a little for a request in the
    child (none is left when a run ends: the engine collects every FLIP)."""
    got = _LOCK.acquire(timeout=5)
    try:
        for w in _WORKER:
            w.close()
        _WORKER.clear()
    finally:
        if got:
            _LOCK.release()


class Pending:
    """A FLIP request queued for, or under way in, the warm child: ``result()`` waits for its
    (mean or None, error or None). Requests never wait for each other's ``result()``: the child
    serves them in order while the verdicts go on (issue 23: the default suite's verdict thread
    waited 112 s of 184 for the previous job's FLIP before it could send the next)."""

    def __init__(self, outcome=None, future=None):
        self._outcome, self._future = outcome, future

    def result(self):
        return self._future.result() if self._future is not None else self._outcome


def start(reference, test, map_path, timeout=DEFAULT_TIMEOUT):
    """Queue ``test`` and ``reference`` (H x W x >= 3 linear sRGB arrays) for the warm child, which
    computes the mean HDR-FLIP and writes its map to ``map_path`` (half floats) while the caller
    goes on (the probes, the next job); returns a Pending. ``timeout`` counts from when the child
    takes the request."""
    try:
        ref, img = prepare(reference), prepare(test)
    except ValueError as exc:
        return Pending((None, f"FLIP not computed: {exc}"))
    if ref.shape != img.shape:
        return Pending((None, f"FLIP not computed: shapes differ: {ref.shape} vs {img.shape}"))
    with _SERVER_LOCK:
        if not (_SERVER and _SERVER[0].is_alive()):
            _SERVER[:] = [threading.Thread(target=_serve_queue, name="flip-requests", daemon=True)]
            _SERVER[0].start()
    done = cf.Future()
    _QUEUE.put((ref, img, map_path, timeout, done))
    return Pending(future=done)


_DEFERRING = threading.local()


@contextlib.contextmanager
def deferred():
    """Within this block, in this thread, verdicts hand what finishes their FLIP to the list
    yielded (``defer``) instead of waiting for it: the caller runs those later, in order, in any
    thread (the default engine: while the next verdict reads and tests its render). Each should
    be called once (its result is kept until then; nothing else waits for it)."""
    _DEFERRING.items = []
    try:
        yield _DEFERRING.items
    finally:
        _DEFERRING.items = None


def defer(finish):
    """True when ``finish`` was handed to the enclosing ``deferred`` block, False (call it now)
    outside one."""
    items = getattr(_DEFERRING, "items", None)
    if items is None:
        return False
    items.append(finish)
    return True


def flip_images(reference, test, map_path, timeout=DEFAULT_TIMEOUT):
    """Mean HDR-FLIP of ``test`` against ``reference``, waited for (``start``): (mean or None,
    error message or None)."""
    return start(reference, test, map_path, timeout).result()


def hdr_flip(ref_path, test_path, map_path, timeout=DEFAULT_TIMEOUT):
    """Mean HDR-FLIP of the RGB of EXR ``test_path`` against ``ref_path`` (flip_images)."""
    from .. import exr
    return flip_images(exr.read_rgb(ref_path), exr.read_rgb(test_path), map_path, timeout)


# HDR-FLIP on the part of the image where something is (issue 45, item 1). A render whose
# background is black (ggx_copper_grazing: 81 % of its pixels are 0 in both images) has a tiny
# median luminance, so HDR-FLIP takes many exposures (25 there, against 4 for a Macbeth chart),
# each an LDR-FLIP of the whole image: 7.4 s of CPU, 5 % of the default suite's rendering. Where
# the reference and the test are both 0 over a pixel's whole filter support, both LDR images are
# the same there at every exposure, and its error is exactly 0; so FLIP evaluates only the box
# around the pixels that are not 0 in either image, grown by the filters' radius (below), and the
# rest of the map is 0. The same numbers as FLIP on the whole image, bit for bit (checked in
# tests/verdict/test_compare.py on renders of the suite), because:
# - the exposures are the whole reference's: HDR-FLIP computes them from its largest and median
#   luminance (flip-evaluator: Image::computeExposures), and those are passed to the box's
#   evaluation; they are found by FLIP itself on a 1 x 3 image of a black pixel and the
#   reference's median- and largest-luminance pixels (luminance in float32 as FLIP computes it);
# - inside the box every pixel sees the same values: FLIP's separable filters clamp at the image
#   edge, and the box's edge lies in the black (or on the image's edge), where clamping to it
#   reads the same 0 as the pixels beyond;
# - outside the box a pixel's whole filter support is black in both images, so its error is 0;
# - the mean is FLIP's: a float32 sum of the whole map in row order (zeros add nothing), divided
#   by the pixel count in float32.
CROP_MAX = 0.8  # crop only when the box is at most this share of the image (else: FLIP as it is)
_LUMA = tuple(np.float32(c) for c in (0.2126, 0.7152, 0.0722))  # FLIP's linearRGBToLuminance


def filter_radius(ppd):
    """The largest of FLIP's filter radii in pixels at ``ppd`` (its spatial filter's, from the
    largest Gaussian scale parameter 0.04, and its feature filter's, 3 standard deviations of
    0.5 * 0.082 degrees), plus 2 pixels against rounding: a wider margin costs only time."""
    spatial = np.ceil(3.0 * np.sqrt(0.04 / (2.0 * np.pi ** 2)) * ppd)
    feature = np.ceil(3.0 * 0.5 * 0.082 * ppd)
    return int(max(spatial, feature)) + 2


def content_box(ref, test, margin):
    """(row slice, column slice) of the pixels not 0 in either image, grown by ``margin`` and
    kept inside the image; None when every pixel is 0 in both."""
    some = np.any(ref != 0, axis=-1) | np.any(test != 0, axis=-1)
    rows, cols = np.flatnonzero(some.any(axis=1)), np.flatnonzero(some.any(axis=0))
    if not rows.size:
        return None
    h, w = some.shape
    return (slice(max(0, rows[0] - margin), min(h, rows[-1] + 1 + margin)),
            slice(max(0, cols[0] - margin), min(w, cols[-1] + 1 + margin)))


def hdr_flip_map(flip_evaluator, ref, test):
    """(H x W float32 map, mean) of HDR-FLIP of ``test`` against ``reference`` (H x W x 3 float32,
    non-negative), as flip_evaluator.evaluate computes them on the whole images; evaluated on the
    box around what is not black when that is at most CROP_MAX of the image (see above)."""
    h, w = ref.shape[:2]

    def full():
        fmap, mean, _ = flip_evaluator.evaluate(ref, test, "HDR", inputsRGB=False, applyMagma=False,
                                                computeMeanError=True)
        return np.asarray(fmap, dtype=np.float32).reshape(h, w, -1)[..., 0], float(mean)

    luma = (_LUMA[0] * ref[..., 0] + _LUMA[1] * ref[..., 1]) + _LUMA[2] * ref[..., 2]  # FLIP's order, float32
    flat = luma.ravel()
    k = flat.size // 2  # FLIP's median: element size/2 of the sorted luminances
    median_at = int(np.argpartition(flat, k)[k])
    proxy = np.zeros((1, 3, 3), np.float32)
    proxy[0, 1], proxy[0, 2] = ref.reshape(-1, 3)[median_at], ref.reshape(-1, 3)[int(np.argmax(flat))]
    _, _, params = flip_evaluator.evaluate(proxy, proxy.copy(), "HDR", inputsRGB=False, applyMagma=False,
                                           computeMeanError=False, parameters={"numExposures": 2})
    box = content_box(ref, test, filter_radius(params["ppd"]))
    if box is None or (box[0].stop - box[0].start) * (box[1].stop - box[1].start) > CROP_MAX * h * w:
        return full()
    start, stop = np.float32(params["startExposure"]), np.float32(params["stopExposure"])
    exposures = int(max(np.float32(2.0), np.ceil(np.float32(stop - start))))  # FLIP's count, in float32
    part, _, _ = flip_evaluator.evaluate(np.ascontiguousarray(ref[box]), np.ascontiguousarray(test[box]), "HDR",
                                         inputsRGB=False, applyMagma=False, computeMeanError=False,
                                         parameters={"startExposure": float(start), "stopExposure": float(stop),
                                                     "numExposures": exposures, "ppd": float(params["ppd"])})
    fmap = np.zeros((h, w), np.float32)
    fmap[box] = np.asarray(part, dtype=np.float32).reshape(box[0].stop - box[0].start, box[1].stop - box[1].start, -1)[..., 0]
    total = np.cumsum(fmap.ravel(), dtype=np.float32)[-1]  # sequential float32 sum, as FLIP's loop
    return fmap, float(total / np.float32(h * w))


def _serve():
    """The child: answer requests from stdin until it closes (module docstring)."""
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # whatever flip_evaluator prints goes to stderr, never into the replies
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch import previews
    import flip_evaluator
    stdin = sys.stdin.buffer
    for line in iter(stdin.readline, b""):
        if not line.strip():
            continue
        req = json.loads(line)
        h, w = (int(v) for v in req["shape"])
        size = h * w * 3 * 4
        ref = np.frombuffer(stdin.read(size), dtype=np.float32).reshape(h, w, 3).copy()  # writable, as flip needs
        test = np.frombuffer(stdin.read(size), dtype=np.float32).reshape(h, w, 3).copy()
        try:
            fmap, mean = hdr_flip_map(flip_evaluator, ref, test)
            previews.write_flip(req["map"], fmap)  # one channel Y, 5 significant bits
            answer = {"flip": float(mean)}
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - reported for this request; the child stays
            answer = {"error": f"{type(exc).__name__}: {exc}"}
        reply.write(json.dumps(answer) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] == ["--serve"]:
        _serve()
    else:
        sys.exit("usage: flip_isolated.py --serve (started by batch/verdict/flip_isolated.py FlipWorker)")
