"""Reference images: references/<scene>.exr (the mean of every channel the scene outputs, R, G,
B and, for Stokes scenes, S0.R ... S3.B; the standard error of that mean per pixel as
stderr.<channel>) and references/<scene>.json (provenance).

A reference records the fingerprint of the scene it was rendered from: everything that
determines the expected image, i.e. the IR without the sample count and names, with every named
spectrum and named conductor replaced by its table and every mesh file by a hash of its contents
(a changed data file or mesh changes the scene). A changed scene makes the reference stale, and
stale references are never used for a verdict. The renderer and its version are provenance, not
fingerprint: a reference exists to judge other versions (and renderers) against; every job shows
the versions of both. References change only through ``batch/make_references.py`` (an explicit
request), and are written atomically (temporary files renamed into place, the JSON last).
"""
import copy
import hashlib
import json
from pathlib import Path

import numpy as np

from ...exporters import ir_json, mesh_io, spectra
from .. import exr

REFERENCE_DIR = Path(__file__).resolve().parents[2] / "references"


def _resolved(node, base_dir):
    """The IR with named spectra and conductors replaced by their tables and mesh files by hashes
    of their contents (in place)."""
    if isinstance(node, dict):
        if node.get("type") == "named" and "name" in node and node["name"] in spectra.named_spectra():
            wl, values = spectra.tabulate(node)
            node["table"] = [[round(float(w), 6), round(float(v), 9)] for w, v in zip(wl, values)]
        if node.get("type") == "conductor" and "material" in node:
            node["tables"] = [spectra.tabulate(s)[1].round(9).tolist() for s in spectra.named_conductor(node["material"])]
        if node.get("type") == "mesh" and "file" in node:
            verts, faces = mesh_io.load_mesh(node, base_dir)
            node["file"] = hashlib.sha256(np.asarray(verts, dtype=np.float64).tobytes()
                                          + np.asarray(faces, dtype=np.int64).tobytes()).hexdigest()
        for v in node.values():
            _resolved(v, base_dir)
    elif isinstance(node, list):
        for v in node:
            _resolved(v, base_dir)
    return node


def fingerprint(scene):
    """sha256 of what determines the expected image: the IR without the sample count, the
    description and the names of the scene's objects (objects sorted by content), with the data
    behind named spectra, conductors and mesh files resolved."""
    data = _resolved(copy.deepcopy({k: v for k, v in scene.items() if not k.startswith("_")}), scene.get("_base_dir"))
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
    exr_path, meta_path = directory / f"{scene['name']}.exr", directory / f"{scene['name']}.json"
    exr_tmp, meta_tmp = exr_path.with_suffix(".exr.tmp"), meta_path.with_suffix(".json.tmp")
    exr.write_image(exr_tmp, names, mean, extra)
    meta = dict(provenance, scene=scene["name"], fingerprint=fingerprint(scene))
    meta_tmp.write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    exr_tmp.replace(exr_path)
    meta_tmp.replace(meta_path)
    return exr_path
