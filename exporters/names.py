"""Names in the scene IR are data, never paths or code.

Scene, case, camera and object names name files and folders (``OUT/<scene>/``,
``references/<scene>.exr``, ``meshes/<object>.ply``, ``spectra/<object>_radiance.spd``) and
appear in comments of every export format. One pattern admits them: ASCII letters, digits,
``_``, ``.`` and ``-``, starting with a letter, digit or ``_`` (so never ``.``, ``..`` or a hidden
file), at most 64 characters, no path separator, no space, no control character. A few names
are reserved because they would collide with what the tool itself writes (the files of an
outputs folder, Windows device names).

Free text (a description, a Blender label) never reaches a file name; where a writer puts text
into a comment it goes through :func:`comment_text`, which keeps a conservative set of printable
characters that cannot end or escape a comment in XML, C/Objective-C (ART's .arm), LuxCore SDL
or Python.

:func:`safe_id` maps any text (a Blender datablock name such as ``"Key Light"`` or ``"Würfel"``)
to a valid, unique name; the extension keeps the original as the object's ``label``.
"""
import re
import unicodedata

MAX_LENGTH = 64
# ECMA-262 and Python read it alike; jsonschema applies it with re.search, where "$" also matches
# before a final newline, so check() below uses fullmatch (the schema carries maxLength too).
PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$"
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")

# What an outputs folder holds beside the per-scene folders (batch/jobs/runner.py, batch/report,
# batch/studies): a scene of such a name would write into them.
OUTPUT_ENTRIES = ("metrics.json", "metrics.json.tmp", "summary.md", "report.html", "sweeps", "stability",
                  "report", "lock", ".lock")
# Windows reserves these as file names, with or without an extension, in any case.
_DEVICES = {"con", "prn", "aux", "nul", *(f"com{i}" for i in range(10)), *(f"lpt{i}" for i in range(10))}
# An object of these names would be mistaken for the scene's own parts in messages and exports
# (the Mitsuba export's environment emitter has the id "environment").
RESERVED_OBJECTS = ("scene", "camera", "render", "environment")


def problem(name, kind="name"):
    """None if ``name`` is a valid scene, case, camera or object name, else what is wrong."""
    if not isinstance(name, str):
        return f"a {kind} must be a string, got {type(name).__name__}"
    if not name:
        return f"a {kind} must not be empty"
    if len(name) > MAX_LENGTH:
        return f"a {kind} is at most {MAX_LENGTH} characters, got {len(name)}"
    if _NAME.fullmatch(name) is None:
        bad = sorted({c for c in name if not (c.isascii() and (c.isalnum() or c in "_.-"))})
        what = (f"the character {bad[0]!r} is not allowed" if len(bad) == 1
                else f"the characters {', '.join(map(repr, bad))} are not allowed" if bad
                else "it must not start with '.' or '-'")
        return (f"{what}: a {kind} names files, so it is letters, digits, '_', '.' and '-', "
                f"starting with a letter, digit or '_', at most {MAX_LENGTH} characters")
    if name.lower().split(".")[0] in _DEVICES:
        return f"{name!r} is a reserved device name on Windows"
    return None


def scene_problem(name):
    """problem() for a scene name, which also names a folder of the outputs and a reference."""
    why = problem(name, "scene name")
    if why is None and name.lower() in OUTPUT_ENTRIES:
        why = f"{name!r} is reserved: an outputs folder already holds an entry of that name"
    return why


def object_problem(name):
    why = problem(name, "object name")
    if why is None and name.lower() in RESERVED_OBJECTS:
        why = f"{name!r} is reserved for the scene's own {name.lower()}"
    return why


def file_stem(name):
    """``name`` for use in a file name, after checking it once more: a writer called on an IR
    that skipped validation still never writes outside its folder."""
    why = problem(name)
    if why is not None:
        raise ValueError(f"refusing to use {name!r} in a file name: {why}")
    return name


_SAFE_COMMENT = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 _.,:;()[]+=%/'")


def comment_text(text):
    """``text`` made safe inside a comment of any export format: one line of conservative
    printable ASCII (anything else becomes '?'), no '--' (XML), no '*/' or backslash (C), no
    newline (every format's comment ends there)."""
    out = "".join(c if c in _SAFE_COMMENT else "?" for c in str(text))
    while "--" in out:
        out = out.replace("--", "-?")
    return out.replace("*/", "*?")


def safe_id(text, taken=()):
    """A valid name for ``text`` (a Blender name, a label), not in ``taken`` (compared without
    case: names become file names, and some file systems ignore case)."""
    ascii_text = unicodedata.normalize("NFKD", str(text)).encode("ascii", "ignore").decode()
    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", ascii_text).strip("_.-")[:MAX_LENGTH] or "object"
    if problem(base) is not None or base.lower() in RESERVED_OBJECTS or base.lower() in OUTPUT_ENTRIES:
        base = ("_" + base)[:MAX_LENGTH]
    lowered = {t.lower() for t in taken}
    name, k = base, 2
    while name.lower() in lowered:
        suffix = f"_{k}"
        name, k = base[:MAX_LENGTH - len(suffix)] + suffix, k + 1
    return name
