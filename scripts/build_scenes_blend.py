"""Build scenes.blend, the canonical test scenes, one Blender scene per test scene.

    .venv/bin/python scripts/build_scenes_blend.py            (or blender -b -P scripts/build_scenes_blend.py)

Once built, scenes.blend is the source of truth a user edits in Blender; this script records
how it was first made (geometry, light, camera and sample counts after the 2020 thesis,
section 3.3.1; our own scenes). golden/ir/*.json shows every change as a readable diff
(tests/test_blender_ir.py fails until they are regenerated with scripts/update_golden.py).
"""
import math
import sys
from pathlib import Path

import bpy
import bmesh
from mathutils import Vector

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

OUT = pkg_bootstrap.ROOT / "scenes.blend"


def rectangle_mesh(name):
    """The IR rectangle: the square [-1, 1]^2 in local XY, normal +Z."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    return mesh


def sphere_mesh(name):
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=64, v_segments=32, radius=1.0)
    bm.to_mesh(mesh)
    bm.free()
    for p in mesh.polygons:
        p.use_smooth = True
    return mesh


def material(name, kind, **fields):
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    a = mat.spectral_bench
    a.kind = kind
    for key, value in fields.items():
        if key == "reflectance":
            a.reflectance.kind, a.reflectance.value = "CONSTANT", value
            mat.diffuse_color = (value, value, value, 1.0)
        else:
            setattr(a, key, value)
    return mat


def add_object(scene, name, mesh, mat, shape, location=(0, 0, 0), rotation=(0, 0, 0), scale=1.0):
    obj = bpy.data.objects.new(name, mesh.copy())  # own mesh: materials live on mesh data
    obj.data.name = name
    obj.location, obj.rotation_euler, obj.scale = location, rotation, (scale, scale, scale)
    obj.data.materials.append(mat)
    obj.spectral_bench.shape = shape
    scene.collection.objects.link(obj)
    return obj


def add_area_light(scene, name, size, location, illuminant, scale):
    light = bpy.data.lights.new(name, "AREA")
    light.shape, light.size = "SQUARE", size
    light.spectral_bench.radiance.kind = "NAMED"
    light.spectral_bench.radiance.named = illuminant
    light.spectral_bench.radiance.scale = scale
    light.energy = 100.0 * scale * size * size  # viewport only; the annotation is what exports
    obj = bpy.data.objects.new(name, light)
    obj.location = location  # Blender area lights emit along local -Z: straight down here
    scene.collection.objects.link(obj)
    return obj


def add_camera(scene, name, origin=(0, -4, 1), target=(0, 0, 0)):
    cam = bpy.data.cameras.new(name)
    # The thesis cameras are Mitsuba's default: 50 mm on the 43.27 mm diagonal of 35 mm film,
    # which for a square image is a 30.594 mm side: 34.02 degrees horizontal field of view.
    cam.lens, cam.sensor_width, cam.sensor_fit = 50.0, math.hypot(36.0, 24.0) / math.sqrt(2.0), "HORIZONTAL"
    obj = bpy.data.objects.new(name, cam)
    obj.location = origin
    obj.rotation_euler = (Vector(target) - Vector(origin)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    scene.camera = obj
    return obj


def new_scene(name, case, spp, description):
    scene = bpy.data.scenes.new(name)
    scene.render.resolution_x = scene.render.resolution_y = 512
    scene.render.resolution_percentage = 100
    a = scene.spectral_bench
    a.case, a.spp, a.max_depth, a.description = case, spp, 64, description
    return scene


def build():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    pkg_bootstrap.package().register()
    square = rectangle_mesh("square")
    sphere = sphere_mesh("sphere")
    copper = material("ggx_copper", "CONDUCTOR", conductor_named=True, conductor="Cu",
                      distribution="GGX", alpha=0.2)
    grey = material("grey_0.5", "DIFFUSE", reflectance=0.5)
    glass = material("ggx_glass", "DIELECTRIC", int_ior=1.5046, ext_ior=1.000277,
                     distribution="GGX", alpha=0.2)
    # Blender object names are global: the floor, light and camera are one object each, linked
    # into all four copper scenes; each scene has its own plate.
    copper_scenes = [new_scene(f"ggx_copper_{angle}", "reflectance", 64,
                               f"Rough GGX copper square (alpha 0.2) turned {angle} degrees about x, grey floor, "
                               "small D65 area light above") for angle in (50, 60, 70, 80)]
    first = copper_scenes[0]
    floor = add_object(first, "floor", square, grey, "RECTANGLE", location=(0, 0, -1), scale=10.0)
    light = add_area_light(first, "light", 1.0, (0, 0, 1.5), "cie_d65", 4.0)
    camera = add_camera(first, "copper_camera")
    for angle, scene in zip((50, 60, 70, 80), copper_scenes):
        add_object(scene, f"copper_plate_{angle}", square, copper, "RECTANGLE", rotation=(math.radians(angle), 0, 0))
        if scene is not first:
            for obj in (floor, light, camera):
                scene.collection.objects.link(obj)
            scene.camera = camera
    scene = new_scene("ggx_glass", "reflectance", 256,
                      "Rough GGX glass sphere (alpha 0.2, IOR 1.5046) under a D65 area light, clear of the sphere")
    add_object(scene, "glass_sphere", sphere, glass, "SPHERE")
    # The thesis' light touched the sphere's top (z = 1.000002 vs 1.0), which made the image
    # ill-conditioned; ours leaves a 0.25 gap.
    add_area_light(scene, "glass_light", 2.0, (0, 0, 1.25), "cie_d65", 5.0)
    add_camera(scene, "glass_camera")
    for s in list(bpy.data.scenes):
        if not s.spectral_bench.case or s.name == "Scene":
            bpy.data.scenes.remove(s)
    bpy.ops.wm.save_as_mainfile(filepath=str(OUT), compress=True)
    print("wrote", OUT, [s.name for s in bpy.data.scenes])


if __name__ == "__main__":
    build()
