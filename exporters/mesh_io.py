"""Triangle meshes to and from files: PLY through plyfile (any layout: ASCII or binary, either
byte order, polygons triangulated as fans), written as binary little-endian PLY for Mitsuba and
ART; a minimal Wavefront OBJ reader (positions and faces)."""
from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement


def write_ply(path, vertices, faces, normals=None, uvs=None, uv_names=("u", "v")):
    """Binary PLY; ``normals`` (per vertex, optional) are written as nx, ny, nz, texture
    coordinates ``uvs`` (per vertex, optional) as u, v (the IR's: v up; a writer whose renderer
    reads v down flips them first)."""
    v = np.asarray(vertices, dtype="<f4").reshape(-1, 3)
    f = np.asarray(faces, dtype="<i4").reshape(-1, 3)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if uvs is not None:
        fields += [(uv_names[0], "<f4"), (uv_names[1], "<f4")]
    vert = np.empty(len(v), dtype=fields)
    vert["x"], vert["y"], vert["z"] = v.T
    if normals is not None:
        n = np.asarray(normals, dtype="<f4").reshape(-1, 3)
        vert["nx"], vert["ny"], vert["nz"] = n.T
    if uvs is not None:
        uv = np.asarray(uvs, dtype="<f4").reshape(-1, 2)
        vert[uv_names[0]], vert[uv_names[1]] = uv.T
    face = np.empty(len(f), dtype=[("vertex_indices", "<i4", (3,))])
    face["vertex_indices"] = f
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    PlyData([PlyElement.describe(vert, "vertex"),
             PlyElement.describe(face, "face", len_types={"vertex_indices": "u1"})], text=False,
            byte_order="<").write(str(path))
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
    """Vertices and triangles of any PLY file (faces under vertex_indices or vertex_index)."""
    ply = PlyData.read(str(path))
    vert = ply["vertex"].data
    v = np.stack([vert["x"], vert["y"], vert["z"]], axis=1).astype(np.float64)
    face = ply["face"].data
    key = "vertex_indices" if "vertex_indices" in face.dtype.names else "vertex_index"
    faces = [[int(poly[0]), int(poly[k]), int(poly[k + 1])] for poly in face[key] for k in range(1, len(poly) - 1)]
    return v.tolist(), faces


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
