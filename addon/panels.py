"""Panels: annotations (Material, Light, World, Camera, Object, Scene) with inline validation,
and the benchmark panel with its References and Results sub-panels (Properties > Scene). Draw code
only: the logic is in validation.py, benchmark.py, reference_sources.py, batch/report/results.py and batch/run_folder.py.
tests/extension/test_blender_ui.py runs every panel's draw() against a recording layout that checks each
drawn property, operator and icon exists."""
import bpy

from ..batch import records
from ..batch import run_folder
from ..batch.report import results, spectra
from . import benchmark, preferences, reference_sources, validation


def _draw_problems(layout, problems):
    for msg in problems:
        layout.label(text=msg, icon="ERROR")


def _draw_spectrum(layout, props, label, target):
    box = layout.box()
    box.label(text=label)
    box.prop(props, "kind")
    if props.kind == "CONSTANT":
        box.prop(props, "value")
    elif props.kind == "NAMED":
        box.prop(props, "named")
        box.prop(props, "scale")
    elif props.kind == "BLACKBODY":
        box.prop(props, "temperature")
        box.prop(props, "scale")
    else:
        for item in props.samples:
            row = box.row(align=True)
            row.prop(item, "wavelength", text="nm")
            row.prop(item, "value", text="")
        row = box.row(align=True)
        for action, icon in (("ADD", "ADD"), ("REMOVE", "REMOVE")):
            op = row.operator("spectral_bench.spectrum_sample", text="", icon=icon)
            op.target, op.action = target, action
        row.operator("spectral_bench.load_spectrum", text="From File", icon="FILEBROWSER").target = target


class _Base:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"


class SPECTRAL_BENCH_PT_material(_Base, bpy.types.Panel):
    bl_label = "Spectral Bench"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return context.material is not None

    def draw(self, context):
        a = context.material.spectral_bench
        self.layout.prop(a, "kind")
        if a.kind == "DIFFUSE":
            _draw_spectrum(self.layout, a.reflectance, "Reflectance", "material.reflectance")
            self.layout.prop(a, "fluorescence")
            if a.fluorescence == "BANDS":
                box = self.layout.box()
                for key in ("absorption_peak", "absorption_width", "emission_peak", "emission_width", "strength"):
                    box.prop(a, key)
            elif a.fluorescence == "MATRIX":
                self.layout.prop(a, "fluorescence_matrix_file")
        elif a.kind == "CONDUCTOR":
            self.layout.prop(a, "conductor_named")
            if a.conductor_named:
                self.layout.prop(a, "conductor")
            else:
                _draw_spectrum(self.layout, a.eta, "eta", "material.eta")
                _draw_spectrum(self.layout, a.k, "k", "material.k")
            self.layout.prop(a, "thin_film")
            if a.thin_film:
                for key in ("film_ior", "film_thickness", "film_ext_ior"):
                    self.layout.prop(a, key)
        elif a.kind == "DIELECTRIC":
            self.layout.prop(a, "ior_model")
            if a.ior_model == "CONSTANT":
                self.layout.prop(a, "int_ior")
            elif a.ior_model == "NAMED":
                self.layout.prop(a, "glass")
            elif a.ior_model == "SELLMEIER":
                self.layout.prop(a, "sellmeier_b")
                self.layout.prop(a, "sellmeier_c")
            else:
                for key in ("cauchy_a", "cauchy_b", "cauchy_c"):
                    self.layout.prop(a, key)
            self.layout.prop(a, "ext_ior")
        elif a.kind == "COATED":
            _draw_spectrum(self.layout, a.reflectance, "Base Reflectance", "material.reflectance")
            self.layout.prop(a, "int_ior", text="Coat IOR")
            self.layout.prop(a, "ext_ior")
        if a.kind in ("CONDUCTOR", "DIELECTRIC", "COATED"):
            self.layout.prop(a, "distribution")
            if a.distribution != "SMOOTH":
                self.layout.prop(a, "alpha")
        _draw_problems(self.layout, validation.material_problems(context.material))


