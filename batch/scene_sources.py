"""Where the scenes come from: scenes.blend (through bpy) or scene IR JSON files.

One bad input fails alone: whatever goes wrong with one file (unreadable, not UTF-8, not JSON,
nested too deeply, not a scene, a name that cannot be an output folder) becomes that input's
SceneError, naming the file and the field, and the other inputs load.
"""
import os
from pathlib import Path

from ..exporters import blend_safety, ir_json, names, validate

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


def name_problem(name):
    """Why ``name`` cannot be a scene's output folder (OUT/<name>/...), or None: the IR's own rule
    (exporters/names.py), applied again to whatever a loader returned."""
    return names.scene_problem(name)


def _label(name, path, k):
    """A safe label for an input that failed: its scene name or file stem when either is safe as
    a name, else input-K (never a raw name that could be a path)."""
    for candidate in (name, Path(str(path)).stem):
        if name_problem(candidate) is None:
            return candidate
    return f"input-{k}"


def load(paths):
    """[(scene name, IR dict or SceneError)] from .blend and .json paths, in order. A scene name
    met twice is an error for the later one (outputs are written per scene name)."""
    seen, out = {}, []
    for k, ((name, result), origin) in enumerate(_load(paths), 1):
        if not isinstance(result, Exception):
            problem = name_problem(name)
            if problem:
                label = _label(None, origin, k)
                result = validate.SceneError(label, [("scene", "name", f"{problem} (input {origin})")])
                name = label
            elif name in seen:
                result = validate.SceneError(name, [("scene", "name", f"a scene of this name already comes from {seen[name]}; "
                                                     f"rename one (outputs are written per scene name), input {origin}")])
            else:
                seen[name] = origin
        else:
            name = _label(name, origin, k)
        out.append((name, result))
    return out


def _load(paths):
    """[((scene name, IR dict or SceneError), input path)]; never raises for one bad input."""
    results = []
    for p in paths:
        path = Path(p)
        try:
            if path.suffix == ".blend":
                if not path.is_file():  # missing, a folder, a FIFO or device (opening it would wait)
                    problem = blend_safety.file_problem(path)
                    raise validate.SceneError(path.stem, [("scene", "(file)", f"no such file: {path}" if problem is None
                                                           or not os.path.lexists(path) else problem)])
                from .blend_input import load_blend
                results += [(r, str(path)) for r in load_blend(path)]
            else:
                scene = ir_json.load(path)
                results.append(((scene["name"], scene), str(path)))
        except validate.SceneError as exc:
            results.append(((exc.scene, exc), str(path)))
        except Exception as exc:  # noqa: BLE001 - one input that breaks the loader fails alone
            results.append(((None, validate.SceneError(path.stem, [("scene", "(file)", f"cannot load {path}: "
                                                                   f"{type(exc).__name__}: {exc}")])), str(path)))
    return results


def case_of(result):
    return result.get("case") if isinstance(result, dict) else None
