"""Triangle meshes to and from files: binary PLY (written for Mitsuba and ART), PLY/OBJ read."""
from pathlib import Path

import numpy as np


def write_ply(path, vertices, faces, normals=None):
    """Binary PLY; ``normals`` (per vertex, optional) are written as nx, ny, nz."""
    v = np.asarray(vertices, dtype="<f4").reshape(-1, 3)
    f = np.asarray(faces, dtype="<i4").reshape(-1, 3)
    extra = "" if normals is None else "property float nx\nproperty float ny\nproperty float nz\n"
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n{extra}"
              f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    if normals is not None:
        v = np.ascontiguousarray(np.concatenate([v, np.asarray(normals, dtype="<f4").reshape(-1, 3)], axis=1))
    face_rec = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    face_rec["n"], face_rec["i"] = 3, f
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(v.tobytes())
        fh.write(face_rec.tobytes())
    return path


def read_obj(path):
    """Vertices and triangulated faces (fan) of a Wavefront OBJ; ignores normals and UVs."""
    verts, faces = [], []
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) for p in parts[1:]]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            faces += [[idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1)]
    return verts, faces


def read_ply(path):
    """Vertices and faces of a PLY written by write_ply (binary little endian, x y z [nx ny nz], triangles)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    nv = int(next(l for l in header if l.startswith("element vertex")).split()[-1])
    nf = int(next(l for l in header if l.startswith("element face")).split()[-1])
    face_at = next(i for i, l in enumerate(header) if l.startswith("element face"))
    props = sum(1 for l in header[:face_at] if l.startswith("property float"))  # x y z (nx ny nz)
    v = np.frombuffer(data, dtype="<f4", count=nv * props, offset=end).reshape(nv, props)[:, :3]
    rec = np.frombuffer(data, dtype=[("n", "u1"), ("i", "<i4", 3)], count=nf, offset=end + nv * 4 * props)
    return v.tolist(), rec["i"].tolist()


def load_mesh(shape, base_dir=None):
    """(vertices, faces) of an IR mesh shape, from inline data or its file."""
    if "vertices" in shape:
        return shape["vertices"], shape["faces"]
    path = Path(shape["file"])
    if not path.is_absolute() and base_dir:
        path = Path(base_dir) / path
    if path.suffix.lower() == ".obj":
        return read_obj(path)
    return read_ply(path)
