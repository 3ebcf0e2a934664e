"""Operators: File > Export entries for the generic JSON, Mitsuba 3 and ART (scriptable as
bpy.ops.spectral_bench.export_json / export_mitsuba / export_art), the canonical scenes (open,
append), the benchmark run (start, cancel, backends, renderers files) and its results (images,
report). Logic lives in exporters/, batch/ and addon/benchmark.py; these stay thin and report
through self.report.
Operators that change the file's data are undoable (bl_options UNDO)."""
import webbrowser
from pathlib import Path

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper

from ..batch import blend_input
from ..batch import run_folder
from ..exporters import art_writer, extract_blender, ir_json, mitsuba_writer, validate
from . import benchmark, canonical, preferences


def export_scene(scene, fmt, path):
    """Export one Blender scene; returns the written path. Raises validate.SceneError."""
    data = extract_blender.extract_scene(scene)
    export_scene.last_warnings = data.get("warnings", [])  # what was converted or lost (docs/scene-format.md 11)
    if fmt == "json":
        return ir_json.write(data, path)
    if fmt == "art":
        out, missing = art_writer.write(data, Path(path))
        export_scene.last_unsupported = missing
        return out
    return mitsuba_writer.write(data, Path(path))


class _ExportBase:
    fmt = ""

    def execute(self, context):
        try:
            out = export_scene(context.scene, self.fmt, self.filepath)
        except validate.SceneError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for obj, field, msg in getattr(export_scene, "last_unsupported", []) if self.fmt == "art" else []:
            self.report({"WARNING"}, f"ART cannot express {obj}.{field}: {msg} (left out)")
        for w in getattr(export_scene, "last_warnings", []):
            self.report({"WARNING"}, f"converted {w['object']}.{w['field']}: {w['message']}")
        self.report({"INFO"}, f"wrote {out}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_export_json(_ExportBase, bpy.types.Operator, ExportHelper):
    """Export the active scene as generic spectral-bench JSON (the scene IR)"""
    bl_idname = "spectral_bench.export_json"
    bl_label = "Export Spectral Bench JSON"
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})
    fmt = "json"


class _FolderExportBase(_ExportBase):
    """An export that writes a folder: the file browser picks a directory."""
    filepath: StringProperty(subtype="DIR_PATH")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


class SPECTRAL_BENCH_OT_export_mitsuba(_FolderExportBase, bpy.types.Operator):
    """Export the active scene as a Mitsuba 3 folder (scene.xml, meshes, spectra)"""
    bl_idname = "spectral_bench.export_mitsuba"
    bl_label = "Export Mitsuba 3 Scene Folder"
    fmt = "mitsuba"


class SPECTRAL_BENCH_OT_export_art(_FolderExportBase, bpy.types.Operator):
    """Export the active scene as an ART 2.1.2 folder (scene.arm, PLY meshes); what ART cannot
    express is reported, not substituted"""
    bl_idname = "spectral_bench.export_art"
    bl_label = "Export ART Scene Folder"
    fmt = "art"


def _spectrum_target(context, path):
    """The SpectrumProps at ``path`` (e.g. 'material.reflectance', 'light.radiance')."""
    owner_name, _, field = path.partition(".")
    owner = {"material": getattr(context, "material", None),
             "light": context.object.data if context.object and context.object.type == "LIGHT" else None,
             "world": context.scene.world}.get(owner_name)
    if owner is None or not field:
        raise ValueError(f"no spectrum at {path!r} in this context")
    return getattr(owner.spectral_bench, field)


def read_spectrum_file(path):
    """[(wavelength nm, value)] from a two-column text file (.spd, .csv, .txt; '#' comments)."""
    pairs = []
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        line = line.split("#", 1)[0].replace(",", " ").replace(";", " ").strip()
        if not line:
            continue
        parts = line.split()
        try:
            pairs.append((float(parts[0]), float(parts[1])))
        except (IndexError, ValueError) as exc:
            raise ValueError(f"{path}, line {n}: expected 'wavelength value', got {line!r}") from exc
    if not pairs:
        raise ValueError(f"{path}: no samples")
    return pairs


