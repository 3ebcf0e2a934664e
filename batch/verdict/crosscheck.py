"""Cross-checks (issue 44): a reference judged against a render of the same scene by another,
independent renderer, and the record of it in the reference's provenance.

``batch/make_references.py --crosscheck NAME`` renders the scene with NAME in independent passes
(the reference maker's pass jobs), then ``judge`` holds the reference against that render on both
their noises with the test that judges every render against a reference and every replacement
against the old reference (batch/verdict/references.py ``judge_replacement``: the block test and
the scale test, batch/verdict/compare.py ``z_test``), states its power the way a run does (the
smallest uniform scale error it detects with 90 % power, compare.py ``ZTest.detectable``) and, when
the two differ beyond noise, fits the diagnosis' error models to that test (batch/verdict/diagnosis/,
as the verdict of a failing render does). No second judge: the figures are the verdict's own.

A cross-check is recorded in the reference's JSON record, under ``crosschecks`` (RECORD_KEY), one
entry per renderer and mode (a newer one of the same renderer and mode replaces the older), with
the sha256 of the reference image it judged (``reference_sha256``) and the scene's fingerprint:
an entry counts (``counting``) only while both are the reference's own (a reference re-made since,
or an image changed by hand, leaves its old cross-checks in the record but they no longer count).
``record`` rewrites the record as one step (a unique temporary file, synced, renamed over it)
under the scene's lock (the lock every writer of that reference holds), after checking that the
image on disk is still the one judged; it changes nothing but the ``crosschecks`` list.

Agreement up to a recorded deviation (known_deviations.toml, batch/verdict/known.py): where the
cross-checking renderer differs from the reference beyond noise, each deviation recorded for that
renderer (backend, scene, mode, version and film as for a run's job) that explains the "noise
test" with a scale model (``scale`` +- ``scale_se``; not an observer, which needs a layer this
test does not carry, nor a ``shadowing`` form, which only the GGX probe re-judges) re-judges the
same test with its model applied, exactly as the verdict re-judges a failing render for
``known`` (compare.py ``ZTest.rejudge``). The first whose model passes makes the cross-check agree
*under* it: the entry records ``agrees_under`` (the deviation's id) with the model it used
(``deviation``), and its power is the test's under that model (the model's uncertainty joins every
block's variance, so it detects less than the plain test: ``detectable``; the plain test's figure
is ``detectable_plain``). A deviation whose model does not fit leaves the cross-check failed. Such
an entry counts only while the deviation file still records that id with that model (``counting``
with ``deviations``): a deviation removed or re-measured since leaves the cross-check uncounted.

What the verdict says (``label``): "reference cross-checked by pbrt-v4 (detects 0.2 %)" for each
counting entry that agreed, "reference cross-checked by pbrt-v4 up to DEVIATION (detects 0.3 %)"
for one that agreed under a deviation; a counting entry that disagreed is said too ("reference
DIFFERS from ...") since a disagreement between two independent renderers is a finding (issue 44
item 4).
"""
import datetime as dt
import json
import math
import os
import re
from pathlib import Path

RECORD_KEY = "crosschecks"
ENTRY_FIELDS = ("renderer", "version", "versions", "mode", "spp", "passes", "seed", "resolution", "detectable",
                "p", "threshold", "scale_p", "scale_threshold", "ratio", "agrees", "approximated", "date", "command",
                "reference_sha256", "fingerprint", "diagnosis", "difference", "agrees_under", "deviation",
                "detectable_plain", "deviations_not_fitting")
NOISE_TEST = "noise test"  # the check name a deviation must explain (known_deviations.toml ``checks``)
DEFAULT_DETECT = 0.005  # the stated power: a cross-check must detect a uniform 0.5 % error with 90 % power


def renderer_label(renderer, version=None):
    """How a verdict names a cross-checking renderer: pbrt's version 4 as "pbrt-v4" (what its
    authors call it), another as "NAME VERSION" (the version's first word that starts with a digit:
    "art 2.1.2", "toy_spectral 1.0"), or the name alone."""
    name = str(renderer)[:40]
    word = next((w for w in str(version).split() if w[:1].isdigit()), "") if isinstance(version, str) else ""
    word = word.rstrip(",;:)")[:20]
    if name == "pbrt" and re.fullmatch(r"\d+", word):
        return f"pbrt-v{word}"
    return f"{name} {word}" if word else name


def percent(fraction):
    """A relative size as "0.12 %" (two significant digits)."""
    return f"{100 * fraction:.2g} %"


