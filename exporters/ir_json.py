"""The generic JSON form of the IR: the IR serialised, versioned, schema-checked.

It is an input as well as an output: every command that takes scenes.blend takes these files.
"""
import json
import re
from pathlib import Path

from . import ir, validate


_NUMBER_LIST = re.compile(r"\[\s*(-?[\d.eE+-]+(?:,\s*-?[\d.eE+-]+)*)\s*\]")


def dumps(scene):
    """Stable, diff-friendly JSON: sorted keys, one line per list of numbers."""
    data = {k: v for k, v in scene.items() if not k.startswith("_")}
    text = json.dumps(data, indent=1, sort_keys=True, allow_nan=True)
    text = _NUMBER_LIST.sub(lambda m: "[" + ", ".join(x.strip() for x in m.group(1).split(",")) + "]", text)
    return text + "\n"


def write(scene, path):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dumps(scene))
    return path


def load(path):
    """Read and validate one IR JSON file. Relative mesh files resolve against its folder."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise validate.SceneError(path.stem, [("scene", "(file)", f"cannot read {path}: {exc}")]) from exc
    if isinstance(data, dict):
        data["_base_dir"] = str(path.parent)
    validate.check(data)
    data["needs"] = ir.derived_needs(data)
    return data
