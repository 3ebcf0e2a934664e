"""Planning a run: which jobs (batch/jobs/job.py) the selected scenes, backends and studies need,
and the results that need no render (a bad scene, a missing backend, a scene a backend cannot
model). Plain data in, plain data out: no rendering here.
"""
import copy
import math
from pathlib import Path

from ...exporters import validate
from .. import records
from ..studies import sweep
from . import job as jobs

job_id = jobs.job_id
# options a resumed run takes from this command; every other option comes from the run being resumed
ENGINE_KEYS = ("resume", "out", "cluster", "cluster_timeout", "dashboard", "log", "visualize", "list", "settings",
               "junit")
VERDICT_KEYS = ("alpha", "min_samples", "block", "flip", "references", "known", "detect", "max_passes")


def verdict_settings(opts):
    """What a job's verdict depends on, from the options (plain data carried by every job)."""
    settings = {k: opts.get(k) for k in VERDICT_KEYS}
    refs = settings["references"]
    settings["references"] = [str(Path(r).resolve()) for r in refs] if isinstance(refs, list) else (
        str(Path(refs).resolve()) if refs else None)
    if not settings["detect"]:  # without --detect, the job ids of earlier runs stay (resume keeps their jobs)
        del settings["detect"], settings["max_passes"]
    return settings


def for_run(scene, opts, judged=True):
    """The scene with --spp and --scale applied (``judged``: at the scale its reference can be
    box-filtered to, ``scale_for``; the reference maker renders at the scale as given)."""
    sc = copy.deepcopy(scene)
    if opts.get("spp"):
        sc["render"]["spp"] = int(opts["spp"])
    if opts.get("scale") and opts["scale"] != 1.0:
        r = sc["render"]
        scale = scale_for(r["width"], r["height"], opts["scale"]) if judged else opts["scale"]
        r["width"], r["height"] = scaled_size(r["width"], r["height"], scale)
    return validate.check_render(sc, f" (after --spp {opts.get('spp')} --scale {opts.get('scale')})"
                                 if opts.get("spp") or opts.get("scale", 1.0) != 1.0 else "")


def scaled_size(width, height, scale):
    """The render resolution (w, h) of a scene of width x height at --scale (as ``for_run``)."""
    return max(1, round(width * scale)), max(1, round(height * scale))


def scale_fits(width, height, scale):
    """True when --scale gives an integer fraction of width x height in each axis: the resolution
    at which the scene's reference (rendered at its own resolution) is box-filtered exactly
    (batch/verdict/compare.py ``reference_at``; the two factors may differ)."""
    w, h = scaled_size(width, height, scale)
    return width % w == 0 and height % h == 0


def valid_scales(sizes):
    """Every scale <= 1 that gives an integer fraction of each (width, height) in ``sizes``, as
    exact fractions d / width of the first sizes' divisors, sorted."""
    candidates = {d / n for width, height in sizes for n in (width, height) for d in range(1, n + 1) if n % d == 0}
    return sorted(c for c in candidates if c <= 1 and all(scale_fits(w, h, c) for w, h in sizes))


def scale_for(width, height, scale):
    """The scale a scene of width x height renders at for --scale ``scale``: ``scale`` itself when
    it gives an integer fraction of the resolution in each axis, else the valid scale (<= 1)
    nearest to it in ratio (ties: the smaller, cheaper one). 0.125 of the 620x420 charts would be
    78x52, which their reference cannot be box-filtered to; they render at 0.1 (62x42) instead,
    judged like any other render. A scale above 1 is returned as it is (``scale_problem`` refuses
    it: a render finer than its reference has nothing to be box-filtered from)."""
    if scale > 1.0 or scale_fits(width, height, scale):
        return scale
    return min(valid_scales([(width, height)]), key=lambda c: (abs(math.log(c / scale)), c))