def _number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def judge(reference, check, scene, renderer, mode, *, alpha=None, min_samples=None, block=None, deviations=(),
          versions=None, film=None):
    """The reference (a references.Reference) judged against ``check`` (the cross-check render as a
    Reference: mean and per-pixel standard error of its passes, provenance with spp and passes) of
    ``scene`` (as rendered) on both their noises. Returns plain data: ``comparable`` (False with
    ``reason``), ``agrees``, ``test`` (the noise test's record: block and scale test), ``ratio``
    ({channel: [check / reference, its standard error]}), ``detectable`` (the uniform scale error
    the test detects with 90 % power, a fraction; None when none up to 100 %), and, when they
    differ, ``diagnosis`` (the verdict's error models: their text and the likely one).

    ``deviations`` (known.load's list) with the renderer's ``versions`` and ``film``: where they
    differ, the first deviation that applies to this renderer and scene and explains the noise test
    by a scale model that passes makes them agree under it (module docstring): ``agrees`` True,
    ``agrees_under`` its id, ``deviation`` its model, ``detectable`` the power under that model and
    ``detectable_plain`` the plain test's; the plain difference and its diagnosis are kept."""
    from . import compare, references
    # the runner's samples per block for this scene (its own larger figure where calibrated: the glass spheres)
    min_samples = compare.min_samples_for(scene.get("name"), min_samples)
    v = references.judge_replacement(reference, check, alpha, min_samples, block, keep=True)
    if not v["comparable"]:
        return {"comparable": False, "agrees": False, "reason": v["reason"]}
    zt = v["_ztest"]
    det = zt.detectable()
    out = {"comparable": True, "agrees": bool(v["same"]), "test": v["test"], "ratio": v["ratio"],
           "detectable": det["scale"] if det else None, "new_is_test": v["_new_is_test"]}
    if not v["same"]:
        out["diagnosis"] = _diagnose(v, reference, check, scene, renderer, mode)
        job = {"scene": scene.get("name"), "backend": renderer, "mode": mode, "versions": versions or {}, "film": film}
        tried = []
        for dev in explaining(deviations, job):
            scale, scale_se = model_for_test(dev, v["_new_is_test"])
            tried.append({"id": dev.id, "scale": dev.scale, "scale_se": dev.scale_se})
            if zt.rejudge(scale, scale_se) is True:
                under = detectable_under(zt, scale, scale_se)
                out.update(agrees=True, agrees_under=dev.id, detectable_plain=out["detectable"], detectable=under,
                           deviation=tried.pop())
                break
        if tried and not out.get("agrees_under"):
            out["deviations_not_fitting"] = tried
    return out


def explaining(deviations, job):
    """The deviations that may explain a cross-check's noise test: those that apply to the
    cross-checking renderer's job (known.applicable: scene, backend, mode, versions, film) and
    explain the noise test by a scale model alone (no observer: the test carries no observer layer;
    no shadowing form: only the GGX probe re-judges that)."""
    from . import known
    if not deviations:
        return []
    return [d for d in known.applicable(deviations, job)
            if d.explains(NOISE_TEST) and d.observer is None and d.shadowing is None]


def model_for_test(dev, new_is_test):
    """(scale, scale_se) of a deviation's model as the noise test applies it to its reference: the
    deviation says the cross-checking renderer reads ``scale`` times the truth; where the reference
    is the tested image (finer than the cross-check) the factor on the other side is 1 / scale,
    its uncertainty scale_se / scale^2 (first-order propagation, JCGM 100:2008 (GUM) 5.1.2)."""
    if new_is_test:
        return float(dev.scale), float(dev.scale_se)
    return 1.0 / float(dev.scale), float(dev.scale_se) / float(dev.scale) ** 2


def detectable_under(zt, scale, scale_se):
    """The smallest uniform scale error the noise test ``zt`` detects with 90 % power once the
    deviation's model is applied (compare.py ``ZTest.detectable`` on the re-judged test: the
    reference ``scale`` times brighter, ``(scale_se m)^2`` added to every block's variance as
    ``rejudge`` adds it); None when none up to 100 %."""
    import dataclasses
    from . import compare
    m = zt.ref_block_mean
    d = zt.diff - (scale - 1.0) * m
    var = zt.var + (scale_se * m) ** 2
    sc = compare.scale_stats(d, var, zt.dof, zt.weight, m, zt.alpha) if zt.weight is not None else None
    det = dataclasses.replace(zt, diff=d, var=var, scale=sc).detectable()
    return det["scale"] if det else None


