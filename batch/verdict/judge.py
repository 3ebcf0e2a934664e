"""The verdict of one render: from its EXR (mean and, with passes, per-pixel standard error) to a
job record with metrics, the noise test against the scene's reference, the analytic probes, the
images a reader looks at (previews, differences, z-score, FLIP, the GGX probe's residuals) and a status
(batch/verdict/status.py). A function of files and settings: it never renders.
"""
from pathlib import Path, PurePosixPath

import numpy as np

from .. import exr
from .. import previews
from .. import spectral_passes
from . import compare, crosscheck, flip_isolated, known, observer_layers, probes, references, stats, status
from .probes import bands as band_probes


def find_reference(name, scene, directories, shape=None, names=None):
    """(usable reference or None, why there is none or None, the problems of every candidate
    passed over: [{"file", "problem"}]). Every folder's candidate is checked for a render of
    ``shape`` with channels ``names`` (batch/verdict/references.py ``search``); a broken one is
    a problem of its file and never stops the batch."""
    try:
        found = references.search(name, directories, scene=scene, shape=shape, names=names)
    except Exception as exc:  # noqa: BLE001 - a bad reference must not stop the batch
        return None, f"no usable reference: the search failed: {exc}", []
    if found.ref is not None:
        return found.ref, None, found.problems
    if found.problems:
        shown = "; ".join(f"{p['file']}: {p['problem']}" for p in found.problems)
        return None, f"no usable reference ({shown})", found.problems
    folders = ", ".join(str(d) for d in references.directories(directories))
    return None, f"no reference for this scene (searched {folders})", []


def load_reference(name, scene, directories, shape=None, names=None):
    """(usable reference or None, why there is none or None): find_reference without the list."""
    ref, unusable, _problems = find_reference(name, scene, directories, shape, names)
    return ref, unusable


PROBES_ALONE = "judged by probes alone"
# Why a judged render has no FLIP (metrics.json ``flip_not_computed``; batch/records.flip_text says it).
# Issue 45: an ok render differs from its reference by noise, and a perceptual map of noise tells
# nothing the z-score map does not, so --flip auto (the default) computes FLIP where a verdict is not ok.
FLIP_OK = "verdict ok; --flip on computes it"
FLIP_OFF = "--flip off"