class _ObjectDataBase(_Base):
    """A panel in Object Data properties for one kind of data (``data_type``)."""
    bl_label = "Spectral Bench"
    bl_context = "data"
    data_type = None

    @classmethod
    def poll(cls, context):
        return isinstance(context.object and context.object.data, cls.data_type)


class SPECTRAL_BENCH_PT_light(_ObjectDataBase, bpy.types.Panel):
    data_type = bpy.types.Light

    def draw(self, context):
        a = context.object.data.spectral_bench
        self.layout.prop(a, "collimated")
        _draw_spectrum(self.layout, a.radiance, "Irradiance" if a.collimated else "Radiance", "light.radiance")
        _draw_problems(self.layout, validation.light_problems(context.object.data))


class SPECTRAL_BENCH_PT_world(_Base, bpy.types.Panel):
    bl_label = "Spectral Bench"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return context.scene.world is not None

    def draw(self, context):
        a = context.scene.world.spectral_bench
        self.layout.prop(a, "enabled")
        if a.enabled:
            _draw_spectrum(self.layout, a.radiance, "Radiance", "world.radiance")
        _draw_problems(self.layout, validation.world_problems(context.scene.world))


class SPECTRAL_BENCH_PT_scene(_Base, bpy.types.Panel):
    bl_label = "Spectral Bench"
    bl_context = "scene"

    def draw(self, context):
        a = context.scene.spectral_bench
        for key in ("case", "description", "spp", "max_depth", "output", "integrator", "needs_polarization",
                    "needs_fluorescence"):
            self.layout.prop(a, key)


class SPECTRAL_BENCH_PT_camera(_ObjectDataBase, bpy.types.Panel):
    data_type = bpy.types.Camera

    def draw(self, context):
        a = context.object.data.spectral_bench
        self.layout.prop(a, "polarizer")
        if a.polarizer:
            self.layout.prop(a, "polarizer_angle")


class SPECTRAL_BENCH_PT_object(_Base, bpy.types.Panel):
    bl_label = "Spectral Bench"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        return context.object is not None and context.object.type == "MESH"

    def draw(self, context):
        self.layout.prop(context.object.spectral_bench, "shape")


def _draw_declared(layout, context, s):
    """The renderers the preferences' renderers files declare, chosen like the built-in backends:
    each with what it reads, writes and models and, unavailable, the reason; a file that cannot be
    used is one error line naming it and the problem (benchmark.declared_renderers)."""
    found = benchmark.declared_renderers(preferences.renderers_files(context))
    col = layout.column(align=True)
    col.label(text="Declared Renderers" if found["renderers"] else "Declared Renderers: none")
    for f in found["files"]:
        if f["problem"]:
            col.label(text=benchmark.one_line(f["problem"]), icon="ERROR")
        else:
            col.label(text=benchmark.one_line(f"{f['path']}: {', '.join(f['names'])}"), icon="FILE")
    for name, ok, why, on, decl in benchmark.declared_states(s, found["renderers"]):
        row = col.row(align=True)
        row.enabled = ok
        text = name if ok else (why if why.startswith(f"{name}: ") else f"{name}: {why}")
        op = row.operator("spectral_bench.toggle_backend", text=text,
                          icon="CHECKBOX_HLT" if (on and ok) else "CHECKBOX_DEHLT", emboss=False)
        op.backend = name
        col.label(text=benchmark.describe_declaration(decl), icon="BLANK1")
    col.operator("spectral_bench.add_renderers_file", text="Add Renderers File", icon="ADD")