def scale_changes(scenes, scale):
    """[(scale rendered at, [(scene, (width, height), (w, h))])] for the selected ``scenes`` [(name,
    IR or error)] that --scale ``scale`` does not divide (``scale_for``), grouped by the scale they
    render at instead; [] when every scene takes ``scale`` as given."""
    if not scale or scale >= 1.0:
        return []
    groups = {}
    for name, sc in scenes:
        if isinstance(sc, dict):
            size = (sc["render"]["width"], sc["render"]["height"])
            if (chosen := scale_for(*size, scale)) != scale:
                groups.setdefault(chosen, []).append((name, size, scaled_size(*size, chosen)))
    return sorted(groups.items())


def scale_problem(scenes, scale):
    """None, or why --scale cannot be judged on the selected ``scenes`` [(name, IR or error)]: a
    scale above 1 asks for renders finer than their references, which cannot be box-filtered to
    them (a usage error; a scale below 1 that divides no resolution is moved to the nearest one
    that does, ``scale_for``)."""
    if not scale or scale <= 1.0:
        return None
    sizes = {n: (sc["render"]["width"], sc["render"]["height"]) for n, sc in scenes if isinstance(sc, dict)}
    bad = list(sizes)
    if not bad:
        return None
    shown = "; ".join(f"{n}: {sizes[n][0]}x{sizes[n][1]} -> {'x'.join(map(str, scaled_size(*sizes[n], scale)))}"
                      for n in bad[:5]) + (f"; and {len(bad) - 5} more" if len(bad) > 5 else "")
    return (f"--scale {scale:g} renders finer than the reference for {shown} (a render is judged against its "
            f"reference box-filtered by an integer factor in each axis); scales up to 1 are judged")


def main_jobs(scenes, made, opts, out, settings):
    """(render jobs, entries decided without rendering) for every scene on every backend. Whatever
    goes wrong while planning one scene on one backend (a mesh that cannot be read, a scene a
    backend chokes on) is that job's failure, with the reason; the others are planned."""
    job_list, immediate = [], []
    for name, scene in scenes:
        for bname, backend in made.items():
            if isinstance(scene, Exception):
                immediate.append(_decided(name, None, bname, "failed", str(scene)))
                continue
            try:
                job, decided = _main_job(name, scene, bname, backend, opts, out, settings)
            except Exception as exc:  # noqa: BLE001 - one scene that cannot be planned fails alone
                immediate.append(_decided(name, scene, bname, "failed", f"cannot be planned: {type(exc).__name__}: {exc}"))
                continue
            if job is not None:
                job_list.append(job)
            else:
                immediate.append(decided)
    return job_list, immediate


def _main_job(name, scene, bname, backend, opts, out, settings):
    """(the render job, None) or (None, the entry decided without rendering)."""
    ok, why = backend.availability()
    if not ok:
        return None, _decided(name, scene, bname, "skipped", why)
    sc = for_run(scene, opts)
    mode, why = backend.mode_for(sc)
    if mode is None:
        r = sc["render"]
        return None, _decided(name, sc, bname, "unsupported", why, spp=r["spp"], resolution=[r["width"], r["height"]])
    job = jobs.make("render", name, sc, bname, mode, sc["render"]["spp"], out,
                    Path(name) / "results" / bname, export=Path(name) / backend.formats[0],
                    backend_options=backend.options, passes=opts["passes"], seed=opts["seed"],
                    timeout=opts["timeout"], source_scene=scene, verdict=settings)
    job["id"] = job_id(job)  # reads every file the scene names (meshes): a broken one fails here, named
    return job, None


def entry(name, scene, backend, **kw):
    """A metrics.json run record for a job decided without rendering (and for exports):
    batch/records.py ``run_record``, the one builder."""
    return records.run_record(name, scene, backend, **kw)


def _decided(name, scene, backend, status, reason, **kw):
    return entry(name, scene, backend, status=status, reason=reason, **kw)


