"""Where references come from, for the panel and the run: the folders to search in order, what
each holds and where a result's reference came from (plain Python: no bpy).

The order matters: the batch runner takes every folder (``--references DIR`` per folder) and, for
each scene, uses the first one holding a usable reference (batch/verdict/references.py ``search``:
a readable record and EXR with noise channels, a resolution the render can be judged at, the
scene's fingerprint); a broken, wrong-sized or stale one is passed over and reported, with its file,
in the run's results (the Results sub-panel draws them). The catalog here lists what each folder
holds (records that are no reference's are left out).
"""
from pathlib import Path

from ..batch.verdict import references

SHIPPED = references.REFERENCE_DIR  # references/ inside the extension, beside scenes.blend


def folders(source, user_dir):
    """[(origin, Path)] for a preference ``source`` (BOTH, FOLDER, EXTENSION) and the user's folder
    (None if unset)."""
    out = []
    if source in ("BOTH", "FOLDER") and user_dir:
        out.append(("folder", Path(user_dir)))
    if source in ("BOTH", "EXTENSION"):
        out.append(("extension", SHIPPED))
    return out


def _records(folder):
    folder = Path(folder)
    if not folder.is_dir():
        return []
    out = []
    for meta in sorted(folder.glob("*.json")):
        if not meta.with_suffix(".exr").is_file():
            continue
        data, _bad = references.read_record(meta)
        if data is None:
            continue  # not a reference's record (or an unreadable one: a run reports it with its file)
        out.append(dict(scene=data.get("scene", meta.stem), backend=data.get("backend"), mode=data.get("mode"),
                        spp=data.get("spp"), passes=data.get("passes"), date=data.get("date"),
                        resolution=data.get("resolution"), path=str(meta.with_suffix(".exr"))))
    return out


def catalog(search):
    """{scene: [record with origin and folder, in search order]} of every reference found."""
    out = {}
    for origin, folder in search:
        for rec in _records(folder):
            out.setdefault(rec["scene"], []).append(dict(rec, origin=origin, folder=str(folder)))
    return out


def summary(search):
    """[(origin, folder, number of references, exists)] for the panel and the preferences."""
    return [(origin, str(folder), len(_records(folder)), Path(folder).is_dir()) for origin, folder in search]


def origin_of(path, search):
    """The origin ("folder", "extension") of a reference file, or "elsewhere"."""
    if not path:
        return None
    p = Path(path).resolve()
    for origin, folder in search:
        try:
            p.relative_to(Path(folder).resolve())
            return origin
        except ValueError:
            continue
    return "elsewhere"


def describe(record):
    """One line of provenance: renderer, mode, samples, passes, date."""
    parts = [record.get("backend") or "?", record.get("mode") or ""]
    if record.get("spp"):
        parts.append(f"{record['spp']} spp" + (f" x {record['passes']} passes" if record.get("passes") else ""))
    if record.get("date"):
        parts.append(str(record["date"])[:10])
    return " ".join(p for p in parts if p)
