"""Minimal annotation panels (Material, Light, World, Scene). Draw code only; no logic."""
import bpy


def _draw_spectrum(layout, props, label):
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
        box.label(text=f"{len(props.samples)} samples")


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
            _draw_spectrum(self.layout, a.reflectance, "Reflectance")
        elif a.kind == "CONDUCTOR":
            self.layout.prop(a, "conductor_named")
            if a.conductor_named:
                self.layout.prop(a, "conductor")
            else:
                _draw_spectrum(self.layout, a.eta, "eta")
                _draw_spectrum(self.layout, a.k, "k")
        elif a.kind == "DIELECTRIC":
            self.layout.prop(a, "int_ior")
            self.layout.prop(a, "ext_ior")
        if a.kind in ("CONDUCTOR", "DIELECTRIC"):
            self.layout.prop(a, "distribution")
            if a.distribution != "SMOOTH":
                self.layout.prop(a, "alpha")


class SPECTRAL_BENCH_PT_light(_Base, bpy.types.Panel):
    bl_label = "Spectral Bench"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return isinstance(context.object and context.object.data, bpy.types.Light)

    def draw(self, context):
        _draw_spectrum(self.layout, context.object.data.spectral_bench.radiance, "Radiance")


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
            _draw_spectrum(self.layout, a.radiance, "Radiance")


class SPECTRAL_BENCH_PT_scene(_Base, bpy.types.Panel):
    bl_label = "Spectral Bench"
    bl_context = "scene"

    def draw(self, context):
        a = context.scene.spectral_bench
        for key in ("case", "description", "spp", "max_depth", "output", "needs_polarization", "needs_fluorescence"):
            self.layout.prop(a, key)


class SPECTRAL_BENCH_PT_camera(_Base, bpy.types.Panel):
    bl_label = "Spectral Bench"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return isinstance(context.object and context.object.data, bpy.types.Camera)

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


CLASSES = (SPECTRAL_BENCH_PT_material, SPECTRAL_BENCH_PT_light, SPECTRAL_BENCH_PT_world, SPECTRAL_BENCH_PT_camera,
           SPECTRAL_BENCH_PT_scene, SPECTRAL_BENCH_PT_object)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
