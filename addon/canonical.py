"""The canonical scenes: scenes.blend ships inside the extension (beside this package's root).

They are read through a temporary BlendData (``bpy.data.temp_data``), so listing or running them
never touches the open file; opening works on a copy (saving never writes into the installed
extension) and appending brings one scene into the open file. Nothing a .blend carries runs, whatever
Blender's Auto Run preference: the copy is opened with scripts off, and what a library load brings
loses its drivers that would run Python before anything evaluates them (batch/blend_input.py).
"""
import shutil
import tempfile
from pathlib import Path

import bpy

from ..batch import blend_input, scene_sources
from ..exporters import extract_blender, validate

BLEND = scene_sources.DEFAULT_BLEND
ALL = "__ALL__"
_NAMES = []   # scene names, read once
_ITEMS = []   # dynamic enum items must stay referenced from Python
_COPIES = []  # the temporary folder of this session's working copies


def available():
    return BLEND.is_file()


def _source():
    """scenes.blend, or a copy of it when it is the open file (Blender cannot load a library from
    the file it has open; the file on disk is what counts, not its unsaved edits)."""
    if bpy.data.filepath and Path(bpy.data.filepath).resolve() == BLEND.resolve():
        return working_copy()
    return BLEND


def scene_names():
    """The canonical scenes' names, sorted (empty if scenes.blend is missing)."""
    if not _NAMES and available():
        with bpy.data.temp_data() as temp:
            with temp.libraries.load(str(_source())) as (src, _dst):
                _NAMES.extend(sorted(src.scenes))
    return list(_NAMES)


def scene_items(_self, _context):
    _ITEMS[:] = [(ALL, "All Canonical Scenes", "Every scene of the shipped scenes.blend")] + [
        (n, n, f"The canonical scene {n}") for n in scene_names()]
    return _ITEMS


def extract(names=None):
    """[(name, IR dict or SceneError)] of the canonical scenes ``names`` (None: all), extracted
    from a temporary BlendData."""
    wanted = [n for n in scene_names() if names is None or n in names]
    missing = sorted(set(names or []) - set(wanted))
    out = [(n, validate.SceneError(n, [("scene", "name", f"no canonical scene of this name in {BLEND}")]))
           for n in missing]
    with bpy.data.temp_data() as temp:
        with temp.libraries.load(str(_source())) as (_src, dst):
            dst.scenes = wanted
        blend_input.drop_python_drivers(blend_input.ids_of(temp).values())  # the IR has no drivers
        for scene in dst.scenes:
            try:
                data = extract_blender.extract_scene(scene)
                out.append((data["name"], data))
            except validate.SceneError as exc:
                out.append((exc.scene, exc))
    return out


def working_copy():
    """A fresh copy of scenes.blend in this session's temporary folder: what "open" opens."""
    if not _COPIES or not Path(_COPIES[0]).is_dir():
        _COPIES[:] = [tempfile.mkdtemp(prefix="spectral_bench_scenes_")]
    return Path(shutil.copy2(BLEND, Path(_COPIES[0]) / BLEND.name))


def append(name):
    """Append canonical scene ``name`` (and what it uses) to the open file; returns the new scene
    (renamed by Blender if the file already has a scene of that name) and what was removed from the
    appended data because it would run Python (see ``blend_input.drop_python_drivers``)."""
    if name not in scene_names():
        raise KeyError(f"no canonical scene {name!r} (known: {', '.join(scene_names())})")
    before = blend_input.ids_of(bpy.data)
    with bpy.data.libraries.load(str(_source()), link=False) as (_src, dst):
        dst.scenes = [name]
    removed = blend_input.drop_python_drivers(
        block for address, block in blend_input.ids_of(bpy.data).items() if address not in before)
    return dst.scenes[0], removed
