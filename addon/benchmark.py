"""The benchmark panel's logic, kept out of draw code so that headless tests can call it:
choose scenes (the canonical ones shipped with the extension, or the open file's annotated
ones), backends (every one in batch/backends.BACKENDS, and every renderer declared in the
preferences' renderers files, each with its availability), samples, scale and passes; run the
batch runner in the background, follow and cancel it; read its results and load their images
into Blender.

A run exports the chosen scenes to IR JSON in-process (Blender's own Python has no bpy module in
a child process), then starts batch/run.py on those files as a child process with the same
Python and sys.path (so the extension's bundled wheels are found). Results land in an ordinary
outputs folder: the panel reads runs started from the command line the same way.
"""
import collections
import datetime as dt
import tempfile
import time
from pathlib import Path

import bpy
from bpy.props import EnumProperty, FloatProperty, IntProperty, StringProperty

from ..batch import backends, run_folder
from ..batch.backends import command
from ..batch.jobs import background as background_job
from ..batch.report import html as report_html
from ..batch.verdict import status as verdict_status
from ..exporters import extract_blender, ir_json, validate
from ..exporters import names as ir_names
from . import canonical, preferences

_ACTIVE = {}  # "job": the BackgroundRun in progress (Python objects cannot live in properties)

SCENE_SOURCES = [
    ("CANONICAL", "Canonical Scenes", "The scenes shipped with the extension (scenes.blend), read without opening it"),
    ("FILE", "This File", "Every scene of the open file (annotated in Scene > Spectral Bench)"),
    ("ACTIVE", "Active Scene", "Only the active scene of the open file"),
]
STATUS_ICONS = {"ok": "CHECKMARK", "failed": "ERROR", "unjudged": "QUESTION", "known": "INFO", "fixed": "CHECKMARK",
                "skipped": "CANCEL", "unsupported": "CANCEL"}
STOKES = run_folder.STOKES
# the batch runner's exit status (batch/verdict/status.py) as the panel says it
FINISHED_WORDS = {0: "passed", 1: "failed", 2: "refused (a bad option or a folder in use: see the log)",
                  3: "finished, some renders unjudged", 4: "nothing ran (every job skipped or unsupported)",
                  130: "interrupted"}  # batch/verdict/status.py


# --flip auto|on|off (issue 45: FLIP where a verdict is not ok, by default)
FLIP_CHOICES = [("AUTO", "Where not ok", "Only for renders whose verdict is not ok (failed, known, fixed, unjudged): an "
                 "ok render differs from its reference by noise (--flip auto, the default)"),
                ("ON", "Every render", "For every render judged against a reference (--flip on)"),
                ("OFF", "Off", "Never (--flip off)")]


class RunSettings(bpy.types.PropertyGroup):
    scene_source: EnumProperty(name="Scenes", items=SCENE_SOURCES, default="CANONICAL")
    canonical_scene: EnumProperty(name="Canonical Scene", items=canonical.scene_items,
                                  description="Which canonical scene to run, open or append")
    # off by default: the RGB backends (batch/backends: DEFAULT is the spectral group)
    backends_off: StringProperty(name="Backends Off", options={"HIDDEN"},
                                 default=",".join(n for n in backends.BACKENDS if n not in backends.DEFAULT),
                                 description="Comma-separated backends switched off (all others run)")
    # declared renderers (names checked by command.parse: never a comma) whose choice differs from
    # the command line's default (on when the declaration joins the group "spectral", else off)
    declared_toggled: StringProperty(name="Declared Renderers Toggled", options={"HIDDEN"}, default="",
                                     description="Comma-separated declared renderers chosen against their default")
    spp: IntProperty(name="Samples", default=0, min=0, description="Samples per pixel (0: each scene's own)")
    scale: FloatProperty(name="Resolution Scale", default=0.25, min=0.01, max=4.0,
                         description="Resolution scale; an integer fraction of the reference's (1/2, 1/4, 1/8) "
                                     "can be judged against it")
    passes: IntProperty(name="Passes", default=2, min=1, max=64,
                        description="Independent passes per render: two or more give the render's own noise")
    flip: EnumProperty(name="HDR-FLIP", default="AUTO", items=FLIP_CHOICES,
                       description="HDR-FLIP against the reference (the runner's --flip)")
    output_parent: StringProperty(name="Outputs Folder", subtype="DIR_PATH", default="",
                                  description="Where outputs-YYYYmmdd-HHMMSS folders go (default: next to the "
                                              ".blend, or the extension's user folder)")
    output_dir: StringProperty(name="Results", subtype="DIR_PATH", default="",
                               description="The outputs folder shown in the results view")
    baseline_dir: StringProperty(name="Baseline", subtype="DIR_PATH", default="",
                                 description="A previous run's outputs folder to compare the results with "
                                             "(batch/compare_runs.py; changed jobs first)")
    status: StringProperty(name="Status", default="")


