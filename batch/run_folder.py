"""The one reader of a run folder (issue 45 item 3): the Blender panel, batch/compare_runs.py, the
baseline (batch/verdict/baseline.py) and the report (batch/report/) open a run folder's metrics.json,
find a job's images and read the EXRs they show only through here. Below report/ and verdict/ in
the import layers (batch:base: scripts/import_graph.py); it calls batch/records.py (the file's
format) and batch/exr.py (the pixels), nothing above.

A run folder (``outputs-*/``) holds metrics.json and, per render job, the folder its record's
``image`` names (``<scene>/results/<backend>/render.exr``, written by batch/jobs/job.py) with the
images the verdict writes beside the render (zscore.exr, block_stderr.exr, flip.exr,
probe_residual.exr); the scene's shared reference is the record's ``reference.image``
(``<scene>/results/reference_WxH.exr``). Every path comes from the record, never from a scene or
backend name, and every one passes one rule (``inside``): a relative path, without '.', '..',
a drive or an absolute root, to a file that exists inside the folder, not through a link out of it
(batch/records.py ``inside_parts``, which the records' own array files use too).

API
- reading metrics.json: ``read`` (strict: compare_runs, the baseline; NotARun names the problem),
  ``read_lenient`` (the report: any version shown as far as it can be), ``load`` (the panel: None
  when there is nothing to show), ``last_status``, ``entry``,
  ``summary_text``, ``report_page``.
- the rule: ``inside``, ``inside_rel``, ``local_url`` (a page's relative link), ``safe_names``.
- one job's files: ``Job(folder, entry)`` with ``dir`` (its folder, relative), ``rel``/``path`` of
  a kind (JOB_FILES: render, reference, zscore, flip, block_stderr, probe_residual,
  diff_abs, diff_rel, S0..S3), ``beside`` (a file the report writes in the job's folder),
  ``preview`` (a spectral job's preview), ``diagnosis_image``, ``kinds`` (what the panel lists);
  ``job(folder, scene, backend)``: the Job of the latest record of that scene and backend;
  ``job_dir(folder, entry)``: the job's folder (where the baseline's z-map goes).
- a scene's and the studies' files: ``scene_ir``, ``stability_strip``, ``chart_path`` (a scene's
  sweep chart, from the sweeps records).
- the baseline's files: ``comparisons`` (OUT/compare[-N]), ``recorded_baseline``,
  ``baseline_records``, ``baseline_image`` (the baseline's render, the z-map), ``zmap_png``.
- EXR copies the panel needs: ``plain_rgb``; differences and Stokes components are written on
  request by ``Job.path(kind, make=True)``.
"""
import json
import os
import re
import stat
from pathlib import Path, PurePosixPath, PureWindowsPath
from urllib.parse import quote

from ..exporters import names as _names
from . import records

FILE_NAME = records.FILE_NAME
RESULTS = "results"             # <scene>/results/<backend>/: a job's folder (batch/jobs/plan.py)
SUMMARY = "summary.md"           # batch/report/summary.py writes it, the page quotes its sections
REPORT = "report.html"           # batch/report/html.py writes it, the panel opens it
COMPARE_DIR = "compare"          # batch/compare_runs.py's default output folder inside the newer run
COMPARE_FILE = "compare.json"
ZMAP = "baseline_zscore.exr"     # the baseline's two-sample z-map beside a render (batch/verdict/baseline.py)
ZMAP_PNG = "baseline_zscore.png"
OWN_REFERENCE = "reference.exr"  # a run from before issue 21: each job's own copy of its reference

# a job's images by kind: the file in the job's folder (batch/verdict/judge.py and batch/previews.py write them)
JOB_FILES = {"render": "render.exr", "reference": OWN_REFERENCE, "diff_abs": "diff_abs.exr",
             "diff_rel": "diff_rel.exr", "flip": "flip.exr", "zscore": "zscore.exr",
             "block_stderr": "block_stderr.exr", "probe_residual": "probe_residual.exr"}
