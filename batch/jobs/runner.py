"""The batch: scenes x backends -> exports, renders, comparisons, metrics.json, summary.

One job never takes down the batch: every failure (bad scene, crashed render, failed
comparison) becomes a run with status "failed" and a reason, and metrics.json is rewritten
after every job so that finished results survive a crash of the runner itself.
"""
import copy
import datetime as _dt
import json
import logging
import time
from pathlib import Path

import numpy as np

from ...exporters import art_writer, ir_json
from .. import backends, exr, scene_sources
from ..verdict import compare, flip_isolated, known, probes, references, status
from ..report import html as report, previews, summary
from ..studies import sweep
from .progress import Progress

log = logging.getLogger("spectral_bench")


class OutputExists(RuntimeError):
    pass


def output_dir(opts):
    out = Path(opts["out"] or _dt.datetime.now().strftime("outputs-%Y%m%d-%H%M%S"))
    if (out / "metrics.json").exists():
        raise OutputExists(f"{out} already holds results (metrics.json); choose another --out, nothing was changed")
    out.mkdir(parents=True, exist_ok=True)
    return out


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
    return list(opts["renderer"] or backends.BACKENDS)


def make_backend(name, opts):
    execs = opts["exec"]
    kwargs = {"executable": execs.get(name) or (execs.get("*") if len(backend_names(opts)) == 1 else None)}
    if name == "mitsuba":
        kwargs["force_variant"] = opts["variant"]
    if name == "art":
        kwargs["ggx"] = bool(opts["art_ggx"])
    if name in ("cycles", "luxcore"):
        kwargs["approximate"] = bool(opts.get("approximate"))
    return backends.get(name, **kwargs)


def plan(opts):
    """The job list [(scene name, case, backend name)] and the scenes; no rendering."""
    inputs = opts["input"] or scene_sources.default_input()
    scenes = select(scene_sources.load(inputs), opts)
    jobs = [(name, scene_sources.case_of(sc), b) for name, sc in scenes for b in backend_names(opts)]
    return jobs, scenes


def for_run(scene, opts):
    """The scene with --spp and --scale applied."""
    sc = copy.deepcopy(scene)
    if opts["spp"]:
        sc["render"]["spp"] = int(opts["spp"])
    if opts["scale"] and opts["scale"] != 1.0:
        sc["render"]["width"] = max(1, round(sc["render"]["width"] * opts["scale"]))
        sc["render"]["height"] = max(1, round(sc["render"]["height"] * opts["scale"]))
    return sc


def _entry(name, scene, backend, **kw):
    e = {"scene": name, "case": scene_sources.case_of(scene), "backend": backend, "mode": None,
         "status": "ok", "reason": "", "spp": None, "resolution": None, "time_s": None, "image": None,
         "metrics": {"rmse": None, "relmse": None, "mape": None, "flip": None}, "probes": []}
    e.update(kw)
    return e