def render_verdict(entry, scene, rendered, image, res_dir, settings, deviations):
    """Judge the render ``image`` of ``rendered`` (the scene as rendered: spp and scale applied;
    ``scene`` as authored, for its reference) in place in ``entry``; writes the verdict's images
    into ``res_dir``. ``settings``: alpha, min_samples, block, flip (True, False or "auto": FLIP only
    for a verdict that is not ok), references."""
    if settings.get("flip", "auto") is True:
        flip_isolated.prestart()  # the FLIP child starts (once) while this verdict reads and tests
    names, test_all, stderr = exr.read_image_and_stderr(image)
    entry["channels"] = names
    entry["sanity"] = compare.image_sanity(test_all)
    if entry["sanity"]["negative"]:
        # negative linear sRGB can be a legitimate out-of-gamut colour; negative S0 never is
        entry["flags"] = [f"{entry['sanity']['negative']} negative values"]
    ref, unusable, problems = find_reference(entry["scene"], scene, settings.get("references"),
                                             shape=test_all.shape, names=names)
    entry["reference_problems"] = problems
    ztest = None
    later = []  # FLIP, computing in its child while the probes run here
    auto = []  # --flip auto: FLIP's start, made once the status is known
    maps = {}
    held = {}  # what the noise test compared (the diagnosis fits its models on it)
    try:
        if unusable:
            entry["reference_problem"] = unusable
        else:
            ztest = noise_test(entry, ref, names, test_all, stderr, res_dir, image, settings, later, auto, held,
                               deviations=deviations)
        observers = sorted({d.observer for d in known.applicable(deviations, entry) if d.observer})
        spectral = _spectral_bands(entry, Path(image).parent)
        entry["probes"] = probes.evaluate(rendered, names, test_all, reference=None if unusable else ref,
                                          stderr=stderr, passes=entry["passes"], observers=observers, maps=maps,
                                          spectral=spectral)
        if spectral is not None:
            entry["bands"] = band_probes.record(entry["probes"], spectral)
        previews.write_probe_residual(res_dir, maps.get("residual_map"))  # the report's "probe residual" view
    except BaseException:
        for finish in later:  # a verdict that breaks still collects its FLIP (its child is free for the next)
            finish()
        raise
    for finish in later:  # FLIP, now or (the default engine: flip_isolated.deferred) after this verdict
        if not flip_isolated.defer(finish):
            finish()
    if unusable and not any(p["pass"] is not None for p in entry["probes"]):
        entry["unjudged_because"] = unusable + ("" if entry["probes"] else "; no analytic probe applies")
    status.decide(entry, deviations, ztest)
    worst = [p["worst"]["text"] for p in entry["probes"] if p["name"].startswith(band_probes.PREFIX) and p["pass"] is False]
    if worst and entry["status"] == "failed":  # where the spectrum is wrong, in the reason the terminal shows
        entry["reason"] += "; worst bands: " + "; ".join(worst[:4]) + (f" and {len(worst) - 4} more" if len(worst) > 4 else "")
    if auto and entry["status"] == "ok":  # --flip auto: an ok render differs from its reference by noise
        entry["flip_not_computed"] = FLIP_OK
    bands = [p for p in entry["probes"] if p["name"].startswith(band_probes.PREFIX)]
    unjudged = [p["unjudged_text"] for p in bands if p.get("unjudged_text")]
    if unjudged:  # said, never failed: bands with too few samples for their noise (probes/bands.py)
        entry["reason"] = ((entry["reason"] + "; ") if entry.get("reason") else "") + (
            f"bands not judged in {len(unjudged)} of {len(bands)} band checks: {unjudged[0]}"
            + (f" and {len(unjudged) - 1} more" if len(unjudged) > 1 else ""))
    if auto and entry["status"] != "ok":  # --flip auto: the error map where the verdict is not ok
        finishers = []
        for start in auto:
            start(finishers)
        for finish in finishers:
            if not flip_isolated.defer(finish):
                finish()
    det = detectable(ztest, entry["probes"], settings.get("alpha"))
    if det is not None:
        entry["detectable"] = det
    if unusable and entry["status"] != "unjudged" and not entry["reason"].startswith(PROBES_ALONE):
        # judged, but without the reference: the reason says so whatever the status
        entry["reason"] = f"{PROBES_ALONE}: {unusable}" + (f"; {entry['reason']}" if entry["reason"] else "")
    if entry["status"] in DIAGNOSED:
        diagnose(entry, rendered, names, test_all, stderr, held, ztest, res_dir)
    return entry


def _spectral_bands(entry, folder):
    """A spectral render's bands (batch/spectral_passes.py), read once and their large file removed
    (the preview stays); None for a render without them. The entry keeps what they were."""
    record = entry.pop("spectral", None)
    got = spectral_passes.read(folder, record, remove=True) if record else None
    if got is None:
        return None
    wl, mean, stderr, meta = got
    return dict(meta, wavelengths_nm=wl, mean=mean, stderr=stderr, preview=record.get("preview"),
                source=record.get("source", "declared"))


DIAGNOSED = ("failed", "known", "fixed")  # a passing render is never diagnosed


def diagnose(entry, rendered, names, image, stderr, held, ztest, res_dir):
    """The error models fitted to a failing (or known/fixed) render (batch/verdict/diagnosis/):
    ``entry["diagnosis"]``, the reason's "likely: ..." (a failed render's) or "no model explains
    it", and the reference as the likely model predicts the render (``diagnosis_model.exr``,
    linked from the report's "why" box) where that model fits the reference evidence. Advice
    only: the status stays; a diagnosis that breaks is recorded as its error, never raised. A
    known or fixed render gets the quick models only (batch/verdict/diagnosis/ ``diagnose``)."""
    from . import diagnosis
    try:
        ev = diagnosis.Evidence(entry, rendered, names, image, stderr, entry.get("passes"), held.get("at"),
                                ztest, held.get("picked"))
        found = diagnosis.diagnose(ev, quick=entry["status"] != "failed")
    except Exception as exc:  # noqa: BLE001 - advice must never take the verdict down
        entry["diagnosis"] = {"criterion": diagnosis.CRITERION, "models": [], "likely": None,
                              "text": "no diagnosis", "errors": [{"model": "*", "error": f"{type(exc).__name__}: {exc}"[:300]}]}
        return
    best = found.pop("_best_fit", None)
    if best is not None and best.corrected is not None and found["likely"]:
        previews.write_half(res_dir / diagnosis.CORRECTED, best.corrected[..., :3])
        found["image"] = str(res_dir / diagnosis.CORRECTED)
    entry["diagnosis"] = found
    if entry["status"] == "failed":
        entry["reason"] = f"{entry['reason']}; {found['text']}"