IMAGE_KINDS = ("render", "reference", "diff_abs", "diff_rel", "flip", "zscore")  # the panel's buttons, in order
DERIVED = ("diff_abs", "diff_rel")  # made from the render and the reference when asked for (issue 21)
STOKES = ("S0", "S1", "S2", "S3")
BASELINE_KINDS = ("baseline_render", "baseline_zscore")


class NotARun(ValueError):
    """A folder that is missing or holds no readable run (named, with what is wrong)."""


# -- metrics.json ------------------------------------------------------------------------------------
def metrics_file(folder):
    return Path(folder) / FILE_NAME


def read(folder):
    """The metrics.json of a finished run in ``folder`` (a records.Run, upgraded to the current
    schema, paths relative to the folder) with a list ``runs``; strict: NotARun naming the folder or
    file and what is wrong (compare_runs, the baseline)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise NotARun(f"{folder}: no such folder")
    path = metrics_file(folder)
    if not path.is_file():
        raise NotARun(f"{folder} is not a run: it holds no metrics.json")
    try:
        data = records.read(path)
    except records.RecordError as exc:
        raise NotARun(str(exc)) from None
    if not isinstance(data.get("runs"), list):
        raise NotARun(f"{path}: not the metrics.json of a run (an object with a list 'runs')")
    return data


def read_lenient(folder):
    """The metrics.json of ``folder`` as the report shows it: paths relative to the folder (as the
    page links them), a version this code does not know read as far as it can be. RecordError when
    it cannot be read at all."""
    return records.read(folder, strict=False)


_LOADED = {}  # metrics.json (absolute) -> ((inode, mtime_ns, size), Run or None): the panel redraws often


def load(folder):
    """The panel's metrics.json (lenient: any version shown as far as it can be; paths as the file
    holds them, relative to the folder), or None if there is none (yet) or it cannot be read. Read
    again only when the file changes (the runner replaces it whole: a new inode); the Run returned
    is shared: read it, do not change it."""
    path = metrics_file(folder).absolute()
    try:
        st = os.stat(path)
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode):
        return None
    key = (st.st_ino, st.st_mtime_ns, st.st_size)
    hit = _LOADED.get(path)
    if hit is not None and hit[0] == key:
        return hit[1]
    try:
        data = records.read(path, strict=False)
    except records.RecordError:
        data = None  # not a metrics.json the panel can show (the report and resume name the problem)
    if len(_LOADED) > 16:
        _LOADED.clear()
    _LOADED[path] = (key, data)
    return data


def last_status(folder, data=None, resolved=False):
    """{scene: {backend: run entry}} of a run folder (latest entry wins; ``data``: its metrics.json
    when already read). Paths relative to the folder, as the file holds them (what ``Job`` takes);
    with ``resolved``, absolute (a copy, for showing: reference files, reference problems)."""
    data = load(folder) if data is None else data
    if resolved and data is not None:
        data = data.resolved()
    status = {}
    for run in data.entries("runs") if data is not None else []:
        status.setdefault(str(run.get("scene")), {})[str(run.get("backend"))] = run
    return status


def entry(folder, scene, backend):
    """The latest run entry of ``scene`` and ``backend``, or None."""
    return last_status(folder).get(str(scene), {}).get(str(backend))


def summary_text(folder):
    """The run's summary.md (as text, undecodable bytes replaced), or "" when it has none."""
    path = inside(folder, SUMMARY)
    return path.read_text(encoding="utf-8", errors="replace") if path is not None else ""


def report_page(folder):
    """The run's report.html if it is a file inside the folder, else None."""
    return inside(folder, REPORT)


# -- the rule: inside the folder, no link out ----------------------------------------------------------
def inside_rel(folder, rel):
    """``rel`` (a path from a metrics.json: anyone's text) as a PurePosixPath relative to ``folder``
    if it names a file inside it (batch/records.py ``inside_parts``: no absolute path, no drive, no
    '.' or '..', no link out); else None."""
    parts = records.inside_parts(folder, rel)
    return PurePosixPath(*parts) if parts else None


def inside(folder, rel):
    """``folder``/``rel`` if ``rel`` names a file inside ``folder`` (``inside_rel``); else None."""
    parts = records.inside_parts(folder, rel)
    return Path(folder, *parts) if parts else None


