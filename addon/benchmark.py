"""The benchmark panel's logic, kept out of draw code so that headless tests can call it:
run the batch runner in the background on the selected scenes, follow and cancel it, and load
its result images into Blender.

A run exports the selected scenes to IR JSON in-process (Blender's own Python need not have bpy
as a module in a child process), then starts batch/run.py on those files as a child process
with the same Python and sys.path. Results land in an ordinary outputs folder: the panel reads
runs started from the command line the same way.
"""
import datetime as dt
from pathlib import Path

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, StringProperty

from ..batch import backends
from ..batch.jobs import background as background_job
from ..batch.report import results
from ..exporters import extract_blender, ir_json, validate

_ACTIVE = {}  # "job": the BackgroundRun in progress (Python objects cannot live in properties)


class RunSettings(bpy.types.PropertyGroup):
    spp: IntProperty(name="Samples", default=0, min=0, description="Samples per pixel (0: each scene's own)")
    scale: FloatProperty(name="Resolution Scale", default=0.25, min=0.01, max=4.0)
    use_mitsuba: BoolProperty(name="Mitsuba 3", default=True)
    only_active: BoolProperty(name="Active Scene Only", default=False)
    output_parent: StringProperty(name="Outputs Folder", subtype="DIR_PATH", default="",
                                  description="Where outputs-YYYYmmdd-HHMMSS folders go (default: next to the .blend)")
    output_dir: StringProperty(name="Results", subtype="DIR_PATH", default="",
                               description="The outputs folder shown in the results view")
    status: StringProperty(name="Status", default="")


def settings(context):
    return context.window_manager.spectral_bench_run


def output_parent(s):
    if s.output_parent:
        return Path(bpy.path.abspath(s.output_parent))
    return Path(bpy.data.filepath).parent if bpy.data.filepath else Path.cwd()


def backend_states():
    """[(name, available, reason)] for the panel (unavailable ones greyed out with the reason)."""
    out = []
    for name in backends.BACKENDS:
        ok, why = backends.get(name).availability()
        out.append((name, ok, why))
    return out


def benchmark_scenes(context, s):
    scenes = [context.scene] if s.only_active else [sc for sc in bpy.data.scenes if sc.spectral_bench.case]
    return scenes


def start_run(context):
    """Export the selected scenes and start the batch runner on them; returns the BackgroundRun."""
    s = settings(context)
    if _ACTIVE.get("job") and _ACTIVE["job"].running():
        raise RuntimeError("a benchmark run is already in progress")
    out = output_parent(s) / dt.datetime.now().strftime("outputs-%Y%m%d-%H%M%S")
    inputs, problems = [], []
    for scene in benchmark_scenes(context, s):
        try:
            data = extract_blender.extract_scene(scene)
        except validate.SceneError as exc:
            problems.append(str(exc))
            continue
        inputs.append(ir_json.write(data, out.parent / f"{out.name}.inputs" / f"{scene.name}.json"))
    if not inputs:
        raise RuntimeError("no scene could be exported: " + "; ".join(problems))
    names = [n for n, on in (("mitsuba", s.use_mitsuba),) if on]
    args = [a for n in names for a in ("-r", n)] + ["--scale", str(s.scale)]
    if s.spp:
        args += ["--spp", str(s.spp)]
    job = background_job.BackgroundRun(inputs, out, total_jobs=len(inputs) * max(len(names), 1), extra_args=args)
    job.export_problems = problems
    _ACTIVE["job"] = job.start()
    s.output_dir = str(out)
    s.status = f"running: 0/{job.total} jobs" + (f" ({len(problems)} scenes not exported)" if problems else "")
    return job


def poll_run(context):
    """Update the status text; returns True while the run goes on."""
    job = _ACTIVE.get("job")
    if job is None:
        return False
    done, total, finished = job.progress()
    s = settings(context)
    if finished:
        word = "cancelled" if job.cancelled else ("passed" if job.returncode() == 0 else "finished with failures")
        s.status = f"{word}: {done}/{total} jobs"
        return False
    s.status = f"running: {done}/{total} jobs"
    return True


def cancel_run(context):
    job = _ACTIVE.get("job")
    if job is not None:
        job.cancel()
        poll_run(context)


def load_result_image(out_dir, scene, backend, kind):
    """Load one result EXR as an Image datablock (reusing one already loaded from that file)."""
    path = results.image_path(out_dir, scene, backend, kind)
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
    cancel = _ACTIVE.get("job")
    if cancel is not None and cancel.running():
        cancel.cancel()
    del bpy.types.WindowManager.spectral_bench_run
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
