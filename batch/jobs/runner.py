"""The batch: plan the jobs (scenes x backends, sweep rungs, stability values: batch/jobs/plan.py),
run them on an engine (batch/jobs/engines.py), and collect their results into metrics.json,
summary.md and report.html.

One job never takes down the batch: every failure (bad scene, crashed render, failed verdict)
becomes a result with status "failed" and a reason, and metrics.json is rewritten atomically after
every job, so finished results survive a crash of the runner itself. ``--resume OUT`` finishes an
interrupted run: results whose job id (batch/jobs/job.py) still matches are kept, the rest run.
"""
from collections import Counter
import datetime as _dt
import logging
import os
import time
from pathlib import Path


from ...exporters import art_writer, ir_json, pbrt_writer
from .. import backends, records, run_folder, scene_sources
from ..verdict import baseline as baselines, known, status
from ..report import html as report, results, summary
from ..studies import sweep
from . import engines, job as job_mod, plan as planning
from .progress import Progress

log = logging.getLogger("spectral_bench")


class UsageError(RuntimeError):
    """A problem with the command, its files or its output folder (exit 2), named."""


class OutputExists(UsageError):
    pass


LOCK_NAME = ".lock"


def _lock(out):
    """Claim ``out`` for this run: an exclusive lock on OUT/.lock, held until released (or the
    process ends); a second run into the same folder is refused at once."""
    import filelock
    lock = filelock.FileLock(str(out / LOCK_NAME), timeout=0)
    try:
        lock.acquire()
    except filelock.Timeout:
        raise UsageError(f"{out} is in use by another run (it holds {out / LOCK_NAME}); choose another --out, "
                         "nothing was changed") from None
    except OSError as exc:
        raise UsageError(f"cannot write to the output folder {out}: {exc.strerror or exc}") from None
    return lock


def _default_out():
    """A new folder outputs-YYYYmmdd-HHMMSS (-2, -3, ... when two runs start in the same second)."""
    base = _dt.datetime.now().strftime("outputs-%Y%m%d-%H%M%S")
    for k in range(1, 1000):
        out = Path(base if k == 1 else f"{base}-{k}")
        try:
            out.mkdir(parents=True, exist_ok=False)
            return out
        except FileExistsError:
            continue
        except OSError as exc:
            raise UsageError(f"cannot create the output folder {out}: {exc.strerror or exc}") from None
    raise UsageError(f"{base}: too many output folders started in this second")


def claim(opts):
    """(output folder, its lock): the folder of --resume, of -o, or a new default one, claimed
    exclusively before anything in it is checked or written."""
    if opts.get("resume"):
        out = Path(opts["resume"])
        if not out.is_dir():
            raise OutputExists(f"{out} is not a folder: nothing to resume")
        lock = _lock(out)
        if not (out / "metrics.json").is_file():
            lock.release()
            raise OutputExists(f"{out} holds no metrics.json: nothing to resume")
        return out, lock
    if opts.get("out"):
        out = Path(opts["out"])
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UsageError(f"cannot create the output folder {out}: {exc.strerror or exc}") from None
    else:
        out = _default_out()
    lock = _lock(out)
    if (out / "metrics.json").exists():
        lock.release()
        raise OutputExists(f"{out} already holds results (metrics.json); choose another --out or --resume it, "
                           "nothing was changed")
    return out, lock


def output_dir(opts):
    """The claimed output folder (its lock is held until the process ends)."""
    out, lock = claim(opts)
    _HELD.append(lock)
    return out


_HELD = []


