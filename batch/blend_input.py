"""Scenes from a .blend file: opens it with bpy (unless it is already open, as under
``blender -b scenes.blend -P batch/run.py``), registers the annotations, extracts the IR."""
from pathlib import Path


def load_blend(path, names=None):
    """[(scene name, IR dict or SceneError)]."""
    import bpy
    path = Path(path).resolve()
    already_open = bool(bpy.data.filepath) and Path(bpy.data.filepath).resolve() == path
    if not already_open:
        bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
    from .. import register
    if not hasattr(bpy.types.Scene, "spectral_bench"):
        register()
    from ..exporters import extract_blender
    return extract_blender.extract(names)
