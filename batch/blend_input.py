"""Scenes from a .blend file: opens it with bpy (unless it is already open, as under
``blender -b scenes.blend -P batch/run.py``), registers the annotations, extracts the IR.

A .blend can carry code: a text block registered as a module runs when the file is opened, and a
driver's scripted expression runs in Python whenever the scene is evaluated. Blender runs both
when its Auto Run Python Scripts preference is on (or under ``blender -y``). Nothing here trusts a
.blend: files are opened with scripts off whatever the preference (``open_blend``), and data read
from a file without opening it (a library load: appending, ``bpy.data.temp_data``) loses its
drivers that would need Python before anything evaluates them (``drop_python_drivers``); the
registered text blocks of such data are unregistered (they would run when the file is next opened
with Auto Run on). A file that Blender itself opened before the runner started (``blender -b
FILE -P batch/run.py``) was opened under Blender's own setting: add ``--disable-autoexec`` there.

Opening a .blend opens its linked libraries too: ``open_blend`` first reads their paths from the
file's blocks (exporters/blend_safety.py) and refuses a file whose library (or the file itself) is
not a regular file, a FIFO or device that would make the open wait forever.
"""
from pathlib import Path


class BlendRefused(ValueError):
    """A .blend that is not opened (why: the file or which library, and its path)."""


def open_blend(path):
    """Open ``path`` as the main file with its scripts off: no registered text block runs and no
    driver runs Python, whatever Blender's Auto Run preference (until another file is opened).
    Raises BlendRefused, opening nothing, when the file or one of its linked libraries is not a
    regular file."""
    import bpy
    from ..exporters import blend_safety
    problem = blend_safety.file_problem(path) or blend_safety.library_problem(path) or _trial_problem(path)
    if problem:
        raise BlendRefused(problem)
    bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False, use_scripts=False)


def _trial_problem(path):
    """Why the .blend at ``path`` is not opened here (text), or None. Blender evaluates the active
    scene's modifiers while it opens a file, before anything can check their size: a file with a
    modifier that can multiply geometry (exporters/blend_safety.py's GROWING_MODIFIERS) is first
    opened in a child process, killed when its resident memory passes TRIAL_MEMORY or its time
    TRIAL_SECONDS (an address-space limit would not do: Blender gives up on a modifier whose memory
    it cannot allocate and opens the file without it); a file the child cannot open within them is
    refused, naming those modifiers."""
    import subprocess
    import sys
    import time
    import bpy
    from ..exporters import blend_safety as bs
    try:
        growing = bs.growing_modifiers(path)
    except Exception as exc:  # noqa: BLE001 - any fault of a hostile file: it is not opened
        return f"{str(path)!r}: its modifiers cannot be read: {exc}"
    if not growing:
        return None
    opener = "import bpy, sys; bpy.ops.wm.open_mainfile(filepath=sys.argv[-1], load_ui=False, use_scripts=False)"
    cmd = ([bpy.app.binary_path, "-b", "--factory-startup", "--disable-autoexec", "--python-expr", opener, "--"]
           if bpy.app.binary_path else [sys.executable, "-c", opener])
    proc = subprocess.Popen([*cmd, str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    start, why = time.monotonic(), None
    try:
        while proc.poll() is None:
            if _resident(proc.pid) > bs.TRIAL_MEMORY:
                why = f"used more than {bs.TRIAL_MEMORY >> 30} GiB of memory (TRIAL_MEMORY)"
            elif time.monotonic() - start > bs.TRIAL_SECONDS:
                why = f"did not finish within {bs.TRIAL_SECONDS} s (TRIAL_SECONDS)"
            if why:
                break
            time.sleep(0.02)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    if why is None and proc.returncode != 0:
        why = f"failed (exit status {proc.returncode})"
    if why is None:
        return None
    return (f"opening it in a trial process {why}, exporters/blend_safety.py; its modifiers that multiply "
            f"geometry: {', '.join(growing[:5])}{' ...' if len(growing) > 5 else ''}")


def _resident(pid):
    """Resident memory of process ``pid`` in bytes (0 where /proc cannot say)."""
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmRSS:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def _ids(data):
    """Every ID of a BlendData (bpy.data or a temp_data), with the node trees embedded in them
    (a material's, a world's, a light's: their drivers are their own)."""
    import bpy
    for prop in data.bl_rna.properties:
        if prop.type != "COLLECTION":
            continue
        for block in getattr(data, prop.identifier):
            if not isinstance(block, bpy.types.ID):
                break
            yield block
            tree = getattr(block, "node_tree", None)
            if isinstance(tree, bpy.types.ID):
                yield tree


def ids_of(data):
    """{address: ID} of every ID of ``data`` (``bpy.data`` or a temp_data): take it before a library
    load and pass what is new after it to ``drop_python_drivers``."""
    return {block.as_pointer(): block for block in _ids(data)}


def drop_python_drivers(blocks):
    """Remove from ``blocks`` (IDs, e.g. what a library load brought) every driver that would run
    Python (a scripted expression that is not a simple expression, which Blender evaluates without
    Python), and unregister the text blocks among them. Returns what was removed, one line each
    ("Object 'Evil': driver location[0] = evil(frame)"), for the caller to report."""
    import bpy
    removed = []
    for block in blocks:
        label = f"{type(block).__name__} {block.name!r}"
        if isinstance(block, bpy.types.Text) and block.use_module:
            block.use_module = False
            removed.append(f"{label}: no longer registered as a module (it would run on opening the file)")
        anim = getattr(block, "animation_data", None)
        if anim is None:
            continue
        for fcurve in list(anim.drivers):
            driver = fcurve.driver
            if driver.type == "SCRIPTED" and not driver.is_simple_expression:
                removed.append(f"{label}: driver {fcurve.data_path}[{fcurve.array_index}] = {driver.expression!r} "
                               "removed (it would run Python)")
                anim.drivers.remove(fcurve)
    return removed


def load_blend(path, names=None):
    """[(scene name, IR dict or SceneError)]."""
    import bpy
    from ..exporters.validate import SceneError
    path = Path(path).resolve()
    already_open = bool(bpy.data.filepath) and Path(bpy.data.filepath).resolve() == path
    if not already_open:
        try:
            open_blend(path)
        except BlendRefused as exc:
            raise SceneError(path.stem, [("scene", "(file)", f"{path} not opened: {exc}")]) from None
    if not hasattr(bpy.types.Scene, "spectral_bench"):
        # only the annotation properties the extraction reads: no operator, panel or preference
        # of the extension is registered to read a .blend
        from ..exporters import blender_properties as properties
        properties.register()
    from ..exporters import extract_blender
    return extract_blender.extract(names)