def settings(context):
    return context.window_manager.spectral_bench_run


def output_parent(s):
    if s.output_parent:
        return Path(bpy.path.abspath(s.output_parent))
    if bpy.data.filepath:
        return Path(bpy.data.filepath).parent
    try:
        return Path(bpy.utils.extension_path_user(preferences.ROOT_PACKAGE, path="outputs", create=True))
    except (ValueError, AttributeError, RuntimeError):  # not installed as an extension
        return Path(tempfile.gettempdir()) / "spectral_bench_outputs"


# -- backends -------------------------------------------------------------------------------------
_AVAILABILITY = {}  # name: (time checked, available, reason); the panel redraws often
AVAILABILITY_TTL_S = 10.0


def availability(name):
    now = time.monotonic()
    checked = _AVAILABILITY.get(name)
    if checked is None or now - checked[0] > AVAILABILITY_TTL_S:
        checked = (now, *backends.get(name).availability())
        _AVAILABILITY[name] = checked
    return checked[1], checked[2]


def backend_states(s=None):
    """[(name, available, reason, selected)] for every backend the batch runner knows: a backend
    added to batch/backends appears here (and in the panel) without any change to the extension."""
    off = set(filter(None, (s.backends_off if s is not None else "").split(",")))
    out = []
    for name in backends.BACKENDS:
        ok, why = availability(name)
        out.append((name, ok, why, name not in off))
    return out


# -- declared renderers (batch/backends/command.py) -----------------------------------------------
_FILES = {}  # path: ((mtime_ns, size), {name: declaration} or None, problem or None)
_DECLARED_AVAILABILITY = {}  # (name, program's declaration): (time checked, available, reason)
TEXT_LIMIT = 200  # characters of file-given text on one panel line


def one_line(text, limit=TEXT_LIMIT):
    """Text from a renderers file (a description, an error quoting a value) as one panel line:
    control characters as spaces, at most ``limit`` characters."""
    flat = "".join(" " if not c.isprintable() else c for c in str(text))
    return flat if len(flat) <= limit else flat[:limit - 3] + "..."


def read_renderers_file(path):
    """({name: declaration}, None), or (None, the DeclarationError's message naming the file and
    the problem): read by batch/backends/command.py, again only when the file changes."""
    path = Path(path)
    try:
        st = path.stat()
        stamp = (st.st_mtime_ns, st.st_size)
    except OSError:
        stamp = None
    cached = _FILES.get(path)
    if cached is not None and stamp is not None and cached[0] == stamp:
        return cached[1], cached[2]
    try:
        found, problem = command.load_file(path), None
    except command.DeclarationError as exc:
        found, problem = None, str(exc)
    _FILES[path] = (stamp, found, problem)
    return found, problem


def declared_renderers(paths):
    """What the renderers files declare, as plain data: {"renderers": {name: declaration},
    "files": [{"path", "names", "problem"}]}. A file that cannot be read, or that declares a
    name an earlier file declared differently (the runner refuses that), has a problem naming
    it and adds no renderer; it is not passed to a run, and the other files still are."""
    renderers, origin, files = {}, {}, []
    for path in paths:
        found, problem = read_renderers_file(path)
        if found is not None:
            twice = [n for n in found if n in renderers and renderers[n] != found[n]]
            if twice:
                found, problem = None, (f"renderer {twice[0]!r} is declared twice: in {origin[twice[0]]} and in "
                                        f"{path} (this file is left out)")
        if found is not None:
            for name, decl in found.items():
                renderers[name], origin[name] = decl, path
        files.append({"path": Path(path), "names": sorted(found or ()), "problem": problem})
    return {"renderers": renderers, "files": files}