# Probes whose expected values are radiances (or a ratio to them, expected 1): a uniform radiance
# scale error 1 + eps multiplies what they expect, so they count towards ``detectable.scale``.
# Band positions, degrees of polarisation and a film relative to its environment do not change
# under a uniform scale: they keep their own figure only.
RADIANCE_PROBES = ("lambert ", "ggx ", "beckmann ", "brewster ", "reflection ", "prism energy", "lone ",
                   "environment seen directly", "furnace ")


def detectable(ztest, probe_records, alpha=None):
    """The run's power (metrics.json ``detectable``): the smallest relative uniform radiance scale
    error the noise test detects with 90 % power (batch/verdict/compare.py ``ZTest.detectable``),
    each probe's own figure (the smallest relative change of what it measures that its best test
    detects with 90 % power: batch/verdict/stats.py ``detectable_scale``; for an interval probe,
    its width plus how far beyond it a mean fails) and, for the charts, the
    dE00 of the largest of the patches' figures applied as a brightness change to that patch
    (``patch_de00``: any single patch changed that much in brightness is detected with 90 % power).
    None when nothing could be judged."""
    out = ztest.detectable() if ztest is not None else None
    figures, patches = {}, []
    for p in probe_records or []:
        if p.get("pass") is None:
            continue
        if not p.get("stat"):
            # an interval probe (probes/floor_sphere.py): a change of the truth that surely fails
            # must cross the interval's width and then its figure beyond it
            if isinstance(p.get("detectable"), float) and isinstance(p.get("width"), float):
                figures[p["name"]] = p["width"] + p["detectable"]
            continue
        eps = stats.detectable_scale(p["stat"])
        figures[p["name"]] = eps
        if eps is not None and p["name"].startswith("lambert patch") and p.get("unit") == "dE00":
            patches.append((eps, p["stat"]["expected"]))
    if out is None and not figures:
        return None
    if out is None:
        out = {"scale": None, "alpha": alpha, "power": compare.POWER, "by": None, "tests": {},
               "method": "no noise test (no usable reference): the radiance probes' own figures"}
    radiance = {k: v for k, v in figures.items() if v is not None and k.startswith(RADIANCE_PROBES)}
    if radiance:
        best = min(radiance, key=radiance.get)
        if out["scale"] is None or radiance[best] < out["scale"]:
            out.update(scale=radiance[best], by=best)
        out["method"] += "; or a probe of radiance, its best test (whichever check needs the least)"
    if figures:
        out["probes"] = figures
    if patches and all(e is not None for e, _ in patches):
        from ...exporters import colorimetry
        eps, expected = max(patches, key=lambda t: t[0])
        e = np.asarray(expected, dtype=np.float64)
        white = colorimetry.srgb_to_xyz(np.ones(3))
        out["patch_de00"] = float(colorimetry.delta_e_2000(colorimetry.lab(colorimetry.srgb_to_xyz(e * (1 + eps)), white),
                                                           colorimetry.lab(colorimetry.srgb_to_xyz(e), white)))
    return out


