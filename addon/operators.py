"""Operators: File > Export entries for the generic JSON and Mitsuba 3 XML (scriptable as
bpy.ops.spectral_bench.export_json / export_mitsuba). Logic lives in exporters/; these stay thin."""
from pathlib import Path

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ExportHelper

from ..exporters import extract_blender, ir_json, mitsuba_writer, validate


def export_scene(scene, fmt, path):
    """Export one Blender scene; returns the written path. Raises validate.SceneError."""
    data = extract_blender.extract_scene(scene)
    if fmt == "json":
        return ir_json.write(data, path)
    return mitsuba_writer.write(data, Path(path))


class _ExportBase:
    fmt = ""

    def execute(self, context):
        try:
            out = export_scene(context.scene, self.fmt, self.filepath)
        except validate.SceneError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"wrote {out}")
        return {"FINISHED"}


class SPECTRAL_BENCH_OT_export_json(_ExportBase, bpy.types.Operator, ExportHelper):
    """Export the active scene as generic spectral-bench JSON (the scene IR)"""
    bl_idname = "spectral_bench.export_json"
    bl_label = "Export Spectral Bench JSON"
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})
    fmt = "json"


class SPECTRAL_BENCH_OT_export_mitsuba(_ExportBase, bpy.types.Operator):
    """Export the active scene as a Mitsuba 3 folder (scene.xml, meshes, spectra)"""
    bl_idname = "spectral_bench.export_mitsuba"
    bl_label = "Export Mitsuba 3 Scene Folder"
    filepath: StringProperty(subtype="DIR_PATH")
    fmt = "mitsuba"

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


def _menu(self, context):
    self.layout.operator(SPECTRAL_BENCH_OT_export_json.bl_idname, text="Spectral Bench JSON (.json)")
    self.layout.operator(SPECTRAL_BENCH_OT_export_mitsuba.bl_idname, text="Mitsuba 3 Scene Folder")


CLASSES = (SPECTRAL_BENCH_OT_export_json, SPECTRAL_BENCH_OT_export_mitsuba)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_export.append(_menu)


def unregister():
    bpy.types.TOPBAR_MT_file_export.remove(_menu)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