def local_url(folder, rel):
    """``rel`` as a relative, percent-encoded URL if it names a file inside ``folder``; else None."""
    parts = records.inside_parts(folder, rel)
    return "/".join(quote(p, safe="") for p in parts) if parts else None


def safe_names(*parts):
    """Whether every part is a name the IR admits (exporters/names.py): none can leave a folder."""
    return all(isinstance(p, str) and _names.problem(p) is None for p in parts)


def _parts(rel):
    text = str(rel)
    return (PureWindowsPath(text) if "\\" in text else PurePosixPath(text)).parts


# -- one job's files -----------------------------------------------------------------------------------
class Job:
    """The files of one job of the run in ``folder``, from its run entry (``entry``: as metrics.json
    holds it, paths relative to the folder; an absolute path is refused like one that leaves it)."""

    def __init__(self, folder, entry):
        self.folder = Path(folder)
        self.entry = entry if isinstance(entry, dict) else {}
        render = inside_rel(self.folder, self.entry.get("image"))
        self.dir = render.parent if render is not None else None  # the job's folder, relative; None: no render

    def _in_dir(self, name):
        return self.dir / name if self.dir is not None and safe_names(name) else None

    def rel(self, kind):
        """The relative path (PurePosixPath) of one of the job's images if it is a file inside the
        folder, else None. ``reference``: the record's shared reference, else the job's own copy (a
        run from before issue 21)."""
        if self.dir is None:
            return None
        if kind == "render":
            return inside_rel(self.folder, self.entry.get("image"))
        if kind == "reference":
            ref = self.entry.get("reference")
            shared = ref.get("image") if isinstance(ref, dict) else None
            if isinstance(shared, str):
                return inside_rel(self.folder, shared)
        if kind in STOKES:
            return inside_rel(self.folder, self._in_dir(f"stokes_{kind}.exr"))
        name = JOB_FILES.get(kind)
        return inside_rel(self.folder, self.dir / name) if name else None

    def path(self, kind, make=False):
        """The absolute path of one of the job's images, or None. The differences (DERIVED) and the
        Stokes components are made from the render (and the reference): with ``make`` they are
        written when missing; without it their path is returned if they can be made."""
        rel = self.rel(kind)
        if rel is not None and not (make and kind in STOKES and _is_link(self.folder / rel)):
            return self.folder / rel
        if kind in DERIVED and self.rel("render") is not None and self.rel("reference") is not None:
            target = self.folder / self.dir / JOB_FILES[kind]
            return _write_difference(target, self.path("render"), self.path("reference"), kind) if make else target
        if kind in STOKES and self.rel("render") is not None and (make or self.has_stokes()):
            target = self.folder / self.dir / f"stokes_{kind}.exr"  # made when the render has the component
            return _write_stokes(target, self.path("render"), kind) if make else target
        return None

    def has_stokes(self):
        channels = self.entry.get("channels")
        return (self.rel("render") is not None and isinstance(channels, list)
                and all(f"{k}.R" in channels for k in STOKES))

    def beside(self, name):
        """The relative path of a file named ``name`` in the job's folder (one the report writes
        there, whether or not it exists yet), or None without a render or for a name that is not
        one plain name."""
        return self._in_dir(name)

    def preview(self):
        """The relative path of a spectral job's preview (its band record's ``preview``: a plain
        name in the job's folder), or None."""
        bands = self.entry.get("bands")
        name = bands.get("preview") if isinstance(bands, dict) else None
        if not isinstance(name, str) or not name or "/" in name or "\\" in name:
            return None
        rel = self._in_dir(name)
        return inside_rel(self.folder, rel) if rel is not None else None

    def diagnosis_image(self):
        """The relative path of the diagnosis's corrected reference (metrics.json ``diagnosis.image``), or None."""
        diag = self.entry.get("diagnosis")
        return inside_rel(self.folder, diag.get("image")) if isinstance(diag, dict) else None

    def kinds(self):
        """The image kinds the panel lists for this job: those present or that can be made, then
        the Stokes components of a render that has them."""
        kinds = [k for k in IMAGE_KINDS if self.path(k) is not None]
        return kinds + (list(STOKES) if self.has_stokes() else [])