def load_known(path):
    """The known deviations of --known (default: the repository's file); a file given but missing
    or broken is a usage error naming it."""
    if path and not Path(path).is_file():
        raise UsageError(f"--known {path}: no such file")
    try:
        return known.load(path)
    except known.KnownDeviationsError as exc:
        raise UsageError(f"known deviations: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - unreadable, not UTF-8, wrong types: named, not a traceback
        raise UsageError(f"known deviations {path or known.DEFAULT_FILE}: {type(exc).__name__}: {exc}") from None


def open_baseline(opts, out=None):
    """The previous run of --baseline (batch/verdict/baseline.py), or UsageError naming the folder:
    missing, not a run (no readable metrics.json), or the run's own output folder."""
    given = opts["baseline"]
    if out is not None and Path(given).resolve() == Path(out).resolve():
        raise UsageError(f"--baseline {given} is this run's own output folder: give the folder of a previous run")
    try:
        return baselines.Run(given)
    except run_folder.NotARun as exc:  # missing, or not a run: named by the one reader of run folders
        raise UsageError(f"--baseline {exc}") from None


def select(results, opts):
    """Filter (name, IR or error) by --scene and --case; unknown --scene names become errors."""
    names, cases = opts["scene"], opts["case"]
    chosen = [(n, r) for n, r in results
              if (not names or n in names) and (not cases or scene_sources.case_of(r) in cases
                                                  or isinstance(r, Exception))]
    for missing in sorted(set(names or []) - {n for n, _ in results}):
        from ...exporters.validate import SceneError
        chosen.append((missing, SceneError(missing, [("scene", "name", "no scene of this name in the input")])))
    return chosen


def backend_names(opts):
    return backends.expand(opts["renderer"], opts.get("renderers"))


def make_backend(name, opts):
    """The backend ``name`` (built-in or declared with --renderers) with this run's options."""
    execs = opts["exec"]
    kwargs = {"executable": execs.get(name) or (execs.get("*") if len(backend_names(opts)) == 1 else None)}
    declared = opts.get("renderers") or {}
    if name in declared:
        return backends.get(name, declaration=declared[name], **kwargs)
    kwargs.update(BACKEND_OPTIONS.get(name, lambda o: {})(opts))
    return backends.get(name, **kwargs)


# the run's options each built-in backend takes beyond its executable
BACKEND_OPTIONS = {
    "mitsuba": lambda o: {"force_variant": o["variant"], "device": o.get("device") or "auto", "film": o.get("film") or "rgb",
                          "layers": tuple(o.get("layers") or ())},
    "art": lambda o: {"ggx": bool(o["art_ggx"])},
    "cycles": lambda o: {"approximate": bool(o.get("approximate"))},
    "luxcore": lambda o: {"approximate": bool(o.get("approximate"))},
}


def plan(opts):
    """The job list [(scene name, case, backend name)] and the scenes; no rendering."""
    inputs = opts["input"] or scene_sources.default_input()
    scenes = select(scene_sources.load(inputs), opts)
    jobs = [(name, scene_sources.case_of(sc), b) for name, sc in scenes for b in backend_names(opts)]
    return jobs, scenes


class Run:
    def __init__(self, opts, out=None, deviations=None):
        """``out``: the claimed output folder (default: claim one now); ``deviations``: the known
        deviations (default: load --known)."""
        self.opts = opts
        self.out = out if out is not None else output_dir(opts)
        self.runs, self.results, self.sweeps, self.stability, self.studies = [], [], [], [], []
        self.started = _dt.datetime.now().isoformat(timespec="seconds")
        self.deviations = deviations if deviations is not None else load_known(opts.get("known"))
        self.previous = self._previous() if opts.get("resume") else {}
        self.base = open_baseline(opts, self.out) if opts.get("baseline") else None

    def _previous(self):
        """Finished results of the run being resumed, by job id (interrupted ones run again)."""
        data = planning.read_metrics(self.out)
        self.started = data.get("started", self.started)
        done = {}
        for r in (data.get("runs") or []) + (data.get("jobs") or []):
            if not isinstance(r, dict):
                continue
            image = r.get("image")
            if r.get("job") and not r.get("interrupted") and (not image or (isinstance(image, str) and (self.out / image).is_file())):
                done[r["job"]] = r
        return done

    def save(self):
        """metrics.json, rewritten atomically (batch/records.py: versioned, paths relative to OUT)."""
        records.write(self.out, self.started, self.opts, self.runs, self.results, self.sweeps, self.stability,
                      self.studies)

    def add(self, entry, quiet=False):
        if self.base is not None:  # judged against the previous run too (--baseline); the status stays
            baselines.attach(entry, self.out, self.base, planning.verdict_settings(self.opts))
        results.label_judged_by(entry)  # what judged it, in the words every reader shows (issue 44)
        self.runs.append(entry)
        self.save()
        if not quiet:
            log.info("%-8s %s / %s %s%s", entry["status"].upper(), entry["scene"], entry["backend"], entry.get("mode") or "",
                     f": {entry['reason']}" if entry.get("reason") else "")
        for p in entry.get("reference_problems") or []:  # every reference problem, with its file
            log.warning("reference problem (%s / %s): %s: %s", entry["scene"], entry["backend"], p["file"], p["problem"])

    # -- export only ------------------------------------------------------------------------
    def export_only(self, scenes):
        formats = self.opts["format"] or ["mitsuba", "art", "json"]
        rgb = {f: make_backend(f, self.opts) for f in formats if f in ("cycles", "luxcore")}
        progress = Progress(len(scenes) * len(formats))
        for name, scene in scenes:
            for fmt in formats:
                progress.show(f"{name} ({fmt})")
                if isinstance(scene, Exception):
                    self.add(planning.entry(name, scene, fmt, mode="export", status="failed", reason=str(scene)))
                else:
                    sc, target = scene, self.out / name / fmt
                    try:
                        sc = planning.for_run(scene, self.opts)
                        reason, who = "", ""
                        if fmt == "json":
                            path = ir_json.write(sc, target / f"{name}.json")
                        elif fmt == "art":
                            path, missing = art_writer.write(sc, target, ggx=bool(self.opts["art_ggx"]))
                            reason, who = "; ".join(f"{o}.{f}: {m}" for o, f, m in missing), "ART"
                        elif fmt == "pbrt":
                            path = pbrt_writer.write(sc, target)
                            reason = "; ".join(f"{o}.{f}: {m}" for o, f, m in pbrt_writer.unsupported(sc))
                            who = "pbrt-v4"
                        elif fmt in rgb:
                            mode, why = rgb[fmt].mode_for(sc)
                            if mode is None:
                                self.add(planning.entry(name, sc, fmt, mode="export", status="unsupported", reason=why))
                                progress.step(f"{name} ({fmt})")
                                continue
                            path = rgb[fmt].export(sc, target)
                        else:
                            path = backends.get("mitsuba").export(sc, target)
                        # an export that leaves something out says so: "unsupported", not "ok"
                        self.add(planning.entry(name, sc, fmt, mode="export", image=None, status="unsupported" if reason else "ok",
                                        reason=(f"{who} cannot express: {reason}" if reason else ""),
                                        export=str(path.relative_to(self.out))))
                    except Exception as exc:  # noqa: BLE001 - one bad export must not stop the batch
                        self.add(planning.entry(name, sc, fmt, mode="export", status="failed", reason=f"export failed: {exc}"))
                progress.step(f"{name} ({fmt})")

    # -- render, judge, study ----------------------------------------------------------------
    def render_all(self, scenes):
        engine = engines.make(self.opts.get("cluster"), self.deviations, timeout=self.opts.get("cluster_timeout"),
                              dashboard=self.opts.get("dashboard"))
        try:
            self._render_all(scenes, engine)
        finally:
            engine.close()

    def _render_all(self, scenes, engine):
        names = backend_names(self.opts)
        made = {n: make_backend(n, self.opts) for n in names}
        if "mitsuba" in made and made["mitsuba"].availability()[0]:
            log.info("%s", made["mitsuba"].llvm_message())
        settings = planning.verdict_settings(self.opts)
        if self.opts.get("study"):  # a study instead of the judged jobs (its own words, no reference)
            from ..studies import spectral_vs_rgb
            main, rows = spectral_vs_rgb.jobs(scenes, made, self.opts, self.out, job_mod.make, planning.for_run)
            immediate = []
            self.studies += rows
        else:
            main, immediate = planning.main_jobs(scenes, made, self.opts, self.out, settings)
        job_list = list(main)
        if self.opts["sweep"]:
            sweep_jobs, lines = planning.sweep_jobs(scenes, made, self.opts, self.out, settings)
            job_list += sweep_jobs
            self.sweeps += lines
        if self.opts["stability"]:
            from ..studies import stability  # the probes and scipy.stats: loaded when needed, not at start-up
            golden = {n: s for n, s in scenes if isinstance(s, dict)}
            self.stability = [{"sweep": s.name, "status": "skipped", "problems": [], "reason": f"needs {s.base} in the input"}
                              for s in stability.STRIPS if isinstance(s.base, str) and s.base not in golden]
            for backend in made.values():
                if backend.availability()[0]:
                    try:
                        stab_jobs, rows = stability.jobs(backend, golden, self.out, "stability", job_mod.make,
                                                        timeout=self.opts["timeout"])
                    except Exception as exc:  # noqa: BLE001 - a base scene the strips cannot use fails the study, not the batch
                        log.exception("the stability case cannot be planned on %s", backend.name)
                        stab_jobs, rows = [], [{"sweep": "stability", "backend": backend.name, "mode": None, "problems": [],
                                                "status": "failed", "reason": f"cannot be planned: {type(exc).__name__}: {exc}"}]
                    job_list += stab_jobs
                    self.stability += rows
        # the same verdict before rendering for several scenes of a backend (ART missing: every
        # scene) is one line of the log, as it is one row of the summary (batch/report/grouping.py)
        same = Counter((e["backend"], e["status"], e.get("reason") or "") for e in immediate)
        told = set()
        for entry in immediate:
            key = (entry["backend"], entry["status"], entry.get("reason") or "")
            self.add(entry, quiet=same[key] > 1)
            if same[key] > 1 and key not in told:
                told.add(key)
                log.info("%-8s %s on %d scenes: %s", key[1].upper(), key[0], same[key], key[2])
        self.done = []
        todo = []
        for j in job_list:
            previous = self.previous.get(planning.job_id(j))
            if previous is not None:
                self._keep(j, previous)
            else:
                todo.append(j)
        if self.previous:
            log.info("resuming %s: %d jobs kept, %d to run", self.out, len(job_list) - len(todo), len(todo))
        self.progress = Progress(len(todo))
        try:
            engine.map(planning.overlap_order(todo), self.record)
        finally:
            self.progress.close()
            self.finish_studies()

    def _keep(self, job, result):
        if job["kind"] == "render":
            if self.base is not None and "baseline" not in result:
                baselines.attach(result, self.out, self.base, planning.verdict_settings(self.opts))
            self.runs.append(result)
        else:
            self.results.append(result)
        self.done.append((job, result))

    def record(self, job, result):
        """One finished job (from the engine): kept, saved, reported."""
        self.done.append((job, result))
        if job["kind"] == "render":
            self.add(result)
            self.page_data(result)
        else:
            self.results.append({k: v for k, v in result.items() if k not in ("row", "point")} |
                                ({"row": result["row"]} if "row" in result else {}) |
                                ({"point": result["point"]} if "point" in result else {}))
            self.save()
        self.progress.step(f"{job['label']}: {result.get('status', '')}")

    def page_data(self, entry):
        """The report's data files of a finished render (its view.js, the scene's reference_WxH.js),
        written now, while the next jobs render, instead of all after the last one: report.html's
        writer at the end keeps them (batch/report/html.py ``_fresh``: a data file this process wrote
        from EXRs that have not changed since), so the page is the same. A failure here is left to that writer."""
        try:
            report.data_files(self.out, entry)  # only the files: the page's other parts are made at the end
        except Exception:  # noqa: BLE001 - only a head start for the report
            log.debug("the report's data of %s / %s are left to the end", entry.get("scene"), entry.get("backend"),
                      exc_info=True)

    def finish_studies(self):
        sweep_results = [(j, r) for j, r in self.done if j["kind"] == "sweep"]
        if sweep_results:
            self.sweeps += planning.sweep_lines(sweep_results)
            self.finish_sweeps()
        study_results = [(j, r) for j, r in self.done if j["kind"] == "study"]
        if study_results:
            from ..studies import spectral_vs_rgb
            self.studies += spectral_vs_rgb.finish(study_results, self.out, self.opts.get("visible_de00") or 1.0)
        stab_results = [(j, r) for j, r in self.done if j["kind"] == "stability"]
        if stab_results:
            from ..studies import stability
            self.stability += stability.finish(stab_results, self.out / "stability")
        self.save()

    def finish_sweeps(self):
        out = self.out / "sweeps"
        out.mkdir(exist_ok=True)
        for name in sorted({l["scene"] for l in self.sweeps}):
            lines = [l for l in self.sweeps if l["scene"] == name and l["points"] and "slope" in l]
            if not lines:
                continue
            floor = lines[0].get("noise_floor_rmse")
            sweep.chart(out / name, name, lines, floor)
            for l in lines:
                l["chart"] = f"sweeps/{name}.png"
            table = sweep.equal_time_and_error(lines)
            if table:
                for l in lines:
                    l["equal"] = table
        self.save()



def check_junit(path, out=None):
    """--junit FILE must be writable where it is asked for, and never one of the run's own files:
    inside the output folder ``out`` (-o or --resume) only directly in it, as a *.xml file that is
    not a link (the run writes no *.xml there). Checked before anything renders."""
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"--junit {path}: is a folder (give a file name)")
    if not path.parent.is_dir():
        raise UsageError(f"--junit {path}: no such folder {path.parent}")
    if out is None:
        return
    folder, target = Path(os.path.abspath(out)).resolve(), Path(os.path.abspath(path.parent)).resolve() / path.name
    if target.is_relative_to(folder) and (target.parent != folder or target.suffix.lower() != ".xml" or path.is_symlink()):
        raise UsageError(f"--junit {path}: inside the output folder {out}, where it would overwrite the run's own "
                         "files; give a file outside it, or a new *.xml directly in it")


