"""Meshes go through plyfile: any PLY layout a user's tool writes is read (ASCII or binary, either
byte order, quads), and what the writers emit reads back exactly."""
import numpy as np

from spectral_bench.exporters import mesh_io

QUAD = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]


def test_binary_round_trip_with_normals(tmp_path):
    path = mesh_io.write_ply(tmp_path / "m.ply", QUAD, [[0, 1, 2], [0, 2, 3]], normals=[[0, 0, 1]] * 4)
    v, f = mesh_io.read_ply(path)
    assert np.allclose(v, QUAD) and f == [[0, 1, 2], [0, 2, 3]]


def test_ascii_quads_and_big_endian_are_read(tmp_path):
    (tmp_path / "a.ply").write_text(
        "ply\nformat ascii 1.0\ncomment from another tool\nelement vertex 4\nproperty double x\nproperty double y\n"
        "property double z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_index\nend_header\n"
        "0 0 0 255\n1 0 0 255\n1 1 0 255\n0 1 0 255\n4 0 1 2 3\n")
    v, f = mesh_io.read_ply(tmp_path / "a.ply")
    assert np.allclose(v, QUAD) and f == [[0, 1, 2], [0, 2, 3]]
    from plyfile import PlyData, PlyElement
    vert = np.array([tuple(p) for p in QUAD], dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f4")])
    face = np.array([([0, 1, 2],)], dtype=[("vertex_indices", ">i4", (3,))])
    PlyData([PlyElement.describe(vert, "vertex"), PlyElement.describe(face, "face")], byte_order=">").write(
        str(tmp_path / "b.ply"))
    v, f = mesh_io.read_ply(tmp_path / "b.ply")
    assert np.allclose(v, QUAD) and f == [[0, 1, 2]]