def job(folder, scene, backend):
    """The Job of the latest record of ``scene`` and ``backend`` in the run in ``folder`` (a Job
    without files when there is none)."""
    return Job(folder, entry(folder, scene, backend))


def job_dir(folder, entry):
    """A run entry's job folder (PurePosixPath relative to ``folder``), or None when its ``image``
    is not a file inside the folder."""
    return Job(folder, entry).dir


def _is_link(path):
    try:
        return stat.S_ISLNK(os.lstat(path).st_mode)
    except OSError:
        return False


def _write_difference(path, render, reference, kind):
    """Write (once) diff_abs.exr or diff_rel.exr from the render and the reference."""
    from . import exr, previews
    if not path.is_file():
        d = previews.differences(exr.read_rgb(render), exr.read_rgb(reference))[DERIVED.index(kind)]
        previews.write_half(path, d)
    return path


def _write_stokes(path, render, component):
    """An RGB EXR of one Stokes component of the render (written beside it, never through a link)."""
    from . import exr
    try:
        rgb = exr.read_rgb(render, prefix=f"{component}.")
    except ValueError:
        return None
    exr.replace_file(path, lambda tmp: exr.write(tmp, rgb))
    return path


def plain_rgb(path):
    """``path`` itself if it holds only R, G, B (and A); else an RGB copy beside it. Blender reads an
    EXR whose channels have dotted names (stderr.R, S0.R: a render with passes or Stokes output) as
    a multilayer image whose pixels a script cannot read and an Image Editor shows by layer."""
    from . import exr
    path = Path(path)
    if set(exr.read(path)) <= {"R", "G", "B", "A"}:
        return path
    rgb = path.with_name(f"{path.stem}_rgb.exr")
    try:
        fresh = stat.S_ISREG(os.lstat(rgb).st_mode) and os.lstat(rgb).st_mtime >= path.stat().st_mtime
    except OSError:
        fresh = False
    if not fresh:  # a new file renamed over the name: never written through a link there
        exr.replace_file(rgb, lambda tmp: exr.write(tmp, exr.read_rgb(path)))
    return rgb


# -- a scene's files, the studies' ----------------------------------------------------------------------
def scene_ir(folder, scene):
    """The scene's IR as the run exported it (``<scene>/json/<scene>.json``, batch/jobs/job.py), or
    None (a scene name that is not one safe name, or no such file inside the folder)."""
    if not safe_names(scene):
        return None
    return inside(folder, PurePosixPath(scene, "json", f"{scene}.json"))


def stability_strip(backend, sweep):
    """The relative path of a stability sweep's strip of one backend (``stability/<backend>/<sweep>.png``,
    batch/studies/stability.py), or None when either is not one plain name."""
    if not all(isinstance(p, str) and p and not re.search(r"[/\\]", p) for p in (backend, sweep)):
        return None
    return PurePosixPath("stability", backend, f"{sweep}.png")


# -- charts --------------------------------------------------------------------------------------------
def chart_path(folder, scene):
    """The error-against-time chart of a sweep over ``scene`` (its sweeps record's ``chart``), or None."""
    data = load(folder)
    for s in data.entries("sweeps") if data is not None else []:
        if s.get("scene") == scene and isinstance(s.get("chart"), str):
            found = inside(folder, s["chart"])
            if found is not None:
                return found
    return None


# -- the baseline's files ------------------------------------------------------------------------------
def zmap_png(zmap):
    """The PNG beside a baseline record's z-map (a relative path string), or ""."""
    return str(PurePosixPath(*_parts(zmap)).with_name(ZMAP_PNG)) if isinstance(zmap, str) and _parts(zmap) else ""


def _same_folder(a, b):
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, ValueError, TypeError):
        return False