def write_junit(path, batch):
    """The run's jobs as JUnit XML (batch/report/junit.py); a file that cannot be written is logged."""
    from ..report import junit
    tool = records.tool_info()
    try:
        junit.write(path, batch.runs, name=f"spectral_bench {batch.out.name}", started=batch.started,
                    properties={"run": str(batch.out), "tool.version": tool["version"] or "",
                                "tool.commit": tool["commit"] or ""})
    except OSError as exc:
        log.error("--junit %s: cannot write it: %s", path, exc.strerror or exc)


def probe_early(opts):
    """Start Mitsuba's LLVM and CUDA probes (child processes that import Mitsuba, a second or so:
    batch/backends/mitsuba/llvm.py, cuda.py) in a thread while the scenes are read and planned; whoever
    needs the answer first waits for the same probe. Nothing is started for --device cpu
    (the CUDA probe then never runs) or a run without Mitsuba."""
    import threading
    from ..backends.mitsuba import cuda, llvm
    try:
        wanted = "mitsuba" in backend_names(opts) and not opts.get("export_only")
    except Exception:  # noqa: BLE001 - a bad --renderers file is reported where it is read, not here
        return
    if wanted:
        target = llvm.find if (opts.get("device") or "auto") == "cpu" else cuda.find  # cuda.find asks llvm.find first
        threading.Thread(target=target, name="mitsuba-probe", daemon=True).start()


