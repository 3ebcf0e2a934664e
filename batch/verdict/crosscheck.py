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

What the verdict says (``label``): "reference cross-checked by pbrt-v4 (detects 0.2 %)" for each
counting entry that agreed; a counting entry that disagreed is said too ("reference DIFFERS from
...") since a disagreement between two independent renderers is a finding (issue 44 item 4).
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
                "reference_sha256", "fingerprint", "diagnosis", "difference")
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


def judge(reference, check, scene, renderer, mode, *, alpha=None, min_samples=None, block=None):
    """The reference (a references.Reference) judged against ``check`` (the cross-check render as a
    Reference: mean and per-pixel standard error of its passes, provenance with spp and passes) of
    ``scene`` (as rendered) on both their noises. Returns plain data: ``comparable`` (False with
    ``reason``), ``agrees``, ``test`` (the noise test's record: block and scale test), ``ratio``
    ({channel: [check / reference, its standard error]}), ``detectable`` (the uniform scale error
    the test detects with 90 % power, a fraction; None when none up to 100 %), and, when they
    differ, ``diagnosis`` (the verdict's error models: their text and the likely one)."""
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
    return out


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
    if not out["agrees"]:
        out["difference"] = difference_lines(result)
        if result.get("diagnosis"):
            out["diagnosis"] = result["diagnosis"].get("text")
    return out


def _entries(provenance):
    items = provenance.get(RECORD_KEY) if isinstance(provenance, dict) else None
    return [e for e in items if isinstance(e, dict)] if isinstance(items, list) else []


def stale_reason(item, provenance):
    """None when a cross-check entry belongs to the reference whose record is ``provenance`` (its
    image's sha256 and the scene's fingerprint are the record's), else why it does not count."""
    sha = provenance.get("exr_sha256") if isinstance(provenance, dict) else None
    if not isinstance(sha, str):
        return "the reference's record gives no image sha256 to tie it to"
    if item.get("reference_sha256") != sha:
        return "made against another image of this reference (its sha256 differs: the reference was re-made since)"
    if item.get("fingerprint") != provenance.get("fingerprint"):
        return "made for another version of the scene (fingerprint differs)"
    return None


def counting(provenance):
    """(counting, not counting) cross-check entries of a reference record: counting ones belong to
    this very reference (``stale_reason`` None) and state whether they agreed; not counting ones
    come as [(entry, why)]."""
    good, bad = [], []
    for item in _entries(provenance):
        why = stale_reason(item, provenance)
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
            "date": str(item.get("date") or "")[:25]}


def label(items):
    """The verdict's words for a reference's counting cross-checks (their ``summary`` dicts), or "":
    "reference cross-checked by pbrt-v4 (detects 0.2 %)", and for one that disagreed "reference
    DIFFERS from pbrt-v4 beyond noise (cross-check of DATE)"."""
    parts = []
    for s in items or []:
        if not isinstance(s, dict):
            continue
        who = str(s.get("label") or s.get("renderer"))[:60]
        if s.get("agrees") is True:
            det = s.get("detectable")
            parts.append(f"reference cross-checked by {who}" + (f" (detects {percent(det)})" if _number(det) else ""))
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