def _diagnose(v, reference, check, scene, renderer, mode):
    """The verdict's diagnosis (batch/verdict/diagnosis/) of the image tested (the cross-check,
    or the reference where it is the finer one) against the other: its text, the likely model
    and each model's figures as the verdict records them; an error is recorded, never raised."""
    import numpy as np
    from . import diagnosis
    test = check if v["_new_is_test"] else reference
    entry = {"scene": scene.get("name"), "backend": renderer, "mode": mode, "status": "failed", "test": v["test"],
             "probes": [], "spp": test.spp, "passes": test.provenance.get("passes")}
    image, stderr = test.mean.astype(np.float64), test.stderr.astype(np.float64)
    try:
        ev = diagnosis.Evidence(entry, scene, test.names, image, stderr, entry["passes"], v["_at"], v["_ztest"],
                                (list(test.names), image, stderr))
        found = diagnosis.diagnose(ev)
    except Exception as exc:  # noqa: BLE001 - advice must never take the cross-check down
        return {"text": "no diagnosis", "likely": None, "error": f"{type(exc).__name__}: {exc}"[:300]}
    found.pop("_best_fit", None)
    return {"text": found.get("text"), "likely": found.get("likely"),
            "of": "the cross-check against the reference" if v["_new_is_test"] else "the reference against the cross-check"}


def difference_lines(result):
    """Where a cross-check that disagrees differs, as lines: each channel's size (check / reference
    - 1 by the scale test, with its standard error and z), the block test's figures, the diagnosis."""
    from ..records import noise_test_failure
    if not result.get("comparable"):
        return [f"cannot judge the reference against the cross-check: {result.get('reason')}"]
    lines = []
    t = result["test"]
    sc = t.get("scale_test") if isinstance(t.get("scale_test"), dict) else {}
    s, se, z = (sc.get(k) or [] for k in ("s", "se", "z"))
    sign = 1 if result.get("new_is_test", True) else -1  # the scale test's s is the tested image over the other
    for i, c in enumerate("RGB"):
        if i < min(len(s), len(se), len(z)) and all(_number(x) for x in (s[i], se[i], z[i])):
            size = (s[i] - 1.0) if sign > 0 else (1.0 / s[i] - 1.0)
            lines.append(f"channel {c}: the cross-check is {percent(abs(size))} {'brighter' if size > 0 else 'darker'} "
                         f"than the reference (+- {percent(se[i])}), z = {sign * z[i]:+.2f}")
    failure = noise_test_failure(t)
    if failure:
        lines.append(f"noise test failed: {failure}")
    for dev in result.get("deviations_not_fitting") or []:
        lines.append(f"the known deviation {dev['id']} (scale {dev['scale']:g} +- {dev['scale_se']:g}) does not fit: "
                     "the test fails under its model too")
    d = result.get("diagnosis") or {}
    if d.get("text"):
        lines.append(f"diagnosis ({d.get('of', 'the cross-check against the reference')}): {d['text']}")
    return lines


def entry(result, *, renderer, mode, versions, spp, passes, seed, resolution, reference_sha256, fingerprint,
          approximated=None, command=None, now=None):
    """The ``crosschecks`` entry for a judged cross-check (plain data, JSON)."""
    t = result.get("test") or {}
    sc = t.get("scale_test") if isinstance(t.get("scale_test"), dict) else {}
    versions = {k: str(v) for k, v in (versions or {}).items() if not str(k).endswith("_exe")}  # no local paths
    out = {"renderer": renderer, "version": versions.get(renderer), "versions": versions, "mode": mode,
           "spp": int(spp), "passes": int(passes), "seed": int(seed), "resolution": list(resolution),
           "detectable": result.get("detectable"), "p": t.get("p_min"), "threshold": t.get("threshold"),
           "scale_p": sc.get("p_min"), "scale_threshold": sc.get("threshold"), "ratio": result.get("ratio"),
           "agrees": bool(result.get("agrees")), "approximated": list(approximated or []),
           "date": (now or dt.datetime.now(dt.timezone.utc)).isoformat(timespec="seconds"), "command": command,
           "reference_sha256": reference_sha256, "fingerprint": fingerprint}
    if result.get("agrees_under"):  # agreed only under a recorded deviation: its model and the plain figures
        out.update(agrees_under=result["agrees_under"], deviation=result.get("deviation"),
                   detectable_plain=result.get("detectable_plain"))
    if result.get("deviations_not_fitting"):
        out["deviations_not_fitting"] = result["deviations_not_fitting"]
    if not out["agrees"] or out.get("agrees_under"):
        out["difference"] = difference_lines(result)
        if result.get("diagnosis"):
            out["diagnosis"] = result["diagnosis"].get("text")
    return out


def _entries(provenance):
    items = provenance.get(RECORD_KEY) if isinstance(provenance, dict) else None
    return [e for e in items if isinstance(e, dict)] if isinstance(items, list) else []