def declared_availability(name, decl):
    """(available, reason) of a declared renderer (CommandBackend.availability), checked again
    after AVAILABILITY_TTL_S."""
    key = (name, tuple(decl["command"][:1]), decl["here"])
    now = time.monotonic()
    checked = _DECLARED_AVAILABILITY.get(key)
    if checked is None or now - checked[0] > AVAILABILITY_TTL_S:
        checked = (now, *backends.CommandBackend(name, decl).availability())
        _DECLARED_AVAILABILITY[key] = checked
    return checked[1], checked[2]


def declared_default(declared):
    """The declared renderers a run chooses unless told otherwise: those the command line's
    default (-r spectral) includes, i.e. those joining the group "spectral"."""
    return set(backends.expand([], declared)) & set(declared)


def describe_declaration(decl):
    """One line of what a declaration says it does: reads, writes, models (and its description)."""
    text = f"reads {decl['reads']}, writes {decl['writes']}, models {', '.join(decl['models']) or 'nothing'}"
    if decl.get("description"):
        text = f"{decl['description']} ({text})"
    return one_line(text)


def declared_states(s=None, declared=None):
    """[(name, available, reason, selected, declaration)] for every declared renderer, in the
    order the files declare them."""
    declared = declared or {}
    toggled = set(filter(None, (s.declared_toggled if s is not None else "").split(",")))
    default = declared_default(declared)
    out = []
    for name, decl in declared.items():
        ok, why = declared_availability(name, decl)
        out.append((name, ok, one_line(why), (name in default) != (name in toggled), decl))
    return out


def chosen_backends(s, declared=None):
    """The available backends and declared renderers chosen for the next run, built-ins first."""
    return ([name for name, ok, _why, on in backend_states(s) if ok and on]
            + [name for name, ok, _why, on, _decl in declared_states(s, declared) if ok and on])


def toggle_backend(s, name, declared=None):
    if name in backends.BACKENDS:
        off = set(filter(None, s.backends_off.split(",")))
        off ^= {name}
        s.backends_off = ",".join(sorted(off))
    elif name in (declared or {}):
        toggled = set(filter(None, s.declared_toggled.split(",")))
        toggled ^= {name}
        s.declared_toggled = ",".join(sorted(toggled))
    else:
        raise KeyError(f"unknown backend {name!r} (known: {', '.join([*backends.BACKENDS, *(declared or {})])})")


def run_arguments(s, files, names):
    """The runner's arguments for the backends ``names`` (one argv item each: no shell, no
    quoting): every readable renderers file as --renderers FILE (absolute), each name as -r NAME
    (a built-in or a name command.parse accepted: never starting with '-'), then the settings."""
    args = [a for path in files for a in ("--renderers", str(Path(path).resolve()))]
    args += [a for n in names for a in ("-r", n)] + ["--scale", str(s.scale), "--passes", str(s.passes)]
    if s.spp:
        args += ["--spp", str(s.spp)]
    if s.flip != "AUTO":  # auto is the runner's default
        args += ["--flip", s.flip.lower()]
    return args


# -- scenes ---------------------------------------------------------------------------------------
def scenes_to_run(context, s):
    """[(name, IR dict or SceneError)] of the chosen scenes."""
    if s.scene_source == "CANONICAL":
        if not canonical.available():
            raise RuntimeError(f"the extension's scenes.blend is missing ({canonical.BLEND})")
        names = None if s.canonical_scene in ("", canonical.ALL) else [s.canonical_scene]
        return canonical.extract(names)
    chosen = [context.scene] if s.scene_source == "ACTIVE" else [sc for sc in bpy.data.scenes if sc.spectral_bench.case]
    out = []
    for scene in chosen:
        try:
            data = extract_blender.extract_scene(scene)
            out.append((data["name"], data))
        except validate.SceneError as exc:
            out.append((exc.scene, exc))
    return out