def check_device(opts):
    """UsageError where --device gpu cannot be honoured (Mitsuba runs and CUDA does not render here:
    batch/backends/mitsuba/cuda.py's probe says why); other devices and backends need nothing."""
    if opts.get("device") == "gpu" and "mitsuba" in backend_names(opts) and not opts.get("export_only"):
        problem = make_backend("mitsuba", opts).device_problem()
        if problem:
            raise UsageError(problem)


def run(opts):
    """Run the batch; returns the exit status (batch/verdict/status.py: 0 when every judged job
    is ok, known or fixed and nothing was left unjudged, 3 when something was unjudged, 4 when
    nothing could run (every job skipped or unsupported), 1 when something failed; 130 when
    interrupted). Raises UsageError (exit 2) for a folder that cannot be claimed, a run that
    cannot be resumed, a broken --known file, a cluster that cannot be reached. Sets opts["out"]
    to the folder used."""
    t0 = time.perf_counter()
    probe_early(opts)
    deviations = None if opts.get("resume") else load_known(opts.get("known"))
    if opts.get("junit"):
        check_junit(opts["junit"], opts.get("resume") or opts.get("out"))
    if opts.get("baseline") and not opts.get("resume"):
        open_baseline(opts, opts.get("out"))  # checked before any folder is made
    if not opts.get("resume"):
        check_device(opts)
    out, lock = claim(opts)
    opts["out"] = str(out)
    try:
        if opts.get("resume"):
            try:
                opts = planning.resumed_options(opts, getattr(opts, "given", None))
            except planning.ResumeError as exc:
                raise UsageError(str(exc)) from None
            deviations = load_known(opts.get("known"))
            check_device(opts)
            if opts.get("baseline"):
                open_baseline(opts, out)
        return _run(opts, out, deviations, t0)
    finally:
        lock.release()


