"""The status of a rendered job, from its checks (the noise test against the reference, the
analytic probes, finite values) and the known deviations (batch/verdict/known.py).

  ok        judged (at least one check could be made) and every check passed
  failed    a check failed and no recorded deviation explains it, or the image has NaN/Inf
  known     every failing check fails exactly as a recorded deviation
  fixed     a recorded deviation would have been seen at this noise and is gone
  unjudged  rendered, but no usable reference and no applicable probe: not a pass
  skipped, unsupported: decided before rendering (the backend is missing, or cannot model it)

Exit status of a batch (batch/jobs/runner.py):

  0  every judged job is ok, known or fixed and nothing was left unjudged
  1  something failed (a scene that did not load counts: its jobs are failed)
  2  a usage error: a bad option or settings value, an output folder that is taken or cannot be
     written, a run that cannot be resumed, a broken --known file, a cluster that cannot be reached
  3  nothing failed but something was unjudged
  4  nothing ran: every job was skipped or unsupported (no backend could render anything)
  130 interrupted (--resume finishes the run)
"""
from dataclasses import dataclass
from typing import Callable, Optional

from . import known as _known

ORDER = {"failed": 0, "known": 1, "unjudged": 2, "fixed": 3, "ok": 4, "unsupported": 5, "skipped": 6}
EXIT_FAILED, EXIT_UNJUDGED, EXIT_NOTHING_RAN = 1, 3, 4
NOT_RUN = ("skipped", "unsupported")


def rank(status):
    """Where a status sorts in every list of results (summary, report, Blender panel): ORDER, a
    status this code does not know last."""
    return ORDER.get(status, len(ORDER)) if isinstance(status, str) else len(ORDER)


@dataclass
class Check:
    name: str
    passed: Optional[bool]  # None: could not be made here
    rejudge: Optional[Callable] = None  # deviation -> passed under its model (None: cannot tell)


def checks_of(entry, ztest=None):
    """The checks of one job record (and its in-memory noise test, for re-judging)."""
    out = []
    sanity = entry.get("sanity") or {}
    if sanity.get("nan") or sanity.get("inf"):
        out.append(Check("finite values", False))
    test = entry.get("test")
    if test is not None:
        # a shadowing form is not in the reference (rendered with the IR's): the noise test cannot tell
        rj = (lambda d, zt=ztest: None if d.shadowing else zt.rejudge(d.scale, d.scale_se, d.observer)) \
            if ztest is not None else None
        out.append(Check("noise test", test.get("pass"), rj))
    for p in entry.get("probes") or []:
        if p.get("stat"):
            out.append(Check(p["name"], p.get("pass"), lambda d, p=p: _rejudge_probe(p, d)))
        elif isinstance(p.get("interval"), dict) and "groups" in p["interval"]:
            # an interval probe that keeps its tests' means (probes/rough_film.py)
            out.append(Check(p["name"], p.get("pass"), lambda d, p=p: _rejudge_interval(p, d)))
        else:
            out.append(Check(p["name"], p.get("pass")))
    return out


def _rejudge_probe(record, dev):
    """A probe's verdict under a deviation's model (None when the probe has no result for the
    model's observer or shadowing form: probes/ggx.py shadowing_key names the latter)."""
    key = f"shadowing {dev.shadowing}" if getattr(dev, "shadowing", None) else dev.observer
    stat = record["stat"] if key is None else (record.get("alternatives") or {}).get(key)
    from . import stats  # scipy.stats: imported by the first verdict, not at start-up
    return None if stat is None else stats.rejudge(stat, dev.scale, dev.scale_se)


def _rejudge_interval(record, dev):
    """An interval probe's verdict under a deviation's model: its tests against the bounds computed
    with the model's observer (``alternatives``), scaled; None without a result for that observer
    or where the model names a shadowing form (the GGX probe's alone)."""
    if getattr(dev, "shadowing", None):
        return None
    stat = record["interval"] if dev.observer is None else (record.get("alternatives") or {}).get(dev.observer)
    from . import stats  # scipy.stats: imported by the first verdict, not at start-up
    return None if not isinstance(stat, dict) or "groups" not in stat else stats.rejudge_interval(stat, dev.scale,
                                                                                                  dev.scale_se)


def decide(entry, deviations=(), ztest=None):
    """Set entry's status, reason, and known/fixed deviation ids from its checks."""
    checks = checks_of(entry, ztest)
    judged = [c for c in checks if c.passed is not None]
    if not judged:
        why = entry.get("unjudged_because") or "no usable reference and no applicable probe"
        entry.update(status="unjudged", reason=f"rendered, not judged: {why}")
        return entry
    devs = _known.applicable(deviations, entry)
    failing, known, fixed = [], set(), set()
    for c in judged:
        models = [d for d in devs if d.explains(c.name) and c.rejudge is not None]
        under = {d.id: ok for d in models if (ok := c.rejudge(d)) is not None}
        if c.passed is False:
            explained = [i for i, ok in under.items() if ok]
            if explained:
                known.update(explained)
            else:
                failing.append(c.name)
        else:
            fixed.update(i for i, ok in under.items() if not ok)
    entry["known"], entry["fixed"] = sorted(known), sorted(fixed - known)
    if failing:
        shown = ", ".join(failing[:6]) + (f" and {len(failing) - 6} more" if len(failing) > 6 else "")
        entry.update(status="failed", reason=(entry.get("reason") or "") + ("; " if entry.get("reason") else "")
                     + f"failed: {shown}")
    elif known:
        entry.update(status="known", reason=f"fails as recorded: {', '.join(sorted(known))} (known_deviations.toml)")
    elif entry["fixed"]:
        entry.update(status="fixed", reason=(f"recorded deviation no longer reproduces: {', '.join(entry['fixed'])} "
                                             "(update known_deviations.toml)"))
    else:
        entry.update(status="ok")
    return entry


def exit_code(records):
    """0, EXIT_UNJUDGED, EXIT_NOTHING_RAN or EXIT_FAILED for a batch's job records (see the
    module docstring)."""
    statuses = {r.get("status") for r in records}
    if "failed" in statuses:
        return EXIT_FAILED
    if "unjudged" in statuses:
        return EXIT_UNJUDGED
    if statuses and statuses <= set(NOT_RUN):
        return EXIT_NOTHING_RAN
    return 0