def _active_scene(context):
    """[(name, IR dict or SceneError)] of the scene open in Blender."""
    try:
        data = extract_blender.extract_scene(context.scene)
        return [(data["name"], data)]
    except validate.SceneError as exc:
        return [(exc.scene, exc)]


# -- running --------------------------------------------------------------------------------------
STUDY_RGB = ("cycles", "luxcore")  # RGB renderers a study adds when chosen (Mitsuba renders both sides)


def start_run(context, study=None):
    """Export the chosen scenes and start the batch runner on them; returns the BackgroundRun.
    ``study`` ("spectral-vs-rgb"): the open scene through that study instead (Mitsuba spectral and
    RGB, plus the chosen RGB renderers; no reference needed)."""
    s = settings(context)
    if _ACTIVE.get("job") and _ACTIVE["job"].running():
        raise RuntimeError("a benchmark run is already in progress")
    found = declared_renderers(preferences.renderers_files(context))
    names = chosen_backends(s, found["renderers"])
    if study:
        names = ["mitsuba"] + [n for n in names if n in STUDY_RGB]
    if not names:
        raise RuntimeError("no available backend is selected")
    search = preferences.reference_folders(context)
    if not search and not study:
        raise RuntimeError("no references to judge against: choose a references folder in the extension's "
                           "preferences, or use the extension's own references")
    out = output_parent(s) / dt.datetime.now().strftime("outputs-%Y%m%d-%H%M%S")
    inputs, problems = [], []
    for name, data in (_active_scene(context) if study else scenes_to_run(context, s)):
        if isinstance(data, Exception):
            problems.append(str(data))
            continue
        # the IR's name, never Blender's: it is checked to name a file (exporters/names.py)
        inputs.append(ir_json.write(data, out.parent / f"{out.name}.inputs" / f"{ir_names.file_stem(data['name'])}.json"))
    if not inputs:
        raise RuntimeError("no scene could be exported: " + "; ".join(problems))
    readable = [f["path"] for f in found["files"] if f["problem"] is None]
    args = run_arguments(s, readable, names)
    args += [a for _origin, folder in search for a in ("--references", str(folder))]
    if study:
        args += ["--study", study]
    per_scene = len(names) + 1 if study else len(names)  # a study: the spectral render and one per RGB route
    job = background_job.BackgroundRun(inputs, out, total_jobs=len(inputs) * per_scene, extra_args=args)
    job.export_problems = problems
    job.renderers_problems = [f["problem"] for f in found["files"] if f["problem"]]  # files left out
    _ACTIVE["job"] = job.start()
    s.output_dir = str(out)
    s.status = f"running: 0/{job.total} jobs" + (f" ({len(problems)} scenes not exported)" if problems else "")
    return job


def active_job():
    return _ACTIVE.get("job")


def progress_fraction():
    job = active_job()
    if job is None or not job.total:
        return None
    return min(job.done_jobs() / job.total, 1.0)


def poll_run(context):
    """Update the status text; returns True while the run goes on."""
    job = active_job()
    if job is None:
        return False
    done, total, finished = job.progress()
    s = settings(context)
    if finished:
        if job.cancelled:
            word = "cancelled"
            if run_folder.load(job.out_dir) is not None and not (job.out_dir / run_folder.REPORT).exists():
                report_html.write(job.out_dir)  # the report of what finished
        else:
            word = FINISHED_WORDS.get(job.returncode(), f"stopped (exit {job.returncode()})")
        data = run_folder.load(job.out_dir)
        counts = collections.Counter(r.get("status") for r in (data.entries("runs") if data is not None else []))
        tally = ", ".join(f"{counts[k]} {k}" for k in STATUS_ICONS if counts[k])
        s.status = f"{word}: {done}/{total} jobs" + (f" ({tally})" if tally else "")
        return False
    s.status = f"running: {done}/{total} jobs"
    return True


def cancel_run(context):
    """Stop the run; returns the number of finished jobs kept (None when nothing was running)."""
    job = active_job()
    if job is None or not job.running():
        return None
    job.cancel()
    poll_run(context)
    return job.done_jobs()


def report_path(out_dir):
    return run_folder.report_page(bpy.path.abspath(out_dir)) if out_dir else None