class SPECTRAL_BENCH_PT_benchmark(_Base, bpy.types.Panel):
    """Scenes, backends (every one batch/backends knows and every declared renderer, unavailable
    ones with the reason), samples, scale, passes; run and cancel with progress."""
    bl_label = "Spectral Benchmark"
    bl_context = "scene"

    def draw(self, context):
        s = benchmark.settings(context)
        layout = self.layout
        box = layout.box()
        box.label(text="Canonical Scenes", icon="SCENE_DATA")
        box.prop(s, "canonical_scene", text="")
        row = box.row(align=True)
        row.operator("spectral_bench.open_canonical_scenes", text="Open All", icon="FILE_FOLDER")
        row.operator("spectral_bench.append_canonical_scene", text="Append", icon="APPEND_BLEND")
        layout.prop(s, "scene_source")
        col = layout.column(align=True)
        col.label(text="Backends")
        for name, ok, why, on in benchmark.backend_states(s):
            row = col.row(align=True)
            row.enabled = ok
            op = row.operator("spectral_bench.toggle_backend", text=name if ok else f"{name}: {why}",
                              icon="CHECKBOX_HLT" if (on and ok) else "CHECKBOX_DEHLT", emboss=False)
            op.backend = name
        _draw_declared(layout, context, s)
        col = layout.column(align=True)
        col.prop(s, "spp")
        col.prop(s, "scale")
        col.prop(s, "passes")
        layout.prop(s, "flip")
        layout.prop(s, "output_parent")
        row = layout.row()
        row.operator_context = "INVOKE_DEFAULT"
        row.operator("spectral_bench.run_benchmark", icon="PLAY")
        row.operator("spectral_bench.cancel_benchmark", icon="CANCEL")
        row = layout.row()  # the open scene, spectral against RGB: no reference needed
        row.operator_context = "INVOKE_DEFAULT"
        row.operator("spectral_bench.run_benchmark", text="What does spectral change?", icon="COLOR").study = "spectral-vs-rgb"
        job = benchmark.active_job()
        fraction = benchmark.progress_fraction()
        if job is not None and job.running() and fraction is not None:
            layout.progress(factor=fraction, type="BAR", text=s.status)
        elif s.status:
            layout.label(text=s.status)


class SPECTRAL_BENCH_PT_benchmark_references(_Base, bpy.types.Panel):
    """Where references come from (the extension, the preferences' folder, or both) and, per
    scene, the reference a run would use first, with its provenance."""
    bl_label = "References"
    bl_context = "scene"
    bl_parent_id = "SPECTRAL_BENCH_PT_benchmark"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        search = preferences.reference_folders(context)
        if not search:
            layout.label(text="No reference folder chosen (Preferences > Add-ons)", icon="ERROR")
        for origin, folder, count, exists in reference_sources.summary(search):
            text = f"{origin}: {count} in {folder}" if exists else f"{origin}: no such folder {folder}"
            layout.label(text=text, icon="FILE_FOLDER" if exists else "ERROR")
        found = reference_sources.catalog(search)
        col = layout.column(align=True)
        for scene in sorted(found):
            first = found[scene][0]
            row = col.split(factor=0.4)
            row.label(text=scene)
            row.label(text=f"{first['origin']}: {reference_sources.describe(first)}"
                      + (f" (+{len(found[scene]) - 1} more)" if len(found[scene]) > 1 else ""))


