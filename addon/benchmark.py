"""The benchmark panel's logic, kept out of draw code so that headless tests can call it:
choose scenes (the canonical ones shipped with the extension, or the open file's annotated
ones), backends (every one in batch/backends.BACKENDS, with its availability), samples, scale
and passes; run the batch runner in the background, follow and cancel it; read its results and
load their images into Blender.

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
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ..batch import backends, exr
from ..batch.jobs import background as background_job
from ..batch.report import html as report_html
from ..batch.report import results
from ..exporters import extract_blender, ir_json, validate
from ..exporters import names as ir_names
from . import canonical, preferences

_ACTIVE = {}  # "job": the BackgroundRun in progress (Python objects cannot live in properties)

SCENE_SOURCES = [
    ("CANONICAL", "Canonical Scenes", "The scenes shipped with the extension (scenes.blend), read without opening it"),
    ("FILE", "This File", "Every scene of the open file (annotated in Scene > Spectral Bench)"),
    ("ACTIVE", "Active Scene", "Only the active scene of the open file"),
]
# results view: failures first, statuses the view does not know next, passes last
STATUS_ORDER = {"failed": 0, "unjudged": 2, "known": 3, "fixed": 4, "unsupported": 5, "skipped": 6, "ok": 7}
STATUS_ICONS = {"ok": "CHECKMARK", "failed": "ERROR", "unjudged": "QUESTION", "known": "INFO", "fixed": "CHECKMARK",
                "skipped": "CANCEL", "unsupported": "CANCEL"}
STOKES = ("S0", "S1", "S2", "S3")
# the batch runner's exit status (batch/verdict/status.py) as the panel says it
FINISHED_WORDS = {0: "passed", 1: "failed", 2: "refused (a bad option or a folder in use: see the log)",
                  3: "finished, some renders unjudged", 4: "nothing ran (every job skipped or unsupported)",
                  130: "interrupted"}  # batch/verdict/status.py


class RunSettings(bpy.types.PropertyGroup):
    scene_source: EnumProperty(name="Scenes", items=SCENE_SOURCES, default="CANONICAL")
    canonical_scene: EnumProperty(name="Canonical Scene", items=canonical.scene_items,
                                  description="Which canonical scene to run, open or append")
    # off by default: the RGB backends (batch/backends: DEFAULT is the spectral group)
    backends_off: StringProperty(name="Backends Off", options={"HIDDEN"},
                                 default=",".join(n for n in backends.BACKENDS if n not in backends.DEFAULT),
                                 description="Comma-separated backends switched off (all others run)")
    spp: IntProperty(name="Samples", default=0, min=0, description="Samples per pixel (0: each scene's own)")
    scale: FloatProperty(name="Resolution Scale", default=0.25, min=0.01, max=4.0,
                         description="Resolution scale; an integer fraction of the reference's (1/2, 1/4, 1/8) "
                                     "can be judged against it")
    passes: IntProperty(name="Passes", default=2, min=1, max=64,
                        description="Independent passes per render: two or more give the render's own noise")
    use_flip: BoolProperty(name="HDR-FLIP", default=True, description="Compute HDR-FLIP against the reference")
    output_parent: StringProperty(name="Outputs Folder", subtype="DIR_PATH", default="",
                                  description="Where outputs-YYYYmmdd-HHMMSS folders go (default: next to the "
                                              ".blend, or the extension's user folder)")
    output_dir: StringProperty(name="Results", subtype="DIR_PATH", default="",
                               description="The outputs folder shown in the results view")
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


def chosen_backends(s):
    return [name for name, ok, _why, on in backend_states(s) if ok and on]


def toggle_backend(s, name):
    if name not in backends.BACKENDS:
        raise KeyError(f"unknown backend {name!r}")
    off = set(filter(None, s.backends_off.split(",")))
    off ^= {name}
    s.backends_off = ",".join(sorted(off))


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


# -- running --------------------------------------------------------------------------------------
def start_run(context):
    """Export the chosen scenes and start the batch runner on them; returns the BackgroundRun."""
    s = settings(context)
    if _ACTIVE.get("job") and _ACTIVE["job"].running():
        raise RuntimeError("a benchmark run is already in progress")
    names = chosen_backends(s)
    if not names:
        raise RuntimeError("no available backend is selected")
    search = preferences.reference_folders(context)
    if not search:
        raise RuntimeError("no references to judge against: choose a references folder in the extension's "
                           "preferences, or use the extension's own references")
    out = output_parent(s) / dt.datetime.now().strftime("outputs-%Y%m%d-%H%M%S")
    inputs, problems = [], []
    for name, data in scenes_to_run(context, s):
        if isinstance(data, Exception):
            problems.append(str(data))
            continue
        # the IR's name, never Blender's: it is checked to name a file (exporters/names.py)
        inputs.append(ir_json.write(data, out.parent / f"{out.name}.inputs" / f"{ir_names.file_stem(data['name'])}.json"))
    if not inputs:
        raise RuntimeError("no scene could be exported: " + "; ".join(problems))
    args = [a for n in names for a in ("-r", n)] + ["--scale", str(s.scale), "--passes", str(s.passes)]
    args += [a for _origin, folder in search for a in ("--references", str(folder))]
    if s.spp:
        args += ["--spp", str(s.spp)]
    if not s.use_flip:
        args.append("--no-flip")
    job = background_job.BackgroundRun(inputs, out, total_jobs=len(inputs) * len(names), extra_args=args)
    job.export_problems = problems
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
            if results.load(job.out_dir) is not None and not (job.out_dir / "report.html").exists():
                report_html.write(job.out_dir)  # the report of what finished
        else:
            word = FINISHED_WORDS.get(job.returncode(), f"stopped (exit {job.returncode()})")
        data = results.load(job.out_dir) or {}
        counts = collections.Counter(r.get("status") for r in data.get("runs", []))
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
    path = Path(bpy.path.abspath(out_dir)) / "report.html" if out_dir else None
    return path if path is not None and path.is_file() else None


# -- results --------------------------------------------------------------------------------------
def result_rows(out_dir):
    """[(scene, backend, run entry)] of an outputs folder: failures first, passes last."""
    status = results.last_status(out_dir) if out_dir else {}
    rows = [(scene, backend, run) for scene, per in status.items() for backend, run in per.items()]
    return sorted(rows, key=lambda r: (STATUS_ORDER.get(r[2]["status"], 1), r[0], r[1]))


def status_icon(status):
    return STATUS_ICONS.get(status, "DOT")


def image_kinds(out_dir, scene, backend, run=None):
    """Image kinds present for one result: render, reference, differences, FLIP, z-score, and for
    Stokes output S0..S3."""
    kinds = [k for k in results.IMAGE_KINDS if results.image_path(out_dir, scene, backend, k)]
    channels = (run or {}).get("channels") or []
    if results.image_path(out_dir, scene, backend, "render") and all(f"{k}.R" in channels for k in STOKES):
        kinds += list(STOKES)
    return kinds


def stokes_path(out_dir, scene, backend, component):
    """An RGB EXR of one Stokes component of the render (written once beside it)."""
    render = results.image_path(out_dir, scene, backend, "render")
    if render is None:
        return None
    path = render.parent / f"stokes_{component}.exr"
    if not path.is_file():
        try:
            rgb = exr.read_rgb(render, prefix=f"{component}.")
        except ValueError:
            return None
        exr.write(path, rgb)
    return path


def plain_rgb(path):
    """``path`` itself if it holds only R, G, B (and A); else an RGB copy beside it. Blender reads an
    EXR whose channels have dotted names (stderr.R, S0.R: a render with passes or Stokes output) as
    a multilayer image whose pixels a script cannot read and an Image Editor shows by layer."""
    names = set(exr.read(path))
    if names <= {"R", "G", "B", "A"}:
        return path
    rgb = path.with_name(f"{path.stem}_rgb.exr")
    if not rgb.is_file() or rgb.stat().st_mtime < path.stat().st_mtime:
        exr.write(rgb, exr.read_rgb(path))
    return rgb


def load_result_image(out_dir, scene, backend, kind):
    """Load one result EXR as an Image datablock (reusing one already loaded from that file)."""
    if kind in STOKES:
        path = stokes_path(out_dir, scene, backend, kind)
    else:
        path = results.image_path(out_dir, scene, backend, kind)
        path = plain_rgb(path) if path is not None else None
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
