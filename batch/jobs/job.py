"""A job is plain data: a JSON-compatible dict naming everything one render needs (the scene IR as
rendered, the backend and its options, mode, samples, passes, seed, where its files go) and how
its result is judged. Executing it is a function of that data alone: it renders, writes its files
under its own folder and returns a small record. The same job gives the same image on any engine
(the seed is part of it), and its id (a hash of what determines the image and the verdict) lets a
resumed run keep what already finished.

Kinds:
  render     a scene on a backend, judged by batch/verdict/judge.py (the main run's jobs)
  sweep      one rung of a speed/accuracy ladder, judged against the reference (batch/studies/sweep.py)
  stability  one value of a stability strip, checked by batch/studies/stability.py
  reference  one independent pass of a reference (batch/make_references.py merges them)
"""
import copy
import hashlib
import importlib
import json
import time
from dataclasses import dataclass
from pathlib import Path



KINDS = ("render", "sweep", "stability", "study", "reference")  # KINDS_TABLE below says what each does


class RenderCrashed(RuntimeError):
    """A render that died (not a timeout, not a scene the backend refuses): worth one retry,
    preferably on another worker."""


def make(kind, scene_name, scene, backend, mode, spp, out, folder, *, backend_options=None, passes=1, seed=0,
         timeout=1800, source_scene=None, export=None, verdict=None, extra=None, label=None):
    """A job dict. ``out``: the run's output folder; ``folder``: this job's folder inside it;
    ``export``: where the backend's scene files go (default: the job's folder)."""
    return {"kind": kind, "scene_name": scene_name, "scene": scene, "source_scene": source_scene or scene,
            "backend": backend, "backend_options": dict(backend_options or {}), "mode": mode, "spp": int(spp),
            "passes": int(passes), "seed": int(seed), "timeout": timeout, "out": str(out), "folder": str(folder),
            "export": str(export or Path(folder) / "export"), "verdict": dict(verdict or {}),
            "extra": dict(extra or {}), "label": label or f"{scene_name} ({backend})"}


def job_id(job):
    """What determines the job's image and its verdict, hashed; computed once when the job is
    planned (batch/jobs/plan.py stores it as job["id"]: the scene's fingerprint reads its meshes)."""
    if "id" in job:
        return job["id"]
    from ..verdict import references
    key = {k: job[k] for k in ("kind", "backend", "backend_options", "mode", "spp", "passes", "seed", "extra")}
    key["scene"] = references.fingerprint(job["scene"])
    key["resolution"] = [job["scene"]["render"]["width"], job["scene"]["render"]["height"]]
    key["verdict"] = {k: v for k, v in job["verdict"].items() if k not in ("known",)}
    return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:20]


def backend_of(job):
    from .. import backends
    return backends.get(job["backend"], **job["backend_options"])


def execute(job):
    """Export and render; returns the render record. A render whose pass failed twice or timed out
    (the pass loop retries a failed pass once: batch/backends/passes.py) is a failed record with
    the renderer's error; RenderCrashed is left for what dies outside the pass loop."""
    from .. import backends
    from ...exporters import ir_json
    out = Path(job["out"])
    folder, export = out / job["folder"], out / job["export"]
    folder.mkdir(parents=True, exist_ok=True)
    record = {"job": job_id(job), "kind": job["kind"], "scene": job["scene_name"], "backend": job["backend"],
              "mode": job["mode"], "status": "rendered", "reason": "", "spp": job["spp"], "passes": job["passes"]}
    t0 = time.perf_counter()
    backend = backend_of(job)
    if job["kind"] == "render":
        ir_json.write(job["scene"], out / job["scene_name"] / "json" / f"{job['scene_name']}.json")
    path = backend.export(job["scene"], export)
    image = folder / "render.exr"
    try:
        if job["kind"] == "render" and job["verdict"].get("detect"):
            info = render_until_decided(job, backend, path, image, folder)
            record["sequential"] = info.pop("sequential")
        else:
            info = backend.render(path, job["mode"], job["spp"], image, passes=job["passes"], seed=job["seed"],
                                  timeout=job["timeout"], log_path=folder / "render.log")
    except backends.BackendFailure as exc:  # a pass that failed twice or timed out (batch/backends/passes.py)
        record.update(status="failed", reason=f"render failed: {exc}")
        return record
    record.update(time_s=info["time_s"], wall_s=info["wall_s"], spp=info["spp"], passes=info.get("passes", 1),
                  versions=info.get("versions"), pass_times=info.get("pass_times"), image_path=str(image), image=str(image.relative_to(out)),
                  job_wall_s=time.perf_counter() - t0)
    for key in ("approximated", "retried", "spectral"):  # an RGB backend's approximations (--approximate);
        # passes retried; a spectral render's bands (batch/spectral_passes.py)
        if info.get(key):
            record[key] = info[key]
    return record


