"""The generic JSON form of the IR: the IR serialised, versioned, schema-checked.

It is an input as well as an output: every command that takes scenes.blend takes these files.
Files are written self-contained (inline tables beside every name, exporters/inline_data.py);
``load`` reads both forms and returns the internal IR (named where the tables are the project's).
``dumps`` serialises a scene as it is (the references' fingerprint hashes the named form).
"""
import json
import re
from pathlib import Path

from . import inline_data, ir, textures, validate


_NUMBER_LIST = re.compile(r"\[\s*(-?[\d.eE+-]+(?:,\s*-?[\d.eE+-]+)*)\s*\]")


def dumps(scene):
    """Stable, diff-friendly JSON: sorted keys, one line per list of numbers."""
    data = {k: v for k, v in scene.items() if not k.startswith("_")}
    text = json.dumps(data, indent=1, sort_keys=True, allow_nan=True)
    text = _NUMBER_LIST.sub(lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text)
    return text + "\n"


def write(scene, path, self_contained=True):
    """Write ``scene`` as a scene file: self-contained by default (every named spectrum, conductor
    and glass carries its data, exporters/inline_data.py; docs/scene-format.md), or in the named
    form (the internal IR as it is) with ``self_contained=False``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dumps(inline_data.embed(with_textures_beside(scene, path.parent)) if self_contained
                          else with_textures_beside(scene, path.parent)))
    return path


def with_textures_beside(scene, folder):
    """``scene`` with each texture's file copied into ``folder``/textures/ as it is (its colour
    space stays recorded) and its ``file`` pointing there: a scene file's folder holds what it
    names (exporters/textures.py)."""
    env = scene.get("environment")
    if not any(textures.textured(o) for o in scene["objects"]) and not textures.env_map(env):
        return scene
    out = dict(scene, objects=[dict(o) for o in scene["objects"]])
    if textures.env_map(env):
        rel = textures.copy_into(env, "environment", scene.get("_base_dir"), folder, stem="environment")
        out["environment"] = dict(env, file=rel)
    for obj in out["objects"]:
        tex = textures.textured(obj)
        if tex is not None:
            rel = textures.copy_into(tex, obj["name"], scene.get("_base_dir"), folder)
            obj["bsdf"] = dict(obj["bsdf"], reflectance_texture=dict(tex, file=rel))
    return out


MAX_DEPTH = 32  # nesting of a scene file (the deepest canonical scene nests 6 levels)


class InputError(validate.SceneError):
    """A scene file's problems, named by the file (``source``) as well as scene, object and field."""

    def __init__(self, scene, problems, source):
        super().__init__(scene, problems)
        self.source = str(source)
        self.args = (f"{self.source}: {self.args[0]}",)


def depth(data, limit=MAX_DEPTH):
    """Nesting depth of parsed JSON (lists and objects), counted without recursion; stops at limit + 1."""
    deepest, stack = 0, [(data, 1)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, (dict, list)):
            deepest = max(deepest, d)
            if deepest > limit:
                return deepest
            stack.extend((v, d + 1) for v in (node.values() if isinstance(node, dict) else node)
                         if isinstance(v, (dict, list)))
    return deepest


def load(path):
    """Read and validate one IR JSON file. Relative mesh files resolve against its folder.
    Every problem, from an unreadable file to a bad field, is an InputError (a SceneError) that
    names the file; its ``scene`` is the file's stem until the scene's own name is known."""
    path = Path(path)
    label = path.stem

    def fail(field, message, obj="scene", scene=None):
        raise InputError(scene or label, [(obj, field, message)], path)

    try:
        raw = path.read_bytes()
    except OSError as exc:
        fail("(file)", f"cannot read {path}: {exc.strerror or exc}")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        fail("(file)", f"not UTF-8 text: byte {raw[exc.start]:#04x} at offset {exc.start}")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        fail("(file)", f"not valid JSON: {exc}")
    except RecursionError:
        fail("(file)", f"nested too deeply (more than {MAX_DEPTH} levels of lists and objects)")
    if depth(data) > MAX_DEPTH:
        fail("(file)", f"nested too deeply (more than {MAX_DEPTH} levels of lists and objects)")
    if not isinstance(data, dict):
        fail("(root)", f"a scene must be a JSON object, got {type(data).__name__}")
    data["_base_dir"] = str(path.parent)
    try:
        validate.check(data)
        data["needs"] = ir.derived_needs(data)
    except validate.SceneError as exc:
        raise InputError(exc.scene if isinstance(exc.scene, str) else label, exc.problems, path) from exc
    except Exception as exc:  # noqa: BLE001 - whatever breaks on a hostile file fails that file
        fail("(file)", f"cannot be checked: {type(exc).__name__}: {exc}")
    return data