# -- results --------------------------------------------------------------------------------------
def result_rows(out_dir, baseline_dir=None):
    """[(scene, backend, run entry)] of an outputs folder: failures first, passes last; with
    baseline records (a chosen baseline folder, or the run's own --baseline), changed jobs first."""
    status = run_folder.last_status(out_dir, resolved=True) if out_dir else {}  # shown: paths absolute
    rows = [(scene, backend, run) for scene, per in status.items() for backend, run in per.items()]
    found = baseline_records(out_dir, baseline_dir)
    from ..batch.verdict import baseline
    return sorted(rows, key=lambda r: (baseline.order((found.get((r[0], r[1])) or (None,))[0]) if found else 0,
                                       verdict_status.rank(r[2].get("status")), r[0], r[1]))


# -- a baseline: a previous run to compare with (batch/verdict/baseline.py, batch/compare_runs.py) --
def baseline_records(out_dir, baseline_dir=None):
    """{(scene, backend): (record, z-map folder, baseline folder)}: batch/run_folder.py baseline_records."""
    if not out_dir:
        return {}
    base = bpy.path.abspath(baseline_dir) if baseline_dir else None
    return run_folder.baseline_records(out_dir, run_folder.load(out_dir) or {}, base)


def compare_with_baseline(out_dir, baseline_dir):
    """Compare the results folder with the baseline folder (batch/compare_runs.py, written to
    OUT/compare, or the first free OUT/compare-N: an earlier comparison is never deleted); returns the
    comparison. Raises run_folder.NotARun for a folder that is not a run, compare_runs.OutputRefused
    for a results folder that is the baseline or inside it."""
    from ..batch import compare_runs
    out_dir, base = Path(bpy.path.abspath(out_dir)), Path(bpy.path.abspath(baseline_dir))
    return compare_runs.run(base, out_dir)[0]  # into OUT/compare, or the first free OUT/compare-N


def baseline_word(found):
    """The baseline verdict's word: its status, or "unstable" (batch/verdict/baseline.py shown_status)."""
    from ..batch.verdict import baseline
    return baseline.shown_status(found[0])


def baseline_line(found):
    """One line for the panel: the baseline verdict and how much."""
    from ..batch.verdict import baseline
    rec = found[0]
    how = baseline.how_much(rec)
    return f"baseline: {baseline.shown_status(rec)}" + (f": {how}" if how else "")


def status_icon(status):
    return STATUS_ICONS.get(status, "DOT")


def image_kinds(out_dir, scene, backend, run=None, found=None):
    """Image kinds present for one result (batch/run_folder.py ``Job.kinds``): render, reference,
    differences, FLIP, z-score, and for Stokes output S0..S3; with a baseline record (``found``),
    the baseline's render and the two-sample z-map. The files come from the job's record as
    metrics.json holds it (``run``, the row's copy with paths made absolute for showing, is not used)."""
    kinds = run_folder.job(out_dir, scene, backend).kinds()
    if found is not None:
        kinds += [k for k in run_folder.BASELINE_KINDS if run_folder.baseline_image(found, k)]
    return kinds


def load_result_image(out_dir, scene, backend, kind, baseline_dir=None):
    """Load one result EXR as an Image datablock (reusing one already loaded from that file): its
    path and RGB copy from batch/run_folder.py (differences and Stokes components written when asked for)."""
    if kind in run_folder.BASELINE_KINDS:
        path = run_folder.baseline_image(baseline_records(out_dir, baseline_dir).get((scene, backend)), kind)
    else:
        path = run_folder.job(out_dir, scene, backend).path(kind, make=True)
    path = run_folder.plain_rgb(path) if path is not None and kind not in STOKES else path
    if path is None:
        raise FileNotFoundError(f"no {kind} image for {scene} / {backend} in {out_dir}")
    image = bpy.data.images.load(str(path), check_existing=True)
    image.reload()
    image.name = f"{scene} {backend} {kind}"
    return image


CLASSES = (RunSettings,)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.WindowManager.spectral_bench_run = bpy.props.PointerProperty(type=RunSettings)


def unregister():
    job = _ACTIVE.get("job")
    if job is not None and job.running():
        job.cancel()
    del bpy.types.WindowManager.spectral_bench_run
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