def stale_reason(item, provenance, deviations=None):
    """None when a cross-check entry belongs to the reference whose record is ``provenance`` (its
    image's sha256 and the scene's fingerprint are the record's), else why it does not count.
    ``deviations`` (known.load's list; None: not checked): an entry that agreed under a deviation
    counts only while that deviation is recorded with the model it was judged under."""
    sha = provenance.get("exr_sha256") if isinstance(provenance, dict) else None
    if not isinstance(sha, str):
        return "the reference's record gives no image sha256 to tie it to"
    if item.get("reference_sha256") != sha:
        return "made against another image of this reference (its sha256 differs: the reference was re-made since)"
    if item.get("fingerprint") != provenance.get("fingerprint"):
        return "made for another version of the scene (fingerprint differs)"
    under = item.get("agrees_under")
    if under is not None and deviations is not None:
        model = item.get("deviation") if isinstance(item.get("deviation"), dict) else {}
        same = [d for d in deviations if d.id == under and d.scale == model.get("scale")
                and d.scale_se == model.get("scale_se")]
        if not same:
            return (f"agreed only under the deviation {str(under)[:80]!r}, which the known deviations no longer "
                    "record with that model")
    return None


def counting(provenance, deviations=None):
    """(counting, not counting) cross-check entries of a reference record: counting ones belong to
    this very reference (``stale_reason`` None) and state whether they agreed; not counting ones
    come as [(entry, why)]. ``deviations``: as ``stale_reason``'s."""
    good, bad = [], []
    for item in _entries(provenance):
        why = stale_reason(item, provenance, deviations)
        if why is None and isinstance(item.get("agrees"), bool):
            good.append(item)
        else:
            bad.append((item, why or "no verdict recorded (agrees is not true or false)"))
    return good, bad


def summary(item):
    """What a run entry keeps of a counting cross-check (metrics.json ``reference.crosschecks``)."""
    det = item.get("detectable")
    return {"renderer": str(item.get("renderer")), "label": renderer_label(item.get("renderer"), item.get("version")),
            "mode": item.get("mode") if isinstance(item.get("mode"), str) else None,
            "spp": item.get("spp") if _number(item.get("spp")) else None,
            "detectable": float(det) if _number(det) else None, "agrees": bool(item.get("agrees")),
            "agrees_under": str(item["agrees_under"])[:80] if item.get("agrees_under") is not None else None,
            "date": str(item.get("date") or "")[:25]}


def label(items):
    """The verdict's words for a reference's counting cross-checks (their ``summary`` dicts), or "":
    "reference cross-checked by pbrt-v4 (detects 0.2 %)", for one that agreed under a recorded
    deviation "reference cross-checked by pbrt-v4 up to DEVIATION (detects 0.3 %)", and for one
    that disagreed "reference DIFFERS from pbrt-v4 beyond noise (cross-check of DATE)"."""
    parts = []
    for s in items or []:
        if not isinstance(s, dict):
            continue
        who = str(s.get("label") or s.get("renderer"))[:60]
        if s.get("agrees") is True:
            det = s.get("detectable")
            under = s.get("agrees_under")
            parts.append(f"reference cross-checked by {who}" + (f" up to {str(under)[:80]}" if under else "")
                         + (f" (detects {percent(det)})" if _number(det) else ""))
        elif s.get("agrees") is False:
            parts.append(f"reference DIFFERS from {who} beyond noise (cross-check of {str(s.get('date') or '')[:10]})")
    return "; ".join(parts)


def agreed(items):
    """True when a reference's counting cross-checks (summary dicts) hold one that agreed."""
    return any(isinstance(s, dict) and s.get("agrees") is True for s in items or [])


def record(directory, scene_name, item):
    """Add ``item`` to the ``crosschecks`` of ``scene_name``'s reference in ``directory``, replacing
    an entry of the same renderer and mode, as one step under the scene's lock: the record read
    again, the image on disk checked to be the one judged (its sha256 the record's and the
    item's), a unique temporary file written and synced, renamed over the record. Nothing else of
    the record changes. Raises ValueError (the reference changed meanwhile) or OSError."""
    from . import references
    directory = Path(directory)
    meta_path, exr_path = directory / f"{scene_name}.json", directory / f"{scene_name}.exr"
    with references.scene_lock(directory, scene_name):
        meta, bad = references.read_record(meta_path)
        if bad:
            raise ValueError(f"{meta_path}: {bad}")
        if meta.get("exr_sha256") != item["reference_sha256"] or references.sha256_of(exr_path) != item["reference_sha256"]:
            raise ValueError(f"{exr_path}: the reference changed while it was cross-checked (sha256 differs); "
                             "nothing recorded: run the cross-check again")
        kept = [e for e in _entries(meta) if (e.get("renderer"), e.get("mode")) != (item["renderer"], item["mode"])]
        meta[RECORD_KEY] = kept + [item]
        tmp = references._temp(directory, scene_name, ".json.tmp")
        try:
            references._write_synced(tmp, (json.dumps(meta, indent=1, sort_keys=True) + "\n").encode())
            os.replace(tmp, meta_path)
            references._fsync_dir(directory)
        finally:
            tmp.unlink(missing_ok=True)
    return meta_path