def noise_test(entry, ref, names, test_all, stderr, res_dir, image, settings, later=None, auto=None, held=None,
               deviations=None):
    """The noise test against the reference, on the render's own noise (entry["test"]); the
    diff, z-score and FLIP images. Returns the in-memory test (for re-judging) or None.
    ``later``: a list that receives what finishes FLIP (call it), which then computes meanwhile;
    None: FLIP is waited for here. With ``settings["flip"] == "auto"``, ``auto`` receives FLIP's
    start instead (call it with a list for its finisher, once the status says FLIP is wanted).
    ``held``: a dict that receives what was compared (the reference at this resolution ``at``;
    ``picked``: the shared channel names, the render and its standard error on them), for the
    diagnosis. ``deviations``: the run's known deviations; a cross-check of the reference that agreed
    only under one counts while that one is still recorded with the same model (crosscheck.counting)."""
    layers, bad_layers = observer_layers.check(ref)
    entry["reference"] = {"path": str(ref.path), "spp": ref.spp, "backend": ref.provenance.get("backend"),
                          "mode": ref.provenance.get("mode"), "versions": ref.provenance.get("versions"),
                          "date": ref.provenance.get("date"), "observer": observer_layers.own_observer(ref.provenance),
                          "observer_layers": sorted(layers)}
    # issue 44: the reference's cross-checks by other renderers that belong to this very image count
    counted, stale = crosscheck.counting(ref.provenance, deviations)
    if counted:
        entry["reference"]["crosschecks"] = [crosscheck.summary(c) for c in counted]
    if stale:
        entry["reference"]["crosschecks_not_counted"] = [
            f"{crosscheck.renderer_label(c.get('renderer'), c.get('version'))} ({str(c.get('date'))[:10]}): {why}"[:300]
            for c, why in stale]
    if bad_layers:  # an unusable layer: a reference problem of its file; the reference itself is used
        entry["reference"]["observer_layers_problem"] = "; ".join(why for _f, why in bad_layers.values())
        entry.setdefault("reference_problems", []).extend(observer_layers.reference_problems(ref, bad_layers))
    # judged on the channels both have (a renderer may add Stokes channels the reference lacks)
    shared = [n for n in ref.names if n in names]
    if shared[:3] != ["R", "G", "B"]:
        entry["test"] = {"pass": False, "reason": f"render channels {names} lack the reference's colour {ref.names}"}
        return None
    if shared != names or shared != ref.names:
        entry["channels_without_reference"] = [n for n in names if n not in shared]
        entry["channels_not_rendered"] = [n for n in ref.names if n not in shared]
        pick, ref_pick = [names.index(n) for n in shared], [ref.names.index(n) for n in shared]
        test_all = test_all[..., pick]
        stderr = None if stderr is None else stderr[..., pick]
        ref_mean, ref_stderr = ref.mean[..., ref_pick], None if ref.stderr is None else ref.stderr[..., ref_pick]
    else:
        ref_mean, ref_stderr = ref.mean, ref.stderr
    test = test_all[..., :3]
    try:
        at = compare.reference_at(ref_mean, ref_stderr, ref.spp, test_all.shape, ref.provenance.get("passes", 8),
                                  observer_layers.offsets(ref, len(shared), layers))
    except ValueError as exc:
        entry["test"] = {"pass": None, "reason": f"cannot compare with the reference: {exc}"}
        return None
    mean = at.mean[..., :3]
    if held is not None:
        held.update(at=at, picked=(shared, test_all, stderr))
    entry["metrics"].update(compare.metrics(test, mean))
    same = (entry["backend"], entry["mode"]) == (ref.provenance.get("backend"), ref.provenance.get("mode"))
    zt = None
    if stderr is None and not same:
        entry["test"] = {"pass": None, "reason": (
            "one pass: the render has no per-pixel noise of its own and another renderer's is not "
            "borrowed (render with --passes >= 2)")}
    else:
        # every channel is judged: R, G, B and, for Stokes output, S0..S3
        own = None if stderr is None else stderr.astype(np.float64) ** 2
        zt = compare.z_test(test_all, at, entry["spp"], own_var_of_mean=own, own_passes=entry["passes"],
                            alpha=settings["alpha"], block=settings.get("block"),
                            min_samples=compare.min_samples_for(entry["scene"], settings["min_samples"]))
        entry["test"] = zt.as_dict()
        if not zt.passed:
            from ..records import noise_test_failure  # the part that failed, with its own figures
            entry["test"]["reason"] = (f"differs from the reference beyond noise (alpha {zt.alpha}, Sidak-corrected "
                                       f"over {zt.blocks} blocks): {noise_test_failure(entry['test'])}")
        previews.write_half(res_dir / "zscore.exr", zt.zmap[..., :3])
        previews.write_half(res_dir / previews.BLOCK_STDERR, zt.semap[..., :3])
    # issue 21: the reader's images kept small (batch/previews.py): one half-float reference per
    # scene and resolution, shared by its backends; no difference images (the page and the panel compute them)
    shared = previews.shared_reference(res_dir, mean, np.sqrt(at.var_of_mean[..., :3]))
    entry["reference"]["image"] = str(PurePosixPath(entry["image"]).parent.parent / shared.name) \
        if isinstance(entry.get("image"), str) else None
    flip = settings.get("flip", "auto")
    if flip is True:
        _start_flip(entry, mean, test, res_dir, later)
    elif flip == "auto" and auto is not None:
        auto.append(lambda finishers: _start_flip(entry, mean, test, res_dir, finishers))
    elif flip is False:
        entry["flip_not_computed"] = FLIP_OFF
    return zt


