"""Issue 42 item 2: an image texture on a Blender material's base colour, made with bpy as a user
makes it (an Image Texture node into the Principled BSDF's Base Color, the plane's own UV map),
exports as the IR's reflectance_texture with the mesh's UVs, and its pattern appears in the
renders, the right way up: a 2 x 2 texture of four colours (Closest interpolation) on a plane seen
from above, each quadrant's mean colour nearest to its own texel's beyond noise. The hostile cases
(a texture outside the .blend's folder, a missing file, a header claiming a huge image, a FIFO)
fail their scene alone, naming object and field. One bpy child for the module.

The writers' side without bpy (fast): the Mitsuba and pbrt exports hold the texture as linear
OpenEXR inside their folder, ART and the RGB backends say unsupported naming the field, the scene
file export copies the texture beside it, and validation refuses a texture without UVs."""
import copy
import json
import os

import numpy as np
import pytest

from conftest import RANDOM_TEST_ALPHA, render_with_noise, run_bpy
from installed import needs_pbrt
from spectral_bench.exporters import art_writer, ir_json, pbrt_writer, rgb_scene, textures, validate

# the texels, linear sRGB, as Blender's image rows bottom to top: bottom-left red, bottom-right
# green, top-left blue, top-right grey
TEXELS = {"bottom-left": (0.7, 0.05, 0.05), "bottom-right": (0.05, 0.7, 0.05),
          "top-left": (0.05, 0.05, 0.7), "top-right": (0.5, 0.5, 0.5)}
SIZE, SPP = 32, 32


def write_image(path, px):
    """An RGB image file of ``px`` (H x W x 3, rows top to bottom; uint8 or float32), by OpenImageIO."""
    import OpenImageIO as oiio
    px = np.ascontiguousarray(px)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(path))
    kind = "uint8" if px.dtype == np.uint8 else "float"
    assert out.open(str(path), oiio.ImageSpec(px.shape[1], px.shape[0], 3, kind)), oiio.geterror()
    out.write_image(px)
    out.close()
    return path


def write_png(path, rows_top_down):
    """An 8-bit sRGB PNG of linear colours (rows listed top to bottom)."""
    lin = np.asarray(rows_top_down, dtype=np.float64)
    enc = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    return write_image(path, np.round(np.clip(enc, 0, 1) * 255).astype(np.uint8))


def quad_png(path):
    t = TEXELS
    return write_png(path, [[t["top-left"], t["top-right"]], [t["bottom-left"], t["bottom-right"]]])


def expected_texels(folder):
    """The texels as the exporter reads them back (8-bit rounding included)."""
    lin = textures.read_linear({"file": "quad.png", "colour_space": "srgb"}, folder)
    return {"top-left": lin[0, 0], "top-right": lin[0, 1], "bottom-left": lin[1, 0], "bottom-right": lin[1, 1]}