class SPECTRAL_BENCH_PT_benchmark_results(_Base, bpy.types.Panel):
    """The results of an outputs folder (also one made on the command line): per scene and backend
    the status (failures first), the reference judged against and every reference problem (file and
    problem), metrics, probes and images."""
    bl_label = "Results"
    bl_context = "scene"
    bl_parent_id = "SPECTRAL_BENCH_PT_benchmark"

    def draw(self, context):
        s = benchmark.settings(context)
        layout = self.layout
        row = layout.row(align=True)
        row.prop(s, "output_dir", text="")
        row.operator("spectral_bench.open_report", text="Open Report", icon="URL")
        out_dir = bpy.path.abspath(s.output_dir) if s.output_dir else ""
        row = layout.row(align=True)  # a previous run to compare with: changed jobs first
        row.prop(s, "baseline_dir", text="Baseline")
        row.operator("spectral_bench.compare_baseline", text="Compare", icon="FILE_REFRESH")
        found = benchmark.baseline_records(out_dir, s.baseline_dir)
        search = preferences.reference_folders(context)
        for scene, backend, run in benchmark.result_rows(out_dir, s.baseline_dir):
            box = layout.box()
            box.label(text=f"{scene} / {backend}: {run['status']}", icon=benchmark.status_icon(run["status"]))
            base = found.get((scene, backend))
            if base is not None:
                box.label(text=benchmark.baseline_line(base)[:200],
                          icon={"changed": "ERROR", "same": "CHECKMARK", "unstable": "INFO"}.get(
                              benchmark.baseline_word(base), "QUESTION"))
                if base[0].get("reason"):
                    box.label(text=str(base[0]["reason"])[:200])
            if run.get("reason"):
                box.label(text=run["reason"][:160], icon="ERROR" if results.judged_without_reference(run) else "NONE")
            if results.judged_by(run):  # what judged it; a renderer's own reference alone is said so
                box.label(text=f"judged by: {results.judged_by(run)}"[:200],
                          icon="INFO" if results.checked_against_itself(run) else "NONE")
            why = (run.get("diagnosis") or {}).get("text") if isinstance(run.get("diagnosis"), dict) else None
            if why:  # the fitted error models (issue 34): "likely: ..." or "no model explains it"
                box.label(text=f"why: {why}"[:200], icon="QUESTION")
            for text in spectra.worst_lines(run):  # a spectral render's failing regions (issue 33), by worst band
                box.label(text=f"worst band: {text}"[:200], icon="ERROR")
            for text in results.reference_problems(run):  # every reference passed over, with its file
                box.label(text=f"reference problem: {text}"[:200], icon="ERROR")
            ref = run.get("reference") or {}
            if ref.get("path"):
                box.label(text=f"reference ({reference_sources.origin_of(ref['path'], search)}): "
                               f"{reference_sources.describe(ref)}", icon="IMAGE_REFERENCE")
            m = run.get("metrics") or {}
            if m.get("rmse") is not None:
                box.label(text="RMSE {rmse:.3g}  relMSE {relmse:.3g}  MAPE {mape:.3g}".format(**m)
                          + (f"  FLIP {records.flip_text(run)}" if records.flip_text(run) else ""))
            t = run.get("test")
            if isinstance(t, dict):
                box.label(text=f"noise test: {records.noise_test_text(t)}"[:200],
                          icon={True: "NONE", False: "ERROR"}.get(t.get("pass"), "QUESTION"))
            for p in run.get("probes", [])[:30]:
                err = "" if p.get("error") is None else f"{p['error']:.3g} {p.get('unit') or ''}"
                mark = {True: "CHECKMARK", False: "ERROR"}.get(p.get("pass"), "QUESTION")
                box.label(text=f"{p['name']}: {err}", icon=mark)
            if run_folder.chart_path(out_dir, scene):
                box.operator("spectral_bench.load_chart", text="Error against time").scene = scene
            flow = box.grid_flow(columns=4, align=True)
            for kind in benchmark.image_kinds(out_dir, scene, backend, run, base):
                op = flow.operator("spectral_bench.load_result", text=kind.replace("_", " "))
                op.scene, op.backend, op.kind = scene, backend, kind


CLASSES = (SPECTRAL_BENCH_PT_material, SPECTRAL_BENCH_PT_light, SPECTRAL_BENCH_PT_world, SPECTRAL_BENCH_PT_camera,
           SPECTRAL_BENCH_PT_scene, SPECTRAL_BENCH_PT_object, SPECTRAL_BENCH_PT_benchmark,
           SPECTRAL_BENCH_PT_benchmark_references, SPECTRAL_BENCH_PT_benchmark_results)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