def sweep_jobs(scenes, made, opts, out, settings):
    """(jobs, lines decided without rendering): every rung of the ladder for each backend mode,
    two passes each (the rung's own noise for its noise test)."""
    ladder = opts["ladder"] or list(sweep.DEFAULT_LADDER)
    job_list, lines = [], []
    for name, scene in scenes:
        if isinstance(scene, Exception):
            continue
        try:
            scene_jobs, scene_lines = _sweep_jobs(name, scene, made, opts, out, settings, ladder)
        except Exception as exc:  # noqa: BLE001 - one scene that cannot be planned fails alone
            scene_jobs, scene_lines = [], [{"scene": name, "backend": b, "mode": None, "points": [],
                                            "reason": f"cannot be planned: {type(exc).__name__}: {exc}"} for b in made]
        job_list += scene_jobs
        lines += scene_lines
    return job_list, lines


def _sweep_jobs(name, scene, made, opts, out, settings, ladder):
    """One scene's sweep jobs and the lines decided without rendering."""
    from ..verdict import judge
    job_list, lines = [], []
    sc = for_run(scene, dict(opts, spp=None))
    ref, unusable = judge.load_reference(name, scene, settings["references"])
    for bname, backend in made.items():
        if not backend.availability()[0]:
            continue
        modes, why = sweep.sweep_modes(backend, sc, opts["sweep_modes"])
        if not modes or unusable:
            lines.append({"scene": name, "backend": bname, "mode": None, "points": [], "reason": why or unusable})
            continue
        for mode in modes:
            for spp in ladder:
                folder = Path(name) / "sweeps" / f"{bname}-{mode}" / f"spp{spp}"
                job_list.append(jobs.make("sweep", name, sc, bname, mode, spp, out, folder,
                                          backend_options=backend.options, passes=2, seed=opts["seed"],
                                          timeout=opts["timeout"], source_scene=scene, verdict=settings,
                                          extra={"mode": mode, "rung": spp},
                                          label=f"{name} sweep {mode} {spp} spp ({bname})"))
                job_list[-1]["id"] = job_id(job_list[-1])
    return job_list, lines


def sweep_lines(results):
    """The sweep lines (one per scene, backend and mode) from the rungs' results."""
    groups = {}
    for job, result in results:
        groups.setdefault((job["scene_name"], job["backend"], job["extra"]["mode"]), []).append((job, result))
    lines = []
    for (name, backend, mode), items in sorted(groups.items()):
        line = {"scene": name, "backend": backend, "mode": mode, "points": [], "reason": ""}
        failed = [r.get("reason", "failed") for _, r in items if r.get("status") != "rendered"]
        points = [r["point"] for _, r in sorted(items, key=lambda jr: jr[0]["spp"]) if r.get("point")]
        if failed or not points or any("rmse" not in p for p in points):
            line["reason"] = "sweep failed: " + "; ".join(failed or [p.get("reason", "") for p in points])[:500]
        else:
            line["points"] = points
            line.update(sweep.analyse(points))
        lines.append(line)
    return lines


class ResumeError(ValueError):
    """A run that cannot be resumed (a usage error, exit 2), named."""


def read_metrics(out):
    """The metrics.json of a run being resumed (batch/records.py ``read``, strict: upgraded to the
    current version, path fields absolute), or ResumeError naming the file."""
    try:
        data = records.read(Path(out) / records.FILE_NAME)
    except records.RecordError as exc:
        raise ResumeError(f"cannot resume: {exc}") from None
    # the kept results go verbatim into summary.md, report.html and the JUnit XML: every value must
    # be of the type and range the runner writes (schemas/metrics.schema.json), or nothing runs
    problems = records.validate(dict(data))
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ResumeError(f"cannot resume from {data.file}: it is not as the runner writes it "
                          f"(schemas/metrics.schema.json): {problems[0]}{more}")
    data = data.resolved()
    if not isinstance(data.get("options", {}), dict) \
            or not all(isinstance(data.get(k, []), list) for k in ("runs", "jobs")):
        raise ResumeError(f"cannot resume from {data.file}: not the metrics.json of a run (an object with options and runs)")
    return data


