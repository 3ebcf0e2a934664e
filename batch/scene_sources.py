"""Where the scenes come from: scenes.blend (through bpy) or scene IR JSON files."""
from pathlib import Path

from ..exporters import ir_json, validate

DEFAULT_BLEND = Path(__file__).resolve().parents[1] / "scenes.blend"


def default_input():
    """The .blend already open in Blender (blender -b file.blend -P ...), else scenes.blend."""
    try:
        import bpy
        if bpy.data.filepath:
            return [bpy.data.filepath]
    except ImportError:
        pass
    return [str(DEFAULT_BLEND)]


def load(paths):
    """[(scene name, IR dict or SceneError)] from .blend and .json paths, in order."""
    results = []
    for p in paths:
        path = Path(p)
        if path.suffix == ".blend":
            if not path.is_file():
                results.append((path.stem, validate.SceneError(path.stem, [("scene", "(file)", f"no such file: {path}")])))
                continue
            from .blend_input import load_blend
            results += load_blend(path)
        else:
            try:
                scene = ir_json.load(path)
                results.append((scene["name"], scene))
            except validate.SceneError as exc:
                results.append((exc.scene if exc.scene != "?" else path.stem, exc))
    return results


def case_of(result):
    return result.get("case") if isinstance(result, dict) else None
