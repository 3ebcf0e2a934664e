"""What a run entry of metrics.json says, in words the summary, the report, JUnit and the Blender
panel share (reference problems, what judged a render, its mode). Reading a run folder (metrics.json,
a job's images) is batch/run_folder.py's."""
from ..verdict import crosscheck


def reference_problems(run):
    """["<file>: <problem>"] for a run entry's reference problems (metrics.json's
    ``reference_problems``: every candidate reference passed over, with its file)."""
    return [f"{p.get('file')}: {p.get('problem')}" for p in run.get("reference_problems") or []
            if isinstance(p, dict)]


def judged_without_reference(run):
    """True for a render judged (by its probes) although no usable reference was found: never a
    plain ok (its reason says why the reference could not be used)."""
    return bool(run.get("reference_problem")) and run.get("status") not in ("unjudged", "skipped", "unsupported")


# -- issue 35: what judged a render. A render judged only against a reference its own renderer made
# (no probe measured) is a regression check: it sees a change of that renderer, never its error.
JUDGED = ("ok", "failed", "known", "fixed")
SELF_CHECK = "checked against itself: detects change, not error"


def probes_measured(run):
    """(measured, passed) probe counts of a run entry: a probe too small to measure at the render's
    resolution (``pass`` None) judged nothing."""
    probes = run.get("probes") if isinstance(run.get("probes"), list) else []  # metrics.json may come from anyone
    probes = [p for p in probes if isinstance(p, dict) and isinstance(p.get("pass"), bool)]
    return len(probes), sum(p["pass"] is True for p in probes)


def reference_maker(run):
    """Who made the reference a run entry was judged against: "mitsuba llvm_ad_spectral, 4096 spp,
    2026-11-22", or "" when it had none."""
    ref = run.get("reference")
    if not isinstance(ref, dict) or not ref.get("backend"):
        return ""
    spp = ref.get("spp")
    parts = [" ".join(str(ref[k]) for k in ("backend", "mode") if ref.get(k)),
             f"{spp} spp" if isinstance(spp, int) and not isinstance(spp, bool) else "",
             str(ref.get("date") or "")[:10]]
    return ", ".join(p for p in parts if p)


def crosschecks(run):
    """The cross-checks of the reference a run entry was judged against that count (issue 44:
    recorded for this very image; metrics.json ``reference.crosschecks``, batch/verdict/judge.py)."""
    ref = run.get("reference")
    items = ref.get("crosschecks") if isinstance(ref, dict) else None
    return [c for c in items if isinstance(c, dict)] if isinstance(items, list) else []


def checked_against_itself(run):
    """True for a judged render whose only judge was a reference made by the same renderer (its
    backend), with no probe measured and no cross-check of that reference by another renderer that
    agreed with it: the verdict says whether the renderer changed, not whether it is right."""
    ref = run.get("reference")
    return (run.get("status") in JUDGED and probes_measured(run)[0] == 0 and isinstance(ref, dict)
            and ref.get("backend") is not None and ref.get("backend") == run.get("backend")
            and not crosscheck.agreed(crosschecks(run)))


def crosscheck_note(run):
    """The cross-checks of a judged run entry's reference in words ("reference cross-checked by
    pbrt-v4 (detects 0.12 %)"), or "" (the summary's status cell adds it)."""
    if run.get("status") not in JUDGED or not reference_maker(run):
        return ""
    return crosscheck.label(crosschecks(run))


def judged_by(run):
    """One line naming what judged a run entry (summary, report, panel, JUnit and metrics.json's
    ``judged_by`` say the same; the runner stores it once per record): the probes measured, who
    made the reference and who cross-checked it ("reference cross-checked by pbrt-v4 (detects
    0.12 %)"), or that it was checked against itself."""
    if run.get("status") not in JUDGED:
        return ""
    measured, passed = probes_measured(run)
    maker = reference_maker(run)
    parts = [f"{measured} probe{'s' if measured != 1 else ''} ({passed} passed)" if measured else "no probe"]
    parts.append(f"reference by {maker}" if maker else "no reference")
    checked = crosscheck_note(run)
    if checked:
        parts.append(checked)
    line = "; ".join(parts)
    return f"{line} ({SELF_CHECK})" if checked_against_itself(run) else line


def label_judged_by(entry):
    """Store ``judged_by`` in a run entry (the runner's record, and any tool that judges a kept
    render again, e.g. benchmarks/profile_verdicts.py), so that two judgings of one render compare
    equal; returns the entry."""
    label = judged_by(entry)
    if label:
        entry["judged_by"] = label
    return entry


def mode_text(run):
    """A run entry's mode as shown: Mitsuba's variant, with its film where it is not Mitsuba's own
    (--film cmf: the scene format's colour)."""
    mode = run.get("mode") or ""
    return f"{mode} (cmf film)" if run.get("film") == "cmf" else str(mode)