def _option_name(key):
    return {"exec": "-e/--exec", "input": "-i/--input", "renderer": "-r/--renderer", "scene": "-s/--scene",
            "case": "-c/--case", "flip": "--flip"}.get(key, "--" + key.replace("_", "-"))


def _given_again(key, what, again):
    """A check of an option that names something to run (RUNS_CODE): the recorded ``value`` is
    only compared with what this command gives; never used itself."""
    def check(opts, value, given):
        if not value:
            if key in given and opts.get(key):
                raise ResumeError(f"cannot resume {opts['resume']} with {_option_name(key)}: the run was started "
                                  "without it (finished jobs would not match); leave the option out or start a new run")
            return opts.get(key)
        names = ", ".join(_brief(n, 80) for n in sorted(value)[:10]) + (" ..." if len(value) > 10 else "")
        if key not in given or not opts.get(key):
            raise ResumeError(f"cannot resume {opts['resume']}: the run was started with {what} {names}, which a "
                              f"run folder never supplies (metrics.json is data; it is not run): {again}")
        mine = same_source(opts[key], value) if key == "renderers" else opts[key]
        field = _first_difference(mine, value)
        if field is not None:
            raise ResumeError(f"cannot resume {opts['resume']}: {_option_name(key)} differs from the run's "
                              f"(recorded in metrics.json) at {field}; give the same {what} as the run, or start a new run")
        return mine
    return check


def same_source(given, recorded):
    """Declarations given again, each naming its file as the run recorded it where both name the same
    file (``source`` is a label in messages, but part of the job ids: ``-o`` from another folder or
    an absolute path to the same file keeps the finished jobs)."""
    out = {}
    for name, decl in given.items():
        old = recorded.get(name) if isinstance(recorded.get(name), dict) else {}
        try:
            same = Path(old.get("source", "")).resolve() == Path(decl["source"]).resolve() and old.get("source")
        except (OSError, ValueError, TypeError):
            same = False
        out[name] = dict(decl, source=old["source"]) if same else decl
    return out


def _brief(value, limit=200):
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"... ({len(text)} characters)"


def _first_difference(given, recorded):
    """The first field (``name.key``) where two {name: value or table} differ, or None (values shown
    cut short: a recorded one is anyone's text)."""
    for name in sorted(set(given) | set(recorded)):
        a, b = given.get(name), recorded.get(name)
        if a is None or b is None:
            return f"{_brief(name)} ({'not given' if a is None else 'not in the run'})"
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if a.get(k) != b.get(k):
                    return f"{_brief(name)}.{k} ({_brief(a.get(k))}, the run: {_brief(b.get(k))})"
        elif a != b:
            return f"{_brief(name)} ({_brief(a)}, the run: {_brief(b)})"
    return None


# Options that name something to run (a declared renderer's command, env and version; -e's
# executables): a run folder may come from anyone, so ``--resume`` takes them from this command only,
# compared with the recorded ones (the job ids depend on them) and refused where they differ.
RUNS_CODE = {
    "renderers": _given_again("renderers", "declared renderers",
                              "give their declarations again with --renderers FILE (the same file as the run)"),
    "exec": _given_again("exec", "executables (-e)", "give them again with -e NAME=PATH (the same paths as the run)"),
}