class Run:
    def __init__(self, opts):
        self.opts = opts
        self.out = output_dir(opts)
        self.runs = []
        self.sweeps = []
        self.started = _dt.datetime.now().isoformat(timespec="seconds")
        self.deviations = known.load(opts.get("known"))

    def save(self):
        data = {"started": self.started, "options": {k: v for k, v in self.opts.items() if k != "exec"},
                "runs": self.runs}
        if self.sweeps:
            data["sweeps"] = self.sweeps
        if getattr(self, "stability", None):
            data["stability"] = self.stability
        tmp = self.out / "metrics.json.tmp"
        tmp.write_text(json.dumps(data, indent=1, default=str) + "\n")
        tmp.replace(self.out / "metrics.json")

    def add(self, entry):
        self.runs.append(entry)
        self.save()
        status = entry["status"].upper()
        log.info("%-8s %s / %s %s%s", status, entry["scene"], entry["backend"], entry.get("mode") or "",
                 f": {entry['reason']}" if entry["reason"] else "")

    # -- export only ------------------------------------------------------------------------
    def export_only(self, scenes):
        formats = self.opts["format"] or ["mitsuba", "art", "json"]
        rgb = {f: make_backend(f, self.opts) for f in formats if f in ("cycles", "luxcore")}
        progress = Progress(len(scenes) * len(formats))
        for name, scene in scenes:
            for fmt in formats:
                progress.show(f"{name} ({fmt})")
                if isinstance(scene, Exception):
                    self.add(_entry(name, scene, fmt, mode="export", status="failed", reason=str(scene)))
                else:
                    sc = for_run(scene, self.opts)
                    target = self.out / name / fmt
                    try:
                        reason = ""
                        if fmt == "json":
                            path = ir_json.write(sc, target / f"{name}.json")
                        elif fmt == "art":
                            path, missing = art_writer.write(sc, target, ggx=bool(self.opts["art_ggx"]))
                            reason = "; ".join(f"{o}.{f}: {m}" for o, f, m in missing)
                        elif fmt in rgb:
                            mode, why = rgb[fmt].mode_for(sc)
                            if mode is None:
                                self.add(_entry(name, sc, fmt, mode="export", status="unsupported", reason=why))
                                progress.step(f"{name} ({fmt})")
                                continue
                            path = rgb[fmt].export(sc, target)
                        else:
                            path = backends.get("mitsuba").export(sc, target)
                        # an export that leaves something out says so: "unsupported", not "ok"
                        self.add(_entry(name, sc, fmt, mode="export", image=None, status="unsupported" if reason else "ok",
                                        reason=(f"ART cannot express: {reason}" if reason else ""),
                                        export=str(path.relative_to(self.out))))
                    except Exception as exc:  # noqa: BLE001 - one bad export must not stop the batch
                        self.add(_entry(name, sc, fmt, mode="export", status="failed", reason=f"export failed: {exc}"))
                progress.step(f"{name} ({fmt})")

    # -- render and compare -----------------------------------------------------------------
    def render_all(self, scenes):
        names = backend_names(self.opts)
        made = {n: make_backend(n, self.opts) for n in names}
        llvm_said = False
        progress = Progress(len(scenes) * len(names))
        for name, scene in scenes:
            for bname in names:
                progress.show(f"{name} ({bname})")
                backend = made[bname]
                if isinstance(scene, Exception):
                    self.add(_entry(name, scene, bname, status="failed", reason=str(scene)))
                    progress.step(f"{name} ({bname})")
                    continue
                ok, why = backend.availability()
                if not ok:
                    self.add(_entry(name, scene, bname, status="skipped", reason=why))
                    progress.step(f"{name} ({bname})")
                    continue
                if bname == "mitsuba" and not llvm_said:
                    log.info("%s", backend.llvm_message())
                    llvm_said = True
                try:
                    self.add(self.render_one(name, scene, backend))
                except Exception as exc:  # noqa: BLE001 - one crashed job must not stop the batch
                    log.exception("job %s / %s crashed", name, bname)
                    self.add(_entry(name, scene, bname, status="failed", reason=f"internal error: {exc!r}"))
                if self.opts["sweep"]:
                    self.sweep_one(name, scene, backend)
                progress.step(f"{name} ({bname})")
        if self.opts["sweep"]:
            self.finish_sweeps()
        if self.opts["stability"]:
            self.run_stability(scenes, made)

    def run_stability(self, scenes, made):
        from ..studies import stability
        golden = {n: s for n, s in scenes if isinstance(s, dict)}
        self.stability = [{"sweep": s.name, "status": "skipped", "problems": [],
                           "reason": f"needs {s.base} in the input"}
                          for s in stability.STRIPS if isinstance(s.base, str) and s.base not in golden]
        for backend in made.values():
            if backend.availability()[0]:
                self.stability += stability.run(backend, golden, self.out / "stability", timeout=self.opts["timeout"])
        self.save()

    def sweep_one(self, name, scene, backend):
        """Render ``scene`` over the ladder for each mode of ``backend``; errors against the reference."""
        ladder = self.opts["ladder"] or list(sweep.DEFAULT_LADDER)
        sc = for_run(scene, dict(self.opts, spp=None))
        modes, why = sweep.sweep_modes(backend, sc, self.opts["sweep_modes"])
        ref, broken = self.reference(name, scene)
        unusable = broken or references.check_usable(ref, scene)
        if not modes or unusable:
            self.sweeps.append({"scene": name, "backend": backend.name, "mode": None, "points": [],
                                "reason": why or unusable})
            return
        folder = self.out / name / "sweeps"
        scene_dir = backend.export(sc, folder / "export" / backend.name)
        for mode in modes:
            line = {"scene": name, "backend": backend.name, "mode": mode, "points": [], "reason": ""}
            try:
                for spp in ladder:
                    image = folder / f"{backend.name}-{mode}" / f"spp{spp}.exr"
                    image.parent.mkdir(parents=True, exist_ok=True)
                    info = backend.render(scene_dir, mode, spp, image, passes=2, seed=self.opts["seed"],
                                          timeout=self.opts["timeout"])
                    names, img, stderr = exr.read_image_and_stderr(image)
                    at = compare.reference_at(ref.mean, ref.stderr, ref.spp, img.shape, ref.provenance.get("passes", 8))
                    point = {"spp": info["spp"], "time_s": info["time_s"], "wall_s": info["wall_s"]}
                    point.update(compare.metrics(img[..., :3], at.mean[..., :3]))
                    if stderr is not None and names == ref.names:
                        zt = compare.z_test(img, at, info["spp"], own_var_of_mean=stderr.astype(np.float64) ** 2,
                                            own_passes=2, alpha=self.opts["alpha"], min_samples=self.opts["min_samples"])
                        point["test"] = zt.as_dict()
                    line["points"].append(point)
                line.update(sweep.analyse(line["points"], at.sigma2[..., :3], at.var_of_mean[..., :3]))
            except Exception as exc:  # noqa: BLE001 - a failing mode must not stop the sweep
                line["reason"] = f"sweep failed: {exc}"
            self.sweeps.append(line)
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

    def reference(self, name, scene):
        """(reference or None, why it cannot judge or None); a broken reference file is a reason."""
        try:
            ref = references.load(name, self.opts["references"], scene=scene)
        except Exception as exc:  # noqa: BLE001 - a bad reference must not stop the batch
            return None, f"reference unreadable: {exc}"
        return ref, None

    def render_one(self, name, scene, backend):
        sc = for_run(scene, self.opts)
        r = sc["render"]
        entry = _entry(name, sc, backend.name, spp=r["spp"], resolution=[r["width"], r["height"]])
        mode, why = backend.mode_for(sc)
        if mode is None:
            entry.update(status="unsupported", reason=why)
            return entry
        entry["mode"] = mode
        ir_json.write(sc, self.out / name / "json" / f"{name}.json")
        xml = backend.export(sc, self.out / name / backend.formats[0])
        res_dir = self.out / name / "results" / backend.name
        res_dir.mkdir(parents=True, exist_ok=True)
        image = res_dir / "render.exr"
        try:
            info = backend.render(xml, mode, r["spp"], image, passes=self.opts["passes"], seed=self.opts["seed"],
                                  timeout=self.opts["timeout"], log_path=res_dir / "render.log")
        except backends.BackendFailure as exc:
            entry.update(status="failed", reason=f"render failed: {exc}")
            return entry
        entry.update(time_s=info["time_s"], wall_s=info["wall_s"], spp=info["spp"], passes=info.get("passes", 1),
                     image=str(image.relative_to(self.out)), versions=info.get("versions"))
        if info.get("approximated"):
            entry["approximated"] = info["approximated"]  # what an -approx mode rendered differently
        names, test_all, stderr = exr.read_image_and_stderr(image)
        entry["channels"] = names
        entry["sanity"] = compare.image_sanity(test_all)
        if entry["sanity"]["negative"]:
            # negative linear sRGB can be a legitimate out-of-gamut colour; negative S0 never is
            entry["flags"] = [f"{entry['sanity']['negative']} negative values"]
        previews.save_linear(res_dir / "render.png", test_all[..., :3])
        ref, broken = self.reference(name, scene)
        unusable = broken or references.check_usable(ref, scene)
        ztest = None
        if unusable:
            entry["reference_problem"] = unusable
        else:
            ztest = self.compare(entry, ref, names, test_all, stderr, res_dir)
        observers = sorted({d.observer for d in known.applicable(self.deviations, entry) if d.observer})
        entry["probes"] = probes.evaluate(sc, names, test_all, reference=None if unusable else ref, stderr=stderr,
                                          passes=entry["passes"], observers=observers)
        if unusable and not any(p["pass"] is not None for p in entry["probes"]):
            entry["unjudged_because"] = unusable + ("" if entry["probes"] else "; no analytic probe applies")
        status.decide(entry, self.deviations, ztest)
        return entry

    def compare(self, entry, ref, names, test_all, stderr, res_dir):
        """The noise test against the reference, on the render's own noise (entry["test"]); the
        diff, z-score and FLIP images. Returns the in-memory test (for re-judging) or None."""
        test = test_all[..., :3]
        entry["reference"] = {"path": str(ref.path), "spp": ref.spp, "backend": ref.provenance.get("backend"),
                              "mode": ref.provenance.get("mode"), "versions": ref.provenance.get("versions"),
                              "date": ref.provenance.get("date")}
        if names != ref.names:
            entry["test"] = {"pass": False, "reason": f"render channels {names} differ from the reference's {ref.names}"}
            return None
        try:
            at = compare.reference_at(ref.mean, ref.stderr, ref.spp, test_all.shape, ref.provenance.get("passes", 8))
        except ValueError as exc:
            entry["test"] = {"pass": None, "reason": f"cannot compare with the reference: {exc}"}
            return None
        mean = at.mean[..., :3]
        entry["metrics"].update(compare.metrics(test, mean))
        same = (entry["backend"], entry["mode"]) == (ref.provenance.get("backend"), ref.provenance.get("mode"))
        if stderr is None and not same:
            entry["test"] = {"pass": None, "reason": (
                "one pass: the render has no per-pixel noise of its own and another renderer's is not "
                "borrowed (render with --passes >= 2)")}
            zt = None
        else:
            # every channel is judged: R, G, B and, for Stokes output, S0..S3
            own = None if stderr is None else stderr.astype(np.float64) ** 2
            zt = compare.z_test(test_all, at, entry["spp"], own_var_of_mean=own, own_passes=entry["passes"],
                                alpha=self.opts["alpha"], block=self.opts["block"], min_samples=self.opts["min_samples"])
            entry["test"] = zt.as_dict()
            if not zt.passed:
                entry["test"]["reason"] = (
                    f"differs from the reference beyond noise: min p = {zt.p_min:.3g} < {zt.threshold:.3g} "
                    f"(alpha {zt.alpha} Sidak-corrected over {zt.blocks} tests), max |z| = {zt.z_max:.1f}")
            exr.write(res_dir / "zscore.exr", zt.zmap[..., :3])
            worst = np.take_along_axis(zt.zmap, np.abs(zt.zmap).argmax(axis=-1)[..., None], axis=-1)[..., 0]
            previews.save_signed(res_dir / "zscore.png", worst, scale=6)
        exr.write(res_dir / "reference.exr", mean)
        exr.write(res_dir / "diff_abs.exr", np.abs(test - mean))
        exr.write(res_dir / "diff_rel.exr", np.abs(test - mean) / (np.abs(mean) + compare.REL_EPS))
        previews.save_linear(res_dir / "reference.png", mean)
        previews.save_signed(res_dir / "diff.png", (test - mean).mean(axis=-1),
                             scale=max(float(np.percentile(np.abs(mean), 99)), 1e-6) * 0.25)
        if self.opts["flip"]:
            flip, err = flip_isolated.hdr_flip(res_dir / "reference.exr", self.out / entry["image"], res_dir / "flip.exr")
            entry["metrics"]["flip"] = flip
            if err:
                entry["flip_error"] = err
            elif (res_dir / "flip.exr").exists():
                previews.save_gray(res_dir / "flip.png", exr.read_rgb(res_dir / "flip.exr")[..., 0])
        return zt


def run(opts):
    """Run the batch; returns the exit status (batch/verdict/status.py: 0 when every judged job
    is ok, known or fixed and nothing was left unjudged, 3 when something was unjudged, 1 when
    something failed)."""
    t0 = time.perf_counter()
    _jobs, scenes = plan(opts)
    batch = Run(opts)
    log.info("writing to %s", batch.out)
    if not scenes:
        log.error("no scene matches the selection")
        batch.save()
        return 2
    if opts["export_only"]:
        batch.export_only(scenes)
    else:
        batch.render_all(scenes)
    text = summary.write(batch.out, batch.runs, time.perf_counter() - t0, batch.sweeps,
                         getattr(batch, "stability", None))
    report.write(batch.out)
    print(text)
    return status.exit_code(batch.runs + getattr(batch, "stability", []))
