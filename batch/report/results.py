"""Reading a batch runner's output folder (metrics.json and its images): shared by the
Blender panel and anything else that inspects results, whoever started the run."""
from pathlib import Path

from ...exporters import names
from .. import records

IMAGE_KINDS = {"render": "render.exr", "reference": "reference.exr", "diff_abs": "diff_abs.exr",
               "diff_rel": "diff_rel.exr", "flip": "flip.exr", "zscore": "zscore.exr"}


def load(out_dir):
    """The metrics.json of an output folder through batch/records.py (upgraded to the current
    version, every path field absolute: the panel opens the files), or None if there is none (yet)
    or it cannot be read. Lenient: a version this code does not know is shown as far as it can be."""
    path = Path(out_dir) / records.FILE_NAME
    if not path.is_file():
        return None
    try:
        return records.read(path, strict=False).resolved()
    except records.RecordError:
        return None  # not a metrics.json the panel can show (the report and resume name the problem)


def latest_output(parent):
    """The newest outputs-* folder with a metrics.json under ``parent``, or None."""
    found = sorted(p for p in Path(parent).glob("outputs-*") if (p / "metrics.json").is_file())
    return found[-1] if found else None


def last_status(out_dir):
    """{scene: {backend: run entry}} of an output folder (latest entry wins)."""
    data = load(out_dir)
    status = {}
    for run in data.entries("runs") if data is not None else []:
        status.setdefault(str(run.get("scene")), {})[str(run.get("backend"))] = run
    return status


def _safe(*parts):
    """The parts of a path inside an output folder, from a metrics.json that may come from anyone:
    only names the IR admits (exporters/names.py), so none can leave the folder."""
    return all(names.problem(p) is None for p in parts)


def image_path(out_dir, scene, backend, kind, make=False):
    """Path of one result image, or None if that run did not write it (or names no safe path).
    The reference may be the scene's shared one and the differences are made from the render and
    the reference (``derived_image``): with ``make`` they are written when missing, without it
    their path is returned if they can be made."""
    if not _safe(scene, backend):
        return None
    path = Path(out_dir) / scene / "results" / backend / IMAGE_KINDS[kind]
    if path.is_file():
        return path
    if kind == "reference":
        return shared_reference(out_dir, scene, backend)
    if kind in DERIVED and image_path(out_dir, scene, backend, "render") and shared_reference(out_dir, scene, backend):
        return derived_image(out_dir, scene, backend, kind) if make else path
    return None


# -- issue 21: runs keep one half-float reference per scene (<scene>/results/reference_WxH.exr) and no
# difference images; these find the reference and write a difference image when the panel asks for it
DERIVED = ("diff_abs", "diff_rel")


def shared_reference(out_dir, scene, backend):
    """The scene's shared reference at the resolution of ``backend``'s render, or None."""
    render = Path(out_dir) / scene / "results" / backend / "render.exr"
    if not render.is_file():
        return None
    import OpenEXR
    with OpenEXR.File(str(render), header_only=True) as f:
        box = f.header()["dataWindow"]
    w, h = int(box[1][0] - box[0][0] + 1), int(box[1][1] - box[0][1] + 1)
    path = render.parent.parent / f"reference_{w}x{h}.exr"
    return path if path.is_file() else None


def derived_image(out_dir, scene, backend, kind):
    """Write (once) and return diff_abs.exr or diff_rel.exr beside the render."""
    from .. import exr
    from .. import previews
    folder = Path(out_dir) / scene / "results" / backend
    path = folder / IMAGE_KINDS[kind]
    if not path.is_file():
        render = exr.read_rgb(folder / "render.exr")
        reference = exr.read_rgb(shared_reference(out_dir, scene, backend))
        previews.write_half(path, previews.differences(render, reference)[DERIVED.index(kind)])
    return path


def chart_path(out_dir, scene):
    """The error-against-time chart of a sweep over ``scene``, or None."""
    if not _safe(scene):
        return None
    path = Path(out_dir) / "sweeps" / f"{scene}.png"
    return path if path.is_file() else None


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


def checked_against_itself(run):
    """True for a judged render whose only judge was a reference made by the same renderer (its
    backend), with no probe measured: the verdict says whether the renderer changed, not whether it
    is right."""
    ref = run.get("reference")
    return (run.get("status") in JUDGED and probes_measured(run)[0] == 0 and isinstance(ref, dict)
            and ref.get("backend") is not None and ref.get("backend") == run.get("backend"))


def judged_by(run):
    """One line naming what judged a run entry (summary, report, panel and JUnit say the same)."""
    if run.get("status") not in JUDGED:
        return ""
    measured, passed = probes_measured(run)
    maker = reference_maker(run)
    parts = [f"{measured} probe{'s' if measured != 1 else ''} ({passed} passed)" if measured else "no probe"]
    parts.append(f"reference by {maker}" if maker else "no reference")
    line = "; ".join(parts)
    return f"{line} ({SELF_CHECK})" if checked_against_itself(run) else line
def mode_text(run):
    """A run entry's mode as shown: Mitsuba's variant, with its film where it is not Mitsuba's own
    (--film cmf: the scene format's colour)."""
    mode = run.get("mode") or ""
    return f"{mode} (cmf film)" if run.get("film") == "cmf" else str(mode)
