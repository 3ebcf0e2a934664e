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
    """[(scene name, IR dict or SceneError)] from .blend and .json paths, in order. A scene name
    met twice is an error for the later one (outputs are written per scene name)."""
    results = _load(paths)
    seen, out = {}, []
    for (name, result), origin in results:
        if name in seen and not isinstance(result, Exception):
            result = validate.SceneError(name, [("scene", "name", f"a scene of this name already comes from {seen[name]}; "
                                                 f"rename one (outputs are written per scene name), input {origin}")])
        seen.setdefault(name, origin)
        out.append((name, result))
    return out


def _load(paths):
    """[((scene name, IR dict or SceneError), input path)]."""
    results = []
    for p in paths:
        path = Path(p)
        if path.suffix == ".blend":
            if not path.is_file():
                results.append(((path.stem, validate.SceneError(path.stem, [("scene", "(file)", f"no such file: {path}")])),
                                str(path)))
                continue
            from .blend_input import load_blend
            results += [(r, str(path)) for r in load_blend(path)]
        else:
            try:
                scene = ir_json.load(path)
                results.append(((scene["name"], scene), str(path)))
            except validate.SceneError as exc:
                results.append(((exc.scene if exc.scene != "?" else path.stem, exc), str(path)))
    return results


def case_of(result):
    return result.get("case") if isinstance(result, dict) else None