def huge_png(side):
    """A PNG whose header claims side x side pixels and whose image data is empty (only the header
    may be read): 100 bytes."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("textured")
    quad_png(folder / "quad.png")
    outside = tmp_path_factory.mktemp("elsewhere")
    quad_png(outside / "outside.png")
    (folder / "huge.png").write_bytes(huge_png(20000))
    os.mkfifo(folder / "fifo.png")
    out = run_bpy(f"""
        import math, bmesh
        from spectral_bench.exporters import extract_blender, validate
        bpy.ops.wm.save_as_mainfile(filepath={str(folder / 'scene.blend')!r})

        def scene(name, image_path=None, level=0.0):
            sc = bpy.data.scenes.new(name)
            m = bpy.data.materials.new(name + "_mat")
            nt = m.node_tree
            p = nt.nodes["Principled BSDF"]
            p.inputs["Specular IOR Level"].default_value = level
            tex = nt.nodes.new("ShaderNodeTexImage")
            tex.interpolation = "Closest"
            img = bpy.data.images.load({str(folder / 'quad.png')!r}, check_existing=False)
            img.name = name + "_img"
            if image_path is not None:
                img.filepath = image_path  # not loaded: Blender reads pixels when they are used
            tex.image = img
            nt.links.new(tex.outputs["Color"], p.inputs["Base Color"])
            me = bpy.data.meshes.new(name + "_plane")
            bm = bmesh.new()
            bm.loops.layers.uv.new("UVMap")
            bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=1.0, calc_uvs=True)
            bm.to_mesh(me)
            bm.free()
            me.materials.append(m)
            ob = bpy.data.objects.new(name + "_plane", me)
            sc.collection.objects.link(ob)
            w = bpy.data.worlds.new(name + "_sky")
            w.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            sc.world = w
            cd = bpy.data.cameras.new(name + "_cam")
            cd.sensor_fit, cd.angle = "HORIZONTAL", math.radians(20.0)
            cam = bpy.data.objects.new(name + "_cam", cd)
            cam.location = (0.0, 0.0, 4.0)  # looking down -z, image up = +y
            sc.collection.objects.link(cam)
            sc.camera = cam
            sc.render.resolution_x = sc.render.resolution_y = {SIZE}
            sc.render.resolution_percentage = 100
            return sc

        out = {{}}
        cases = {{"diffuse": None, "outside": {str(outside / 'outside.png')!r}, "missing": "//absent.png",
                  "huge": "//huge.png", "fifo": "//fifo.png"}}
        built = {{name: scene(name, path) for name, path in cases.items()}}
        built["coated"] = scene("coated", None, 0.5)
        for name, sc in built.items():
            try:
                out[name] = extract_blender.extract_scene(sc)
            except validate.SceneError as exc:
                out[name] = {{"problems": [list(p) for p in exc.problems]}}
        print(json.dumps(out))
    """, timeout=300)
    return folder, out


@pytest.mark.slow
def test_a_blender_image_texture_exports_with_its_uvs(exported):
    folder, out = exported
    sc = out["diffuse"]
    (plane,) = sc["objects"]
    b = plane["bsdf"]
    assert b["type"] == "diffuse"
    assert b["reflectance_texture"] == {"file": "quad.png", "colour_space": "srgb", "filter": "nearest"}
    shape = plane["shape"]
    assert shape["type"] == "mesh" and len(shape["uvs"]) == len(shape["vertices"])
    # each corner's UV is its position mapped from [-1, 1] to [0, 1] (Blender's grid UVs)
    for (x, y, _z), (u, v) in zip(shape["vertices"], shape["uvs"]):
        assert (u, v) == pytest.approx(((x + 1) / 2, (y + 1) / 2), abs=1e-6)
    msgs = {w["field"]: w["message"] for w in sc["warnings"]}
    msg = msgs["material[diffuse_mat].node_tree.nodes[Principled BSDF].inputs[Base Color]"]
    assert "image texture" in msg and "uplifted by the renderer" in msg
    assert not any("not converted" in m for m in msgs.values()), msgs
    # the coated base takes the texture too (Principled's default specular layer)
    assert out["coated"]["objects"][0]["bsdf"]["type"] == "coated_diffuse"
    assert out["coated"]["objects"][0]["bsdf"]["reflectance_texture"]["file"] == "quad.png"


@pytest.mark.slow
@pytest.mark.parametrize("case, words", [("outside", "outside the .blend's folder"), ("missing", "no such file"),
                                         ("huge", "20000 x 20000"), ("fifo", "FIFO")])
def test_a_hostile_texture_fails_its_scene_alone_named(exported, case, words):
    _folder, out = exported
    problems = out[case]["problems"]
    assert len(problems) == 1, problems
    obj, field, message = problems[0]
    assert obj == f"{case}_plane"
    assert field == f"material[{case}_mat].node_tree.nodes[Image Texture].image"
    assert words in message and f"{case}_img" in message
    assert "objects" in out["diffuse"]  # the good scene beside it exported


def _quadrants(img):
    h, w = img.shape[:2]
    # the plane covers the middle of the view; each quadrant's inner half, away from the seams
    q = {"top-left": img[h // 8:h * 3 // 8, w // 8:w * 3 // 8], "top-right": img[h // 8:h * 3 // 8, w * 5 // 8:w * 7 // 8],
         "bottom-left": img[h * 5 // 8:h * 7 // 8, w // 8:w * 3 // 8],
         "bottom-right": img[h * 5 // 8:h * 7 // 8, w * 5 // 8:w * 7 // 8]}
    return {k: v.reshape(-1, v.shape[-1]) for k, v in q.items()}


def _assert_pattern(names, img, texels, alpha=None):
    """Each quadrant's mean colour is nearest to its own texel, and every other texel lies beyond
    its noise: the largest channel's |z| past the two-sided Sidak threshold of the 4 x 3 such
    comparisons at ``alpha`` (stats.ALPHA for a renderer whose render is the same every run,
    RANDOM_TEST_ALPHA for one whose render is random: the suite's budget, tests/conftest.py)."""
    from scipy import stats as sps
    from spectral_bench.batch.verdict import stats
    alpha = stats.ALPHA if alpha is None else alpha
    z = float(sps.norm.isf((1 - (1 - alpha) ** (1 / 12)) / 2))
    rgb = img[..., [names.index(c) for c in "RGB"]].astype(np.float64)
    for where, px in _quadrants(rgb).items():
        mean, se = px.mean(axis=0), px.std(axis=0, ddof=1) / np.sqrt(len(px)) + 1e-12
        dist = {k: float(np.max(np.abs(mean - np.asarray(t)) / se)) for k, t in texels.items()}
        own, other = dist[where], min(d for k, d in dist.items() if k != where)
        assert own < other and other > z, (where, mean, dist, z)


@pytest.mark.slow
def test_the_checkerboard_appears_in_a_mitsuba_render_the_right_way_up(exported, tmp_path):
    folder, out = exported
    sc = dict(out["diffuse"], _base_dir=str(folder))
    rendered, names, img, _se = render_with_noise(sc, tmp_path, SPP)
    assert (tmp_path / "mitsuba" / "textures" / "diffuse_plane_reflectance.exr").is_file()
    _assert_pattern(names, img, expected_texels(folder))


@pytest.mark.slow
def test_the_pattern_check_sees_a_texture_upside_down(exported, tmp_path):
    """The check's power: the same plane with v flipped (the texture upside down) fails it."""
    folder, out = exported
    sc = copy.deepcopy(dict(out["diffuse"], _base_dir=str(folder)))
    shape = sc["objects"][0]["shape"]
    shape["uvs"] = [[u, 1.0 - v] for u, v in shape["uvs"]]
    rendered, names, img, _se = render_with_noise(sc, tmp_path, SPP)
    with pytest.raises(AssertionError):
        _assert_pattern(names, img, expected_texels(folder))


@pytest.mark.slow
def test_the_checkerboard_appears_in_a_cycles_render_the_right_way_up(exported, tmp_path):
    """-r cycles: the export's texture as an Image Texture node on the mesh's UVs (RGB texels, no
    uplift)."""
    folder, out = exported
    sc = dict(out["diffuse"], _base_dir=str(folder))
    rendered, names, img, _se = render_with_noise(sc, tmp_path, SPP, backend="cycles")
    _assert_pattern(names, img, expected_texels(folder))


@pytest.mark.slow
def test_the_checkerboard_appears_in_a_luxcore_render_the_right_way_up(exported, tmp_path):
    folder, out = exported
    sc = dict(out["diffuse"], _base_dir=str(folder))
    rendered, names, img, _se = render_with_noise(sc, tmp_path, SPP, backend="luxcore")
    _assert_pattern(names, img, expected_texels(folder), RANDOM_TEST_ALPHA)  # random across machines


@pytest.mark.slow
@needs_pbrt
def test_the_checkerboard_appears_in_a_pbrt_render_the_right_way_up(exported, tmp_path):
    folder, out = exported
    sc = dict(out["diffuse"], _base_dir=str(folder))
    rendered, names, img, _se = render_with_noise(sc, tmp_path, SPP, backend="pbrt")
    _assert_pattern(names, img, expected_texels(folder), RANDOM_TEST_ALPHA)  # random across machines


# -- without bpy ---------------------------------------------------------------------------------

def textured_scene(folder):
    quad_png(folder / "quad.png")
    sc = {"format": "spectral-bench-scene", "version": 1, "name": "tex", "case": "custom", "needs": [],
          "render": {"spp": 4, "width": 8, "height": 8, "max_depth": 8, "filter": "box", "integrator": "path"},
          "camera": {"name": "cam", "fov": 30.0, "to_world": np.eye(4).tolist()},
          "environment": {"type": "uniform", "radiance": {"type": "constant", "value": 1.0}},
          "objects": [{"name": "floor", "emitter": None,
                       "shape": {"type": "mesh", "vertices": [[-1, -1, -3], [1, -1, -3], [1, 1, -3], [-1, 1, -3]],
                                 "faces": [[0, 1, 2], [0, 2, 3]], "uvs": [[0, 0], [1, 0], [1, 1], [0, 1]]},
                       "bsdf": {"type": "diffuse", "reflectance": {"type": "constant", "value": 0.3},
                                "reflectance_texture": {"file": "quad.png", "colour_space": "srgb"}}}],
          "_base_dir": str(folder)}
    from spectral_bench.exporters import ir
    sc["format"], sc["version"] = ir.FORMAT, ir.VERSION
    return sc


def test_validation_takes_a_textured_mesh_and_refuses_one_without_uvs(tmp_path):
    sc = textured_scene(tmp_path)
    validate.check(copy.deepcopy(sc))
    bare = copy.deepcopy(sc)
    del bare["objects"][0]["shape"]["uvs"]
    with pytest.raises(validate.SceneError) as err:
        validate.check(bare)
    assert ("floor", "shape.uvs") in {(o, f) for o, f, _m in err.value.problems}
    short = copy.deepcopy(sc)
    short["objects"][0]["shape"]["uvs"] = [[0, 0]]
    with pytest.raises(validate.SceneError) as err:
        validate.check(short)
    assert any(f == "shape.uvs" and "1 texture coordinates for 4 vertices" in m for _o, f, m in err.value.problems)


def mitsuba_file(sc, folder, xpath):
    """The Mitsuba export of ``sc`` in ``folder``/mitsuba: (its element at ``xpath``, the file that
    element names, relative to the export), the file checked to lie inside the export."""
    import xml.etree.ElementTree as ET
    from spectral_bench.exporters import mitsuba_writer
    xml = mitsuba_writer.write(sc, folder / "mitsuba")
    node = ET.parse(xml).getroot().find(xpath)
    rel = node.find("string[@name='filename']").get("value")
    assert (folder / "mitsuba" / rel).resolve().is_relative_to((folder / "mitsuba").resolve()), rel
    assert (folder / "mitsuba" / rel).is_file(), rel
    return node, rel


def test_writers_hold_the_texture_inside_their_folder_or_say_unsupported(tmp_path):
    sc = textured_scene(tmp_path)
    _bitmap, rel = mitsuba_file(sc, tmp_path, ".//texture[@type='bitmap']")
    assert rel == "textures/floor_reflectance.exr"
    linear = textures.read_linear({"file": rel, "colour_space": "linear"}, tmp_path / "mitsuba")
    assert linear == pytest.approx(textures.read_linear(sc["objects"][0]["bsdf"]["reflectance_texture"], tmp_path),
                                   abs=1e-6)
    pbrt_writer.write(sc, tmp_path / "pbrt")
    text = (tmp_path / "pbrt" / pbrt_writer.SCENE_FILE).read_text()
    assert '"imagemap" "string filename" "textures/floor_reflectance.exr"' in text
    assert '"texture reflectance" "floor_reflectance"' in text and (tmp_path / "pbrt" / rel).is_file()
    assert pbrt_writer.unsupported(sc) == []
    assert ("floor", "bsdf.reflectance_texture") in {(o, f) for o, f, *_ in art_writer.unsupported(sc)}
    rgb = rgb_scene.problems(sc, {"ggx"})
    assert ("floor", "bsdf.reflectance_texture") in {(o, f) for o, f, *_ in rgb}
    assert rgb_scene.problems(sc, {"ggx"}, textures=True) == []


def test_the_scene_file_export_copies_the_texture_beside_it(tmp_path):
    sc = textured_scene(tmp_path / "src")
    path = ir_json.write(sc, tmp_path / "out" / "tex.json")
    data = json.loads(path.read_text())
    tex = data["objects"][0]["bsdf"]["reflectance_texture"]
    assert tex["file"] == "textures/floor_reflectance.png"
    assert (tmp_path / "out" / tex["file"]).read_bytes() == (tmp_path / "src" / "quad.png").read_bytes()
    again = ir_json.load(path)  # a stranger's copy loads and validates where it lies
    assert again["objects"][0]["bsdf"]["reflectance_texture"]["file"] == tex["file"]