class SPECTRAL_BENCH_OT_load_spectrum(bpy.types.Operator, ImportHelper):
    """Fill a sampled spectrum from a two-column file (wavelength in nm, value)"""
    bl_idname = "spectral_bench.load_spectrum"
    bl_label = "Load Spectrum File"
    bl_options = {"UNDO"}
    target: StringProperty(default="material.reflectance", options={"HIDDEN"})
    filter_glob: StringProperty(default="*.spd;*.csv;*.txt", options={"HIDDEN"})

    def execute(self, context):
        try:
            props = _spectrum_target(context, self.target)
            pairs = read_spectrum_file(self.filepath)
        except (OSError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        props.kind = "SAMPLED"
        props.samples.clear()
        for w, v in pairs:
            item = props.samples.add()
            item.wavelength, item.value = w, v
        self.report({"INFO"}, f"{len(pairs)} samples from {self.filepath}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_spectrum_sample(bpy.types.Operator):
    """Add or remove a row of a sampled spectrum's table"""
    bl_idname = "spectral_bench.spectrum_sample"
    bl_label = "Edit Spectrum Table"
    bl_options = {"UNDO"}
    target: StringProperty(default="material.reflectance", options={"HIDDEN"})
    action: EnumProperty(items=[("ADD", "Add", ""), ("REMOVE", "Remove", "")])

    def execute(self, context):
        props = _spectrum_target(context, self.target)
        if self.action == "ADD":
            last = props.samples[-1].wavelength if len(props.samples) else 360.0
            item = props.samples.add()
            item.wavelength = last + 10.0
        elif len(props.samples):
            props.samples.remove(len(props.samples) - 1)
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_run_benchmark(bpy.types.Operator):
    """Render the chosen scenes in the background with the chosen backends and judge them"""
    bl_idname = "spectral_bench.run_benchmark"
    bl_label = "Run Benchmark"
    wait: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"},
                       description="Block until the run ends (scripts)")
    study: StringProperty(default="", options={"HIDDEN", "SKIP_SAVE"},
                          description="Run this study on the open scene instead (spectral-vs-rgb)")
    _timer = None

    @classmethod
    def description(cls, context, properties):
        if properties.study == "spectral-vs-rgb":
            return ("What does spectral rendering change for the open scene? Render it spectrally and in RGB "
                    "(no reference needed) and map where they differ (CIEDE2000, against both renders' noise)")
        return cls.__doc__

    def execute(self, context):
        try:
            job = benchmark.start_run(context, study=self.study or None)
        except RuntimeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for problem in job.export_problems:
            self.report({"WARNING"}, f"not exported: {problem}")
        for problem in job.renderers_problems:
            self.report({"WARNING"}, f"renderers file left out: {problem}")
        self.report({"INFO"}, f"started {job.total} jobs -> {job.out_dir}")
        if self.wait:
            job.wait()
            benchmark.poll_run(context)
            self.report({"INFO"}, benchmark.settings(context).status)
        return {"FINISHED"}

    def invoke(self, context, event):
        if self.execute(context) != {"FINISHED"}:
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.5, window=context.window)
        wm.progress_begin(0, 100)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        going = benchmark.poll_run(context)
        fraction = benchmark.progress_fraction()
        if fraction is not None:
            context.window_manager.progress_update(int(100 * fraction))
        context.workspace.status_text_set(f"Spectral Bench: {benchmark.settings(context).status}")
        for area in context.screen.areas:
            area.tag_redraw()
        if going:
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        context.window_manager.progress_end()
        context.workspace.status_text_set(None)
        self.report({"INFO"}, f"Spectral Bench: {benchmark.settings(context).status}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_cancel_benchmark(bpy.types.Operator):
    """Stop the running benchmark; finished results are kept"""
    bl_idname = "spectral_bench.cancel_benchmark"
    bl_label = "Cancel Benchmark"

    @classmethod
    def poll(cls, context):
        job = benchmark.active_job()
        return job is not None and job.running()

    def execute(self, context):
        kept = benchmark.cancel_run(context)
        if kept is None:
            self.report({"WARNING"}, "no benchmark is running")
            return {"CANCELLED"}
        self.report({"INFO"}, f"cancelled: {kept} finished jobs kept in {benchmark.settings(context).output_dir}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_toggle_backend(bpy.types.Operator):
    """Use this backend in the next run, or not"""
    bl_idname = "spectral_bench.toggle_backend"
    bl_label = "Toggle Backend"
    backend: StringProperty()

    def execute(self, context):
        declared = benchmark.declared_renderers(preferences.renderers_files(context))["renderers"]
        try:
            benchmark.toggle_backend(benchmark.settings(context), self.backend, declared)
        except KeyError as exc:
            self.report({"ERROR"}, exc.args[0])
            return {"CANCELLED"}
        return {"FINISHED"}


def _installed_preferences(op, context):
    """The extension's saved preferences, or None (reported) where it is not installed as one."""
    prefs = preferences.settings(context)
    if isinstance(prefs, preferences.Defaults):
        op.report({"ERROR"}, "renderers files are kept in the extension's preferences: install and enable the "
                             "extension (or run batch/run.py --renderers FILE)")
        return None
    return prefs


class SPECTRAL_BENCH_OT_add_renderers_file(bpy.types.Operator, ImportHelper):
    """Add a TOML file declaring renderers ([renderers.NAME] tables): they are listed with the
    backends and passed to every run as --renderers FILE"""
    bl_idname = "spectral_bench.add_renderers_file"
    bl_label = "Add Renderers File"
    filename_ext = ".toml"
    filter_glob: StringProperty(default="*.toml", options={"HIDDEN"})

    def execute(self, context):
        prefs = _installed_preferences(self, context)
        if prefs is None:
            return {"CANCELLED"}
        path = str(Path(bpy.path.abspath(self.filepath)).resolve())
        if any(str(Path(bpy.path.abspath(f.path)).resolve()) == path for f in prefs.renderers_files if f.path):
            self.report({"INFO"}, f"{path} is listed already")
            return {"FINISHED"}
        prefs.renderers_files.add().path = path
        context.preferences.is_dirty = True
        found = benchmark.declared_renderers([path])["files"][0]
        if found["problem"]:
            self.report({"WARNING"}, found["problem"])
        else:
            self.report({"INFO"}, f"{path}: {', '.join(found['names'])}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_remove_renderers_file(bpy.types.Operator):
    """Remove this renderers file from the list (the file itself stays)"""
    bl_idname = "spectral_bench.remove_renderers_file"
    bl_label = "Remove Renderers File"
    index: IntProperty(default=-1, options={"HIDDEN"})

    def execute(self, context):
        prefs = _installed_preferences(self, context)
        if prefs is None:
            return {"CANCELLED"}
        if not 0 <= self.index < len(prefs.renderers_files):
            self.report({"ERROR"}, f"no renderers file at position {self.index}")
            return {"CANCELLED"}
        prefs.renderers_files.remove(self.index)
        context.preferences.is_dirty = True
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_open_canonical_scenes(bpy.types.Operator):
    """Open the canonical scenes shipped with the extension (a copy: saving never changes the extension)"""
    bl_idname = "spectral_bench.open_canonical_scenes"
    bl_label = "Open Canonical Scenes"

    def invoke(self, context, event):
        if bpy.data.is_dirty:
            return context.window_manager.invoke_confirm(self, event)
        return self.execute(context)

    def execute(self, context):
        if not canonical.available():
            self.report({"ERROR"}, f"the extension's scenes.blend is missing ({canonical.BLEND})")
            return {"CANCELLED"}
        path = canonical.working_copy()
        self.report({"INFO"}, f"opening the canonical scenes (a copy in {path.parent})")
        blend_input.open_blend(path)  # its scripts off, whatever the Auto Run preference
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_append_canonical_scene(bpy.types.Operator):
    """Append one canonical scene (with its objects, materials and annotations) to this file"""
    bl_idname = "spectral_bench.append_canonical_scene"
    bl_label = "Append Canonical Scene"
    bl_options = {"REGISTER", "UNDO"}
    scene: StringProperty(name="Scene", description="Name of the canonical scene (default: the panel's choice)")

    def execute(self, context):
        name = self.scene or benchmark.settings(context).canonical_scene
        if name in ("", canonical.ALL):
            self.report({"ERROR"}, "choose one canonical scene to append")
            return {"CANCELLED"}
        try:
            scene, removed = canonical.append(name)
        except KeyError as exc:
            self.report({"ERROR"}, exc.args[0])
            return {"CANCELLED"}
        for line in removed:
            self.report({"WARNING"}, f"appending {name}: {line}")
        if getattr(context, "window", None) is not None:
            context.window.scene = scene
        self.report({"INFO"}, f"appended the canonical scene {name} as {scene.name!r}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_open_report(bpy.types.Operator):
    """Open the run's report.html in the web browser"""
    bl_idname = "spectral_bench.open_report"
    bl_label = "Open Report"

    def execute(self, context):
        out_dir = benchmark.settings(context).output_dir
        path = benchmark.report_path(out_dir)
        if path is None:
            self.report({"ERROR"}, f"no report.html in {out_dir or '(no results folder)'} (yet)")
            return {"CANCELLED"}
        webbrowser.open(path.resolve().as_uri())
        self.report({"INFO"}, f"opened {path}")
        return {"FINISHED"}


def _show_in_image_editor(context, image):
    """Show ``image`` in the screen's Image Editor; with none, in Blender's image window (as F11
    does). Nothing to show it in headless."""
    screen = getattr(context, "screen", None)
    if screen is None:
        return False
    for area in screen.areas:
        if area.type == "IMAGE_EDITOR":
            area.spaces.active.image = image
            return True
    bpy.ops.render.view_show("INVOKE_DEFAULT")
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "IMAGE_EDITOR":
                area.spaces.active.image = image
                return True
    return False


class SPECTRAL_BENCH_OT_load_result(bpy.types.Operator):
    """Load a result image (render, reference, a difference, FLIP, z-score or a Stokes component) into
    the Image Editor"""
    bl_idname = "spectral_bench.load_result"
    bl_label = "Load Result Image"
    bl_options = {"REGISTER", "UNDO"}
    scene: StringProperty()
    backend: StringProperty(default="mitsuba")
    kind: EnumProperty(items=[(k, k.replace("_", " ").title(), "") for k in run_folder.IMAGE_KINDS]
                       + [(k, k, f"Stokes component {k} of the render") for k in benchmark.STOKES]
                       + [("baseline_render", "Baseline Render", "The baseline run's render of this job"),
                          ("baseline_zscore", "Baseline Zscore", "Per-block z of this render against the baseline's, "
                                                                 "both on their own noise")])

    def execute(self, context):
        s = benchmark.settings(context)
        out_dir = bpy.path.abspath(s.output_dir)
        try:
            image = benchmark.load_result_image(out_dir, self.scene, self.backend, self.kind, s.baseline_dir)
        except (FileNotFoundError, RuntimeError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        _show_in_image_editor(context, image)
        self.report({"INFO"}, f"loaded {image.name}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_compare_baseline(bpy.types.Operator):
    """Compare the results with the baseline folder (batch/compare_runs.py): each render against the
    baseline's on both their noises, probes, status and time; written to a new folder compare/ (compare-2, ...) of the results"""
    bl_idname = "spectral_bench.compare_baseline"
    bl_label = "Compare with Baseline"

    def execute(self, context):
        from ..batch import compare_runs
        s = benchmark.settings(context)
        if not s.output_dir or not s.baseline_dir:
            self.report({"ERROR"}, "choose a results folder and a baseline folder first")
            return {"CANCELLED"}
        try:
            result = benchmark.compare_with_baseline(s.output_dir, s.baseline_dir)
        except (run_folder.NotARun, compare_runs.OutputRefused, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        changed = sum(1 for j in result["jobs"] if j["changed"])
        self.report({"INFO"}, f"{changed} of {len(result['jobs'])} jobs changed; {len(result['new_jobs'])} new, "
                              f"{len(result['missing_jobs'])} missing")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_load_chart(bpy.types.Operator):
    """Load the error-against-time chart of a sweep into an Image Editor"""
    bl_idname = "spectral_bench.load_chart"
    bl_label = "Load Sweep Chart"
    bl_options = {"REGISTER", "UNDO"}
    scene: StringProperty()

    def execute(self, context):
        out_dir = bpy.path.abspath(benchmark.settings(context).output_dir)
        path = run_folder.chart_path(out_dir, self.scene)
        if path is None:
            self.report({"ERROR"}, f"no sweep chart for {self.scene} in {out_dir}")
            return {"CANCELLED"}
        image = bpy.data.images.load(str(path), check_existing=True)
        image.name = f"{self.scene} sweep chart"
        _show_in_image_editor(context, image)
        self.report({"INFO"}, f"loaded {image.name}")
        return {"FINISHED"}


def _menu(self, context):
    self.layout.operator(SPECTRAL_BENCH_OT_export_json.bl_idname, text="Spectral Bench JSON (.json)")
    self.layout.operator(SPECTRAL_BENCH_OT_export_mitsuba.bl_idname, text="Mitsuba 3 Scene Folder")
    self.layout.operator(SPECTRAL_BENCH_OT_export_art.bl_idname, text="ART Scene Folder (.arm)")


CLASSES = (SPECTRAL_BENCH_OT_export_json, SPECTRAL_BENCH_OT_export_mitsuba, SPECTRAL_BENCH_OT_export_art,
           SPECTRAL_BENCH_OT_load_spectrum,
           SPECTRAL_BENCH_OT_spectrum_sample, SPECTRAL_BENCH_OT_run_benchmark, SPECTRAL_BENCH_OT_cancel_benchmark,
           SPECTRAL_BENCH_OT_toggle_backend, SPECTRAL_BENCH_OT_add_renderers_file,
           SPECTRAL_BENCH_OT_remove_renderers_file, SPECTRAL_BENCH_OT_open_canonical_scenes,
           SPECTRAL_BENCH_OT_append_canonical_scene, SPECTRAL_BENCH_OT_open_report,
           SPECTRAL_BENCH_OT_load_result, SPECTRAL_BENCH_OT_load_chart, SPECTRAL_BENCH_OT_compare_baseline)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_export.append(_menu)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(_menu)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
