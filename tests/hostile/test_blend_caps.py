"""A small .blend cannot hang the runner or take the machine's memory (issue 40, item 4).

Each .blend is built here with real bpy (a child process), then read by the real entry point,
``batch/run.py -i FILE.blend --export-only``, in a child whose address space is capped
(``RLIMIT_AS``) and which is killed after a time-out: before these checks existed, a FIFO as a
linked library or an environment image waited forever, and a generated 4096 x 4096 environment
image, a cube with a level-9 subdivision or a large array were read into Python lists (gigabytes,
minutes). Now each is refused before anything is read, naming scene, object, field, the cap and
the value, and the file's other scenes export.
"""
import os
import resource
import subprocess
import sys
import textwrap

import pytest

from conftest import ROOT, metrics
from spectral_bench.exporters import blend_safety

MEMORY_CAP = 3 << 30  # address space of the runner's child: bpy alone reserves ~1.4 GB
TIMEOUT = 120


def bpy_child(code, timeout=300):
    """Run ``code`` (bpy imported, a factory-empty file, SCENE's functions defined) in a child Python."""
    prelude = "import bpy, json, os, sys\nbpy.ops.wm.read_factory_settings(use_empty=True)\n"
    proc = subprocess.run([sys.executable, "-c", prelude + SCENE + textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]


# a scene of a camera and a cube (Blender's own data, no annotation), for bpy_child
SCENE = """
import bmesh
def scene(name):
    sc = bpy.data.scenes.new(name)
    sc.render.resolution_x, sc.render.resolution_y = 32, 24
    cam = bpy.data.objects.new(name + " camera", bpy.data.cameras.new(name + " camera"))
    cam.location = (0, -6, 0)
    cam.rotation_euler = (1.5708, 0, 0)
    sc.collection.objects.link(cam)
    sc.camera = cam
    me = bpy.data.meshes.new(name + " mesh")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1)
    bm.to_mesh(me)
    bm.free()
    cube = bpy.data.objects.new(name + " cube", me)
    sc.collection.objects.link(cube)
    world = bpy.data.worlds.new(name + " world")
    world.use_nodes = True
    sc.world = world
    return sc, cube, world
def environment(world, image):
    tree = world.node_tree
    tex = tree.nodes.new("ShaderNodeTexEnvironment")
    tex.name = "Environment"
    tex.image = image
    tree.links.new(tex.outputs["Color"], tree.nodes["Background"].inputs["Color"])
"""


def run_capped(*args, timeout=TIMEOUT, memory=MEMORY_CAP):
    """batch/run.py in a child with its address space capped at ``memory``, killed after ``timeout``."""
    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    return subprocess.run([sys.executable, str(ROOT / "batch" / "run.py"), *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT, preexec_fn=cap)


def export(blend, out):
    proc = run_capped("-i", blend, "--export-only", "--format", "json", "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    return proc, {r["scene"]: r for r in metrics(out)["runs"]}


@pytest.mark.slow
def test_meshes_above_the_caps_fail_their_scene_before_they_are_read(tmp_path):
    """A cube with a level-9 subdivision (3 million triangles, refused from its predicted size
    before it is evaluated) and a cube in an array of 100000 (1.2 million triangles, evaluated when
    Blender opens the file, refused from its evaluated size before it is read) fail their scenes
    naming object, field, cap and value; the plain cube's scene of the same file exports. (Blender
    evaluates the modifiers of a file's active scene: each is the active scene of its file.)"""
    subdivided, arrayed = tmp_path / "subdivided.blend", tmp_path / "arrayed.blend"
    bpy_child(f"""
        sc, cube, _ = scene("subdivided")
        mod = cube.modifiers.new("Subdivision", "SUBSURF")
        mod.levels = mod.render_levels = 9
        scene("plain")
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        bpy.context.window.scene = sc  # the file's active scene: Blender evaluates it on opening the file
        bpy.ops.wm.save_as_mainfile(filepath={str(subdivided)!r})
        bpy.ops.wm.read_factory_settings(use_empty=True)
        sc, cube, _ = scene("arrayed")
        cube.modifiers.new("Array", "ARRAY").count = 100000
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        bpy.context.window.scene = sc
        bpy.ops.wm.save_as_mainfile(filepath={str(arrayed)!r})
    """)
    out = tmp_path / "out"
    proc = run_capped("-i", subdivided, arrayed, "--export-only", "--format", "json", "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert runs["plain"]["status"] == "ok", runs["plain"]
    sub = runs["subdivided"]["reason"]
    assert runs["subdivided"]["status"] == "failed"
    for part in ("subdivided", "subdivided cube", "modifiers[Subdivision].levels", "3145728 triangles",
                 f"cap of {blend_safety.MAX_MESH_TRIANGLES}", "MAX_MESH_TRIANGLES"):
        assert part in sub, sub
    arr = runs["arrayed"]["reason"]
    assert runs["arrayed"]["status"] == "failed"
    for part in ("arrayed cube", "modifiers", "1200000 triangles", f"cap of {blend_safety.MAX_MESH_TRIANGLES}"):
        assert part in arr, arr


@pytest.mark.slow
def test_a_scene_whose_meshes_together_are_above_the_cap_fails_before_the_last_is_read(tmp_path):
    """Three cubes of a level-8 subdivision (786432 triangles each, under the cap of one mesh):
    the third would take the scene above MAX_SCENE_TRIANGLES; it is refused before it is read,
    naming it, the scene's count and the cap."""
    blend = tmp_path / "many.blend"
    bpy_child(f"""
        sc, first, _ = scene("many")
        for name in ("cube a", "cube b", "cube c"):
            cube = bpy.data.objects.new(name, first.data)
            sc.collection.objects.link(cube)
            mod = cube.modifiers.new("Subdivision", "SUBSURF")
            mod.levels = mod.render_levels = 8
        bpy.data.objects.remove(first)
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        bpy.context.window.scene = sc
        bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})
    """)
    proc, runs = export(blend, tmp_path / "out")
    assert proc.returncode == 1, proc.stderr[-2000:]
    reason = runs["many"]["reason"]
    assert runs["many"]["status"] == "failed"
    assert "cube a" not in reason and "cube b" not in reason, reason
    for part in ("cube c", "modifiers[Subdivision].levels", "786432 triangles", f"{2 * 786432 + 786432}",
                 f"scene's cap of {blend_safety.MAX_SCENE_TRIANGLES}", "MAX_SCENE_TRIANGLES"):
        assert part in reason, reason


@pytest.mark.slow
def test_a_blend_whose_modifiers_blow_up_when_blender_opens_it_fails_alone(tmp_path):
    """Blender evaluates the active scene's modifiers while it opens the file, before any check can
    run: an 84 kB .blend whose cube is in an array of 8 million (64 million vertices, ~4 GB inside
    Blender) is first opened in a trial process, killed when it passes TRIAL_MEMORY, and refused
    naming the modifier; a file with an array of 2000 (a trial too: above 1000) opens and exports.
    The runner's address space is capped at 6 GB here, above the trial's resident cap (under a
    tighter cap Blender would give up on the array itself and open the file without it)."""
    big, small = tmp_path / "big.blend", tmp_path / "small.blend"
    bpy_child(f"""
        for path, count in (({str(big)!r}, 8000000), ({str(small)!r}, 2000)):
            bpy.ops.wm.read_factory_settings(use_empty=True)
            sc, cube, _ = scene("array")
            cube.modifiers.new("Array", "ARRAY").count = count
            bpy.data.scenes.remove(bpy.data.scenes["Scene"])
            bpy.context.window.scene = sc
            bpy.ops.wm.save_as_mainfile(filepath=path)
    """)
    assert blend_safety.growing_modifiers(big) == ["modifiers[Array] (count 8000000)"]
    out = tmp_path / "out"
    proc = run_capped("-i", big, small, "--export-only", "--format", "json", "-o", out, memory=6 << 30)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert runs["array"]["status"] == "ok", runs["array"]
    reason = runs["big"]["reason"]
    assert runs["big"]["status"] == "failed"
    for part in (str(big), "trial process", f"more than {blend_safety.TRIAL_MEMORY >> 30} GiB", "TRIAL_MEMORY",
                 "modifiers[Array] (count 8000000)"):
        assert part in reason, reason


def test_the_predicted_size_of_a_subdivision(tmp_path):
    """4^levels quads per base quad (level 1: one quad per face corner), 2 triangles a quad; only
    the modifiers evaluation applies (viewport or render levels, shown or not)."""
    class Mod:
        def __init__(self, type, levels, render_levels=None, shown=True):
            self.type, self.name, self.levels = type, type.title(), levels
            self.render_levels = levels if render_levels is None else render_levels
            self.show_viewport = self.show_render = shown
    cube = (8, 6, 24)
    assert blend_safety.subdivided(cube, [Mod("SUBSURF", 9)], False)[1] == 6 * 4 ** 9 * 2
    assert blend_safety.subdivided(cube, [Mod("SUBSURF", 1, 9)], True)[1] == 6 * 4 ** 9 * 2
    assert blend_safety.subdivided(cube, [Mod("SUBSURF", 2), Mod("MULTIRES", 3)], False)[1] == 6 * 4 ** 5 * 2
    assert blend_safety.subdivided(cube, [Mod("SUBSURF", 9, shown=False)], False)[1:] == (12, [])


@pytest.mark.slow
def test_an_environment_image_above_the_cap_or_not_a_regular_file_fails_its_scene(tmp_path):
    """A generated 4096 x 4096 environment image (an 85 kB .blend that took 1.6 GB) is refused from
    its settings, before a pixel is made; an environment image whose file is a FIFO (which waited
    forever) or a device is refused from os.stat, never opened, and so is a fluorescent material's
    re-radiation matrix file that is a FIFO; a small image file exports."""
    blend = tmp_path / "images.blend"
    small, fifo, matrix = tmp_path / "small.png", tmp_path / "fifo.png", tmp_path / "matrix.json"
    bpy_child(f"""
        small = bpy.data.images.new("small", 8, 4)
        small.filepath_raw = {str(small)!r}
        small.file_format = "PNG"
        small.save()
        _, _, world = scene("small map")
        environment(world, bpy.data.images.load({str(small)!r}))
        _, _, world = scene("generated map")
        environment(world, bpy.data.images.new("huge", 4096, 4096, float_buffer=True))
        _, _, world = scene("fifo map")
        fifo = bpy.data.images.load({str(small)!r}, check_existing=False)
        fifo.name = "fifo"
        fifo.filepath = {str(fifo)!r}
        environment(world, fifo)
        _, _, world = scene("device map")
        dev = bpy.data.images.load({str(small)!r}, check_existing=False)
        dev.name = "device"
        dev.filepath = "/dev/zero"
        environment(world, dev)
        sys.path.insert(0, {str(ROOT)!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        from spectral_bench.exporters import blender_properties
        blender_properties.register()
        _, cube, _ = scene("fifo matrix")
        mat = bpy.data.materials.new("fluorescent")
        mat.spectral_bench.kind, mat.spectral_bench.fluorescence = "DIFFUSE", "MATRIX"
        mat.spectral_bench.fluorescence_matrix_file = {str(matrix)!r}
        cube.data.materials.append(mat)
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})
    """)
    os.mkfifo(fifo)
    os.mkfifo(matrix)
    assert blend.stat().st_size < 200_000
    proc, runs = export(blend, tmp_path / "out")
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert runs["small_map"]["status"] == "ok", runs["small_map"]
    field = "node_tree.nodes[Environment].image"
    for scene, parts in (("generated_map", ("world[generated map world]", field, "4096 x 4096 = 16777216 pixels",
                                            f"cap of {blend_safety.MAX_IMAGE_PIXELS}", "MAX_IMAGE_PIXELS")),
                         ("fifo_map", ("world[fifo map world]", field, str(fifo), "a FIFO (named pipe)")),
                         ("device_map", ("world[device map world]", field, "/dev/zero", "a character device")),
                         ("fifo_matrix", ("fifo matrix cube", "material[fluorescent].spectral_bench.fluorescence_matrix_"
                                          "file", str(matrix), "a FIFO (named pipe)"))):
        assert runs[scene]["status"] == "failed", runs[scene]
        for part in parts:
            assert part in runs[scene]["reason"], runs[scene]["reason"]


@pytest.mark.slow
def test_a_blend_whose_linked_library_is_a_fifo_fails_alone_naming_the_library(tmp_path):
    """Blender opens a .blend's linked libraries when it opens the file: a FIFO there made
    open_mainfile wait forever. The library paths are read from the file's blocks first: that
    .blend fails naming the library, and another .blend of the same run exports."""
    lib, main, good = tmp_path / "lib.blend", tmp_path / "main.blend", tmp_path / "good.blend"
    bpy_child(f"""
        scene("library")
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        bpy.ops.wm.save_as_mainfile(filepath={str(lib)!r})
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene("good")
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        bpy.ops.wm.save_as_mainfile(filepath={str(good)!r})
        bpy.ops.wm.read_factory_settings(use_empty=True)
        sc, _, _ = scene("linking")
        with bpy.data.libraries.load({str(lib)!r}, link=True, relative=True) as (src, dst):
            dst.objects = ["library cube"]
        sc.collection.objects.link(dst.objects[0])
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        bpy.ops.wm.save_as_mainfile(filepath={str(main)!r})
    """)
    assert blend_safety.library_paths(main) == ["//lib.blend"]
    proc, runs = export(main, tmp_path / "linked")  # a regular library: opened, its object exported
    assert proc.returncode == 0 and runs["linking"]["status"] == "ok", (proc.stderr[-2000:], runs)
    lib.unlink()
    os.mkfifo(lib)
    fifo_blend = tmp_path / "fifo.blend"
    os.mkfifo(fifo_blend)
    out = tmp_path / "out"
    proc = run_capped("-i", main, good, fifo_blend, "--export-only", "--format", "json", "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert runs["good"]["status"] == "ok", runs["good"]
    reason = runs["main"]["reason"]
    assert runs["main"]["status"] == "failed"
    for part in (str(main), "linked library '//lib.blend'", str(lib), "a FIFO (named pipe)", "not opened"):
        assert part in reason, reason
    assert runs["fifo"]["status"] == "failed" and f"{str(fifo_blend)!r} is a FIFO" in runs["fifo"]["reason"], runs


def test_library_paths_of_a_blend_without_libraries_and_of_no_blend(tmp_path):
    assert blend_safety.library_paths(ROOT / "scenes.blend") == []
    other = tmp_path / "x.blend"
    other.write_bytes(b"not a blend")
    assert blend_safety.library_paths(other) is None


def test_image_sizes_from_headers_without_pixels(tmp_path):
    """PNG, JPEG, Radiance HDR and OpenEXR files written by OpenImageIO: the size read from their
    first bytes (the fallback where OpenImageIO's Python module is missing) is OpenImageIO's."""
    import OpenImageIO as oiio
    for ext, fmt in (("png", "uint8"), ("jpg", "uint8"), ("hdr", "float"), ("exr", "half")):
        path = tmp_path / f"image.{ext}"
        assert oiio.ImageBuf(oiio.ImageSpec(70, 33, 3, fmt)).write(str(path))
        assert blend_safety.header_size(path.read_bytes()[:1 << 16]) == (70, 33) == blend_safety.image_header_size(path)
    assert blend_safety.header_size(b"not an image") is None
