"""Reference images: references/<scene>.exr (the mean of every channel the scene outputs, R, G,
B and, for Stokes scenes, S0.R ... S3.B; the standard error of that mean per pixel as
stderr.<channel>) and references/<scene>.json (provenance).

A reference records the fingerprint of the scene it was rendered from (the IR without the
sample count); a changed scene makes it stale, and stale references are never used for a
verdict. References change only through ``batch/make_references.py`` (an explicit request).
"""
import copy
import hashlib
import json
from pathlib import Path

import numpy as np

from ...exporters import ir_json
from .. import exr

REFERENCE_DIR = Path(__file__).resolve().parents[2] / "references"


def fingerprint(scene):
    """sha256 of what determines the expected image: the IR without the sample count, the
    description and the names of the scene's objects (objects sorted by content)."""
    data = copy.deepcopy({k: v for k, v in scene.items() if not k.startswith("_")})
    data["render"].pop("spp", None)
    for key in ("description", "name", "case"):
        data.pop(key, None)
    data["camera"].pop("name", None)
    for obj in data["objects"]:
        obj.pop("name", None)
    data["objects"].sort(key=lambda o: json.dumps(o, sort_keys=True))
    return hashlib.sha256(ir_json.dumps(data).encode()).hexdigest()


class Reference:
    def __init__(self, names, mean, stderr, provenance, path):
        self.names, self.mean, self.stderr, self.provenance, self.path = names, mean, stderr, provenance, path

    @property
    def spp(self):
        return self.provenance["spp"]


def directories(directory=None):
    """The reference folders to search, in order: None -> references/; one path; or a list of
    paths (the Blender extension passes the user's folder and its own)."""
    if not directory:
        return [REFERENCE_DIR]
    if isinstance(directory, (str, Path)):
        return [Path(directory)]
    return [Path(d) for d in directory] or [REFERENCE_DIR]


def load(scene_name, directory=None, scene=None):
    """Reference or None if there is none. With several folders, the first holding a reference
    usable for ``scene`` wins; if none is usable (or ``scene`` is None) the first found, so that
    a stale reference is still reported as stale."""
    first = None
    for folder in directories(directory):
        exr_path, meta_path = folder / f"{scene_name}.exr", folder / f"{scene_name}.json"
        if not exr_path.is_file() or not meta_path.is_file():
            continue
        meta = json.loads(meta_path.read_text())
        if scene is not None and meta.get("fingerprint") != fingerprint(scene):
            first = first or (exr_path, meta)
            continue
        return _read(exr_path, meta)
    return _read(*first) if first else None


def _read(exr_path, meta):
    names, mean, stderr = exr.read_image_and_stderr(exr_path)
    if stderr is None:
        raise ValueError(f"{exr_path} has no stderr.<channel> noise channels: not a reference")
    return Reference(names, mean, stderr, meta, exr_path)


def check_usable(ref, scene):
    """None if ``ref`` can judge renders of ``scene``, else the reason it cannot."""
    if ref is None:
        return "no reference for this scene"
    if ref.provenance.get("fingerprint") != fingerprint(scene):
        return (f"reference {ref.path.name} is stale: the scene changed since it was rendered "
                f"({ref.provenance.get('date')}); re-render it with batch/make_references.py")
    return None


HALF_MAX = 65504.0


def _noise_channel(stderr):
    """The standard error as half floats (the mean stays float32): a third smaller references
    with no verdict changed (benchmarks/reference_storage.py, benchmarks/REFERENCES.md); float32
    where a value would not fit in half."""
    finite = np.isfinite(stderr)
    if finite.all() and float(np.max(np.abs(stderr), initial=0.0)) < HALF_MAX:
        return stderr.astype(np.float16)
    return stderr.astype(np.float32)


def save(scene, names, mean, stderr, provenance, directory=None):
    directory = Path(directory or REFERENCE_DIR)
    directory.mkdir(parents=True, exist_ok=True)
    extra = {f"stderr.{n}": _noise_channel(stderr[..., i]) for i, n in enumerate(names)}
    exr.write_image(directory / f"{scene['name']}.exr", names, mean, extra)
    meta = dict(provenance, scene=scene["name"], fingerprint=fingerprint(scene))
    (directory / f"{scene['name']}.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return directory / f"{scene['name']}.exr"
