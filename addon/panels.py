"""Panels: annotations (Material, Light, World, Camera, Object, Scene) with inline validation,
and the benchmark panel (Properties > Scene). Draw code only: the logic is in validation.py,
benchmark.py and batch/report/results.py, which tests call directly (draw() cannot run headless)."""
import bpy

from ..batch.report import results
from . import benchmark, validation


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
        elif a.kind == "DIELECTRIC":
            self.layout.prop(a, "int_ior")
            self.layout.prop(a, "ext_ior")
        if a.kind in ("CONDUCTOR", "DIELECTRIC"):
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
        _draw_spectrum(self.layout, context.object.data.spectral_bench.radiance, "Radiance", "light.radiance")
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
        for key in ("case", "description", "spp", "max_depth", "output", "needs_polarization", "needs_fluorescence"):
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


class SPECTRAL_BENCH_PT_benchmark(_Base, bpy.types.Panel):
    bl_label = "Spectral Benchmark"
    bl_context = "scene"

    def draw(self, context):
        s = benchmark.settings(context)
        layout = self.layout
        col = layout.column(align=True)
        for name, ok, why in benchmark.backend_states():
            row = col.row()
            row.enabled = ok
            row.prop(s, f"use_{name}", text=name if ok else f"{name}: {why}")
        layout.prop(s, "spp")
        layout.prop(s, "scale")
        layout.prop(s, "only_active")
        layout.prop(s, "output_parent")
        row = layout.row()
        row.operator_context = "INVOKE_DEFAULT"
        row.operator("spectral_bench.run_benchmark", icon="PLAY")
        row.operator("spectral_bench.cancel_benchmark", icon="CANCEL")
        if s.status:
            layout.label(text=s.status)
        layout.prop(s, "output_dir")
        status = results.last_status(bpy.path.abspath(s.output_dir)) if s.output_dir else {}
        for scene in sorted(status):
            for backend, run in status[scene].items():
                box = layout.box()
                icon = {"ok": "CHECKMARK", "failed": "ERROR"}.get(run["status"], "INFO")
                box.label(text=f"{scene} / {backend}: {run['status']}", icon=icon)
                if run.get("reason"):
                    box.label(text=run["reason"][:120])
                m = run.get("metrics") or {}
                if m.get("rmse") is not None:
                    box.label(text="RMSE {rmse:.3g}  relMSE {relmse:.3g}  MAPE {mape:.3g}".format(**m)
                              + (f"  FLIP {m['flip']:.3g}" if m.get("flip") is not None else ""))
                for p in run.get("probes", [])[:30]:
                    err = "" if p["error"] is None else f"{p['error']:.3g} {p['unit']}"
                    mark = {True: "CHECKMARK", False: "ERROR"}.get(p["pass"], "QUESTION")
                    box.label(text=f"{p['name']}: {err}", icon=mark)
                if results.chart_path(bpy.path.abspath(s.output_dir), scene):
                    box.operator("spectral_bench.load_chart", text="Error against time").scene = scene
                row = box.row(align=True)
                for kind in results.IMAGE_KINDS:
                    if results.image_path(bpy.path.abspath(s.output_dir), scene, backend, kind):
                        op = row.operator("spectral_bench.load_result", text=kind.replace("_", " "))
                        op.scene, op.backend, op.kind = scene, backend, kind


CLASSES = (SPECTRAL_BENCH_PT_material, SPECTRAL_BENCH_PT_light, SPECTRAL_BENCH_PT_world, SPECTRAL_BENCH_PT_camera,
           SPECTRAL_BENCH_PT_scene, SPECTRAL_BENCH_PT_object, SPECTRAL_BENCH_PT_benchmark)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