def study_records(rows):
    """A study's rows as statuses of the exit code: its words (differs visibly, ...) are findings,
    not failures; a render that failed is failed, a route that could not run is skipped/unsupported."""
    return [{"status": r["status"] if r.get("status") in ("failed", "skipped", "unsupported") else "ok"} for r in rows]


def _run(opts, out, deviations, t0):
    _jobs, scenes = plan(opts)
    if not opts["export_only"] and (why := planning.scale_problem(scenes, opts.get("scale"))):
        raise UsageError(why)  # exit 2: renders the noise test could not judge
    if not opts["export_only"]:
        for chosen, moved in planning.scale_changes(scenes, opts.get("scale")):
            sizes = sorted({(size, to) for _, size, to in moved})
            log.info("--scale %g is no integer fraction of %s: %s render%s at %g (%s), the nearest scale their "
                     "reference can be box-filtered to", opts["scale"], ", ".join(f"{w}x{h}" for (w, h), _ in sizes),
                     ", ".join(n for n, _, _ in moved), "s" if len(moved) == 1 else "", chosen,
                     ", ".join(f"{w}x{h}" for _, (w, h) in sizes))
    batch = Run(opts, out, deviations)
    log.info("writing to %s", batch.out)
    for name, sc in scenes:  # what each scene's export converted or lost (a Blender scene without annotations)
        for w in (sc.get("warnings", []) if isinstance(sc, dict) else []):  # a scene that failed to load: no dict
            log.warning("conversion (%s): %s.%s: %s", name, *(t if t.isprintable() else repr(t)
                                                             for t in (w["object"], w["field"], w["message"])))
    if not scenes:
        log.error("no scene matches the selection")
        batch.save()
        return 2
    code = None
    try:
        if opts["export_only"]:
            batch.export_only(scenes)
        else:
            batch.render_all(scenes)
    except engines.Interrupted:
        log.error("interrupted: finished jobs are in %s/metrics.json; --resume %s finishes the run", batch.out, batch.out)
        code = 130
    batch.save()
    text = summary.write(batch.out, batch.runs, time.perf_counter() - t0, batch.sweeps, batch.stability, batch.studies)
    report.write(batch.out)
    print(text)
    if opts.get("junit"):
        write_junit(opts["junit"], batch)
    if code is None:
        code = status.exit_code(batch.runs + batch.stability + study_records(batch.studies))
        if code == status.EXIT_NOTHING_RAN:
            log.error("nothing was rendered: every job was skipped or unsupported (exit %d)", code)
    return code