def render_until_decided(job, backend, path, image, folder):
    """``--detect S`` (batch/verdict/sequential.py): the job's passes, then doubled (no pass
    rendered twice: batch/backends/passes.py Accumulation) until the noise test's detectable scale
    error is <= S, it fails at the alpha spent per look, or ``max_passes``. Returns the last
    render record with ``sequential`` (the looks)."""
    import math
    from ..backends import passes as passes_mod
    from ..verdict import judge as verdicts, sequential
    v = job["verdict"]
    acc = passes_mod.Accumulation(per_pass=math.ceil(job["spp"] / job["passes"]))
    last = {}

    def render_to(n):
        last.update(passes_mod.render(backend, path, job["mode"], job["spp"], image, passes=n, seed=job["seed"],
                                      timeout=job["timeout"], log_path=folder / "render.log", accumulation=acc))

    def look(alpha):
        return verdicts.look(job["scene_name"], job["source_scene"], job["scene"], job["backend"], job["mode"], last["spp"],
                             last["passes"], image, folder, v, alpha)

    seq = sequential.run(render_to, look, job["passes"], v.get("max_passes") or sequential.MAX_PASSES,
                         v["detect"], v["alpha"])
    return dict(last, sequential=seq)


def _judge_render(job, record, deviations):
    """A render job's metrics.json entry (batch/verdict/judge.py), failed when the render was."""
    from ..verdict import judge as verdicts, known
    entry = new_entry(job)
    if record["status"] != "rendered":
        entry.update(status="failed", reason=record["reason"])
        return entry
    entry.update({k: record[k] for k in ("time_s", "wall_s", "spp", "passes", "pass_times", "image", "versions",
                                         "approximated", "retried", "sequential", "spectral")
                  if k in record})
    if deviations is None:
        deviations = known.load(job["verdict"].get("known"))
    out = Path(job["out"])
    settings = job["verdict"]
    if "sequential" in record:  # --detect: the final verdict at the alpha spent per look (sequential.py)
        settings = dict(settings, alpha=record["sequential"]["alpha_per_look"])
    return verdicts.render_verdict(entry, job["source_scene"], job["scene"], out / record["image"],
                                   out / job["folder"], settings, deviations)


@dataclass(frozen=True)
class Kind:
    """What a kind of job does with its render record: ``judge`` (a function, or "module:function"
    imported when first needed: a study's probes and scipy load only when a job of its kind is
    judged) and the key under which its result sits in the record (``result``)."""
    judge: object = None
    result: str = None

    def judged(self, job, record, deviations):
        if callable(self.judge):
            return self.judge(job, record, deviations)
        if record["status"] != "rendered" or self.judge is None:
            return dict(record)
        module, _, name = self.judge.partition(":")
        fn = getattr(importlib.import_module(module, __package__), name)
        return dict(record, **{self.result: fn(job, record)})


# the job kinds: one table (the runner, the engines and resume dispatch through it)
KINDS_TABLE = {
    "render": Kind(_judge_render),
    "sweep": Kind("..verdict.judge:sweep_point", "point"),  # one rung of a speed/accuracy ladder
    "stability": Kind("..studies.stability:judge_value", "row"),  # one value of a stability strip
    "study": Kind(None),  # one render of --study spectral-vs-rgb (studies/spectral_vs_rgb.py compares the pairs)
    "reference": Kind(None),  # one pass of a reference (batch/make_references.py merges them)
}