def _start_flip(entry, mean, test, res_dir, later):
    """The warm FLIP child (flip_isolated.py) gets the arrays in hand (no temporary reference file,
    no re-reading of the render) and writes the map as half floats; it computes while this thread
    goes on (the probes) when the caller collects it later (``later``), else it is waited for."""
    pending = flip_isolated.start(mean, test, res_dir / "flip.exr")  # nothing below can raise before it is collected
    if later is not None:
        later.append(lambda: _flip_result(entry, pending))
    else:
        _flip_result(entry, pending)


def _flip_result(entry, pending):
    flip, err = pending.result()
    entry["metrics"]["flip"] = flip
    if err:
        entry["flip_error"] = err


def look(scene_name, scene, rendered, backend, mode, spp, passes, image, res_dir, settings, alpha):
    """One look of ``--detect`` (batch/verdict/sequential.py): the noise test of the render
    ``image`` at ``alpha``, judged as the final verdict judges it (``noise_test``, without FLIP),
    and the run's detectable scale error (``detectable``: the noise test's or a radiance probe's,
    whichever is smaller; the probes count for power only, their verdict is the final image's).
    Returns (passed, or None when the render is not judged by the noise test; detectable or None)."""
    names, img, stderr = exr.read_image_and_stderr(image)
    ref, unusable, _problems = find_reference(scene_name, scene, settings.get("references"), shape=img.shape, names=names)
    if unusable:
        return None, None
    entry = {"scene": scene_name, "backend": backend, "mode": mode, "spp": spp, "passes": passes, "metrics": {},
             "image": None}
    zt = noise_test(entry, ref, names, img, stderr, res_dir, image, dict(settings, alpha=alpha, flip=False))
    if zt is None:
        return None, None
    found = probes.evaluate(rendered, names, img, reference=ref, stderr=stderr, passes=passes)
    det = detectable(zt, found, alpha)
    return bool(zt.passed), None if det is None else det["scale"]


def sweep_point(job, record):
    """One rung of a sweep: time, error against the reference and the noise test on the rung's
    own noise (two passes)."""
    scene = job["source_scene"]
    names, img, stderr = exr.read_image_and_stderr(record["image_path"])
    ref, unusable, problems = find_reference(job["scene_name"], scene, job["verdict"].get("references"),
                                             shape=img.shape, names=names)
    point = {"spp": record["spp"], "time_s": record["time_s"], "wall_s": record["wall_s"]}
    if unusable:
        if problems:
            point["reference_problems"] = problems
        point["reason"] = unusable
        return point
    layers, bad_layers = observer_layers.check(ref)
    problems = list(problems) + observer_layers.reference_problems(ref, bad_layers)
    if problems:
        point["reference_problems"] = problems
    at = compare.reference_at(ref.mean, ref.stderr, ref.spp, img.shape, ref.provenance.get("passes", 8),
                              observer_layers.offsets(ref, img.shape[-1], layers))
    point.update(compare.metrics(img[..., :3], at.mean[..., :3]))
    point["predicted_rmse"] = float(np.sqrt(np.mean(at.sigma2[..., :3]) / record["spp"] + np.mean(at.var_of_mean[..., :3])))
    point["noise_floor_rmse"] = float(np.sqrt(np.mean(at.var_of_mean[..., :3])))
    if stderr is not None and names == ref.names:
        zt = compare.z_test(img, at, record["spp"], own_var_of_mean=stderr.astype(np.float64) ** 2,
                            own_passes=record["passes"], alpha=job["verdict"]["alpha"],
                            min_samples=compare.min_samples_for(job["scene_name"], job["verdict"]["min_samples"]))
        point["test"] = zt.as_dict()
        if not zt.passed:  # a rung that fails exactly as a recorded deviation says (its film) converges to that
            entry = {"scene": job["scene_name"], "backend": job["backend"], "mode": job["mode"],
                     "versions": record.get("versions"), "film": (job.get("backend_options") or {}).get("film")}
            point["test"]["known"] = sorted(d.id for d in known.applicable(known.load(job["verdict"].get("known")), entry)
                                            if d.explains("noise test") and not d.shadowing
                                            and zt.rejudge(d.scale, d.scale_se, d.observer))
    return point