def comparisons(folder):
    """The folders batch/compare_runs.py wrote into the run in ``folder`` (OUT/compare, OUT/compare-2,
    ...: real folders, not links, holding compare.json), newest first."""
    found = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    for e in entries:
        if not re.fullmatch(rf"{COMPARE_DIR}(-[0-9]{{1,4}})?", e.name):
            continue
        try:
            if not stat.S_ISDIR(os.lstat(e.path).st_mode):
                continue
            st = os.lstat(Path(e.path) / COMPARE_FILE)
        except OSError:
            continue
        if stat.S_ISREG(st.st_mode):
            found.append((st.st_mtime_ns, e.name))
    return [Path(folder) / name for _, name in sorted(found, reverse=True)]


def recorded_baseline(folder, run):
    """The baseline folder a run's --baseline record names (``run``: as the user gave it, relative
    to where the run was started, which is not known), followed only where it cannot lead anywhere
    a run folder does not: a relative path without '..' taken beside the run folder (the usual
    ``--baseline out_prev -o out_new``), that holds a metrics.json. An absolute path or one with
    '..' (a hand-edited metrics.json can name any folder) is not followed: None (the panel's
    Baseline field names the folder then)."""
    text = run if isinstance(run, str) else ""
    if not text or "\0" in text or PurePosixPath(text).is_absolute() or PureWindowsPath(text).anchor:
        return None
    parts = PurePosixPath(text.replace("\\", "/")).parts
    if not parts or any(p in ("", "..") for p in parts):
        return None
    root = Path(folder).parent
    try:
        found = (root / Path(*parts)).resolve()
        if not found.is_relative_to(root.resolve()) or not metrics_file(found).is_file():
            return None
    except (OSError, ValueError):
        return None
    return found


def baseline_records(folder, data, baseline_dir=None):
    """{(scene, backend): (baseline record, folder its z-map is relative to, baseline folder or None)}
    for the run in ``folder`` (``data``: its metrics.json). With ``baseline_dir`` (the user's
    choice): the newest comparison that batch/compare_runs.py (or the panel's Compare) wrote to
    OUT/compare[-N] against that folder, else the records of a run made with --baseline naming
    that folder; without: the run's own --baseline records, their baseline folder only where
    ``recorded_baseline`` follows it (else None: no baseline render is shown)."""
    out = {}
    folder = Path(folder)
    if baseline_dir:
        for comp_dir in comparisons(folder):
            try:
                comp = json.loads((comp_dir / COMPARE_FILE).read_text(encoding="utf-8"))
            except (OSError, ValueError, RecursionError):
                continue
            if not (isinstance(comp, dict) and _same_folder(comp.get("old"), baseline_dir)):
                continue
            for j in comp.get("jobs") if isinstance(comp.get("jobs"), list) else []:
                if isinstance(j, dict) and isinstance(j.get("baseline"), dict):
                    out[(j.get("scene"), j.get("backend"))] = (j["baseline"], comp_dir, Path(baseline_dir))
            for j in comp.get("new_jobs") if isinstance(comp.get("new_jobs"), list) else []:
                if isinstance(j, dict):
                    missing = {"run": str(baseline_dir), "status": "missing", "reason": "no such job in the baseline run"}
                    out[(j.get("scene"), j.get("backend"))] = (missing, folder, Path(baseline_dir))
            return out
    runs = (data or {}).get("runs") if isinstance(data, dict) else None
    for e in runs if isinstance(runs, list) else []:
        rec = e.get("baseline") if isinstance(e, dict) else None
        if isinstance(rec, dict) and (not baseline_dir or _same_folder(rec.get("run"), baseline_dir)):
            base = Path(baseline_dir) if baseline_dir else recorded_baseline(folder, rec.get("run"))
            out[(e.get("scene"), e.get("backend"))] = (rec, folder, base)
    return out


def baseline_image(found, kind):
    """The baseline's render or the z-map of one record from ``baseline_records``, or None (also for
    a path that would leave its folder)."""
    if found is None:
        return None
    rec, root, base = found
    if kind == "baseline_render":
        return inside(base, rec.get("image")) if base is not None else None
    if kind == "baseline_zscore":
        return inside(root, rec.get("zmap"))
    return None
