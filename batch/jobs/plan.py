"""Planning a run: which jobs (batch/jobs/job.py) the selected scenes, backends and studies need,
and the results that need no render (a bad scene, a missing backend, a scene a backend cannot
model). Plain data in, plain data out: no rendering here.
"""
import copy
import json
from pathlib import Path

from ..studies import sweep
from . import job as jobs

job_id = jobs.job_id
VERDICT_KEYS = ("alpha", "min_samples", "block", "flip", "references", "known")


def verdict_settings(opts):
    """What a job's verdict depends on, from the options (plain data carried by every job)."""
    settings = {k: opts.get(k) for k in VERDICT_KEYS}
    refs = settings["references"]
    settings["references"] = [str(Path(r).resolve()) for r in refs] if isinstance(refs, list) else (
        str(Path(refs).resolve()) if refs else None)
    return settings


def for_run(scene, opts):
    """The scene with --spp and --scale applied."""
    sc = copy.deepcopy(scene)
    if opts["spp"]:
        sc["render"]["spp"] = int(opts["spp"])
    if opts["scale"] and opts["scale"] != 1.0:
        sc["render"]["width"] = max(1, round(sc["render"]["width"] * opts["scale"]))
        sc["render"]["height"] = max(1, round(sc["render"]["height"] * opts["scale"]))
    return sc


def main_jobs(scenes, made, opts, out, settings):
    """(render jobs, entries decided without rendering) for every scene on every backend."""
    job_list, immediate = [], []
    for name, scene in scenes:
        for bname, backend in made.items():
            if isinstance(scene, Exception):
                immediate.append(_decided(name, None, bname, "failed", str(scene)))
                continue
            ok, why = backend.availability()
            if not ok:
                immediate.append(_decided(name, scene, bname, "skipped", why))
                continue
            sc = for_run(scene, opts)
            mode, why = backend.mode_for(sc)
            if mode is None:
                r = sc["render"]
                immediate.append(_decided(name, sc, bname, "unsupported", why, spp=r["spp"],
                                          resolution=[r["width"], r["height"]]))
                continue
            job_list.append(jobs.make("render", name, sc, bname, mode, sc["render"]["spp"], out,
                                      Path(name) / "results" / bname, export=Path(name) / backend.formats[0],
                                      backend_options=backend.options, passes=opts["passes"], seed=opts["seed"],
                                      timeout=opts["timeout"], source_scene=scene, verdict=settings))
    return job_list, immediate


def entry(name, scene, backend, **kw):
    """A metrics.json run record for a job decided without rendering (and for exports)."""
    e = {"scene": name, "case": scene.get("case") if isinstance(scene, dict) else None, "backend": backend,
         "mode": None, "status": "ok", "reason": "", "spp": None, "resolution": None, "time_s": None,
         "image": None, "metrics": {"rmse": None, "relmse": None, "mape": None, "flip": None}, "probes": []}
    e.update(kw)
    return e


def _decided(name, scene, backend, status, reason, **kw):
    return entry(name, scene, backend, status=status, reason=reason, **kw)


def sweep_jobs(scenes, made, opts, out, settings):
    """(jobs, lines decided without rendering): every rung of the ladder for each backend mode,
    two passes each (the rung's own noise for its noise test)."""
    from ..verdict import judge
    ladder = opts["ladder"] or list(sweep.DEFAULT_LADDER)
    job_list, lines = [], []
    for name, scene in scenes:
        if isinstance(scene, Exception):
            continue
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


def resumed_options(opts):
    """The options of the run being resumed (so that the same jobs are planned), with this
    command's engine, log and resume settings."""
    data = json.loads((Path(opts["resume"]) / "metrics.json").read_text())
    previous = dict(data.get("options") or {})
    keep = {k: opts[k] for k in ("resume", "cluster", "log", "visualize") if k in opts}
    merged = dict(opts)
    merged.update({k: v for k, v in previous.items() if k in opts})
    merged.update(keep)
    merged["exec"] = opts["exec"]
    merged["out"] = opts["resume"]
    return merged