def warm(job_list):
    """Load what the verdicts of ``job_list`` need before the first of them: the verdict modules,
    colour-science (its import is about a second) and the warm FLIP child
    (batch/verdict/flip_isolated.py). The default engine calls it in its verdict thread while the
    first job renders; the verdicts are the same without it, only later."""
    if not any(j["kind"] in ("render", "sweep") for j in job_list):
        return
    from ..verdict import flip_isolated, judge as _verdicts  # noqa: F401 - imported to be ready
    from ...exporters import colorimetry
    colorimetry.srgb_to_xyz([1.0, 1.0, 1.0])
    if any(j["kind"] == "render" and j["verdict"].get("flip", "auto") is True for j in job_list):  # auto: when asked
        flip_isolated.prestart()


def prestart_workers(job_list):
    """Start the warm render workers that ``job_list`` will need, in the background, where a
    backend keeps them (``prestart(modes, timeout)``: Mitsuba's one per variant). Nothing waits
    here; a job whose worker is still starting waits for that one instead of starting another."""
    by_backend = {}
    for j in job_list:
        if j["kind"] in ("render", "sweep", "stability", "reference"):
            by_backend.setdefault((j["backend"], json.dumps(j["backend_options"], sort_keys=True)), []).append(j)
    for jobs_of in by_backend.values():
        backend = backend_of(jobs_of[0])
        if hasattr(backend, "prestart"):
            backend.prestart([j["mode"] for j in jobs_of], max(float(j["timeout"]) for j in jobs_of))


def judge(job, record, deviations=None):
    """The kind's verdict on a render record: the job's result (a metrics.json entry, a sweep
    point, a stability row or a reference pass), through KINDS_TABLE."""
    return KINDS_TABLE[job["kind"]].judged(job, record, deviations)


def judge_deferring(job, record, deviations=None):
    """``judge``, leaving a render verdict's FLIP to finish later (batch/verdict/flip_isolated.py
    ``deferred``): (result, [finish, ...]). The result is complete once each finish has been
    called, in order, exactly once (the default engine calls them in a third thread, so that the
    next verdict starts while FLIP computes)."""
    from ..verdict import flip_isolated
    with flip_isolated.deferred() as pending:
        try:
            result = judge(job, record, deviations)
        except BaseException:
            for finish in pending:
                finish()
            raise
    return result, list(pending)


def run(job, deviations=None):
    """Execute and judge one job (what an engine's worker calls). Failures inside the verdict
    become failed records; a crashed render raises RenderCrashed for the engine to retry."""
    record = execute(job)
    try:
        return judge(job, record, deviations)
    except Exception as exc:  # noqa: BLE001 - a verdict that breaks is a failed job, not a crashed batch
        return failure(job, f"verdict failed: {exc!r}", record)


def new_entry(job, **kw):
    """A metrics.json run record for a render job (batch/records.py ``run_record``: the one builder)."""
    from .. import records
    r = job["scene"]["render"]
    film = job["backend_options"].get("film")  # Mitsuba's: its own film or the scene format's colour
    return records.run_record(job["scene_name"], job["scene"], job["backend"], mode=job["mode"], spp=job["spp"],
                              resolution=[r["width"], r["height"]], job=job_id(job), **({"film": film} if film else {}),
                              **kw)


def describe(exc):
    """One line for an unexpected exception in a job, naming the file where it is a file's
    problem (an output folder that cannot be written, a path taken by a file)."""
    if isinstance(exc, OSError) and exc.filename:
        what = f"{exc.strerror or type(exc).__name__}: {exc.filename}"
        if exc.filename2:
            what += f" -> {exc.filename2}"
        return f"cannot write or read a file: {what}"
    return f"internal error: {exc!r}"


def failure(job, reason, record=None):
    """The result of a job that could not finish (crash after its retry, killed worker, interrupt)."""
    if job["kind"] == "render":
        return new_entry(job, status="failed", reason=reason)
    out = {"job": job_id(job), "kind": job["kind"], "scene": job["scene_name"], "backend": job["backend"],
           "mode": job["mode"], "status": "failed", "reason": reason}
    if record:
        out.update({k: v for k, v in record.items() if k not in out})
    return out


def strip_scene(job):
    """A copy of the job without its scenes (small enough to log or store)."""
    out = copy.copy(job)
    out.pop("scene", None)
    out.pop("source_scene", None)
    return out