def resumed_options(opts, given=None):
    """The options of the run being resumed (so that the same jobs, with the same ids, are
    planned), with this command's engine, log and resume settings (ENGINE_KEYS). Every other
    option comes from the run being resumed, checked through the option's own type; one that this
    command gives (``given``: its option names; default: those that differ from the defaults) with
    another value is refused with ResumeError naming it. ``opts`` is the command's options
    (batch/cli.py ``Options``): the defaults and each option's check come with them, so that
    planning imports no entry point."""
    data = read_metrics(opts["resume"])
    previous = data.get("options") or {}
    if given is None:
        given = {k for k, v in opts.items() if v != opts.defaults.get(k) and not (k == "exec" and not v)}
    merged = dict(opts)
    for key, value in previous.items():
        if key not in opts.defaults or key in ENGINE_KEYS:
            continue
        try:
            value = opts.check(key, value)
        except ValueError as exc:  # the option's UsageError
            raise ResumeError(f"cannot resume from {Path(opts['resume']) / 'metrics.json'}: it records {exc}") from None
        if key in RUNS_CODE:
            merged[key] = RUNS_CODE[key](opts, value, given)
            continue
        if key in given and opts.get(key) != value:
            raise ResumeError(f"cannot resume {opts['resume']} with {_option_name(key)} {opts.get(key)!r}: the run "
                              f"was started with {value!r} (finished jobs would not match); leave the option out "
                              "or start a new run")
        merged[key] = value
    merged["out"] = opts["resume"]
    return merged


# Seconds per pixel of a verdict (the verdict thread's share; FLIP computes beside it in its own
# child) on this project's 2-core machine: the default suite's 65 s of verdicts over 27 jobs of
# ~0.22 Mpixel (benchmarks/ENGINES.md); and per sample and pixel of a render whose reference
# records no time. Only the *order* of the jobs depends on them (``overlap_order``), never a result.
VERDICT_S_PER_PIXEL = 1.1e-5
RENDER_S_PER_SAMPLE = 1.4e-7


def estimated_seconds(job):
    """(render, verdict) seconds of a render job, estimated for ordering: the render from its
    scene's reference record (the seconds it took for its samples and pixels, scaled to the job's;
    RENDER_S_PER_SAMPLE without one), the verdict from the job's pixels."""
    from ..verdict import references
    r = job["scene"]["render"]
    pixels = r["width"] * r["height"]
    per_sample = RENDER_S_PER_SAMPLE
    for folder in references.directories(job["verdict"].get("references")):
        meta, _problem = references.read_record(folder / f"{job['scene_name']}.json")
        if meta is None:
            continue
        try:
            seconds, (w, h) = float(meta.get("time_s")), meta["resolution"]
            if math.isfinite(seconds) and seconds > 0 and w > 0 and h > 0:
                per_sample = seconds / (meta["spp"] * w * h)
        except (TypeError, ValueError, KeyError):  # a record without a usable time: the default
            pass
        break
    return per_sample * pixels * job["spp"], pixels * VERDICT_S_PER_PIXEL


def overlap_order(job_list):
    """The jobs in the order that lets the verdicts (one thread, judging job k while job k+1
    renders: batch/jobs/engines.py) finish soonest after the last render: Johnson's rule for a
    two-stage flow shop (S. M. Johnson, "Optimal two- and three-stage production schedules with
    setup times included", Naval Research Logistics Quarterly 1(1), 1954): jobs whose render is
    shorter than their verdict first, by render time ascending; then the rest by verdict time
    descending. Long renders late absorb the verdicts queued behind short ones, and the last job
    has a short verdict. Render jobs only (other kinds keep their place after them); ties keep
    the planned order. No result depends on the order: a job's seeds are its own (--seed and
    its pass index), and each render starts from its own scene."""
    renders = [j for j in job_list if j.get("kind") == "render"]
    if len(renders) < 2:
        return list(job_list)
    est = {id(j): estimated_seconds(j) for j in renders}
    first = sorted((j for j in renders if est[id(j)][0] < est[id(j)][1]), key=lambda j: est[id(j)][0])
    last = sorted((j for j in renders if est[id(j)][0] >= est[id(j)][1]), key=lambda j: -est[id(j)][1])
    return first + last + [j for j in job_list if j.get("kind") != "render"]
