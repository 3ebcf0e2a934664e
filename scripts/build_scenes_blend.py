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
        elif key == "reflectance_named":
            a.reflectance.kind, a.reflectance.named, a.reflectance.scale = "NAMED", value, 1.0
        elif key in ("eta", "k"):
            getattr(a, key).kind, getattr(a, key).value = "CONSTANT", value
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


def add_camera(scene, name, origin=(0, -4, 1), target=(0, 0, 0), polarizer=None):
    cam = bpy.data.cameras.new(name)
    # The thesis cameras are Mitsuba's default: 50 mm on the 43.27 mm diagonal of 35 mm film,
    # which for a square image is a 30.594 mm side: 34.02 degrees horizontal field of view.
    w, h = scene.render.resolution_x, scene.render.resolution_y
    cam.lens, cam.sensor_width, cam.sensor_fit = 50.0, math.hypot(36.0, 24.0) * w / math.hypot(w, h), "HORIZONTAL"
    if polarizer is not None:
        cam.spectral_bench.polarizer, cam.spectral_bench.polarizer_angle = True, polarizer
    obj = bpy.data.objects.new(name, cam)
    obj.location = origin
    obj.rotation_euler = (Vector(target) - Vector(origin)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    scene.camera = obj
    return obj


def new_scene(name, case, spp, description, resolution=(512, 512)):
    scene = bpy.data.scenes.new(name)
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.render.resolution_percentage = 100
    a = scene.spectral_bench
    a.case, a.spp, a.max_depth, a.description = case, spp, 64, description
    return scene


def uniform_world(name, kind, value):
    world = bpy.data.worlds.new(name)
    a = world.spectral_bench
    a.enabled = True
    if kind == "NAMED":
        a.radiance.kind, a.radiance.named, a.radiance.scale = "NAMED", value, 1.0
    else:
        a.radiance.kind, a.radiance.value = "CONSTANT", value
    return world


def build_spectral_accuracy(square):
    """Section 3.3.2: the 24-patch ColorChecker (N. Ohta's spectra), each patch a Lambertian
    square, in front of a dark grey board, under a uniform CIE D65 or D50 environment."""
    from spectral_bench.exporters import spectra
    scenes = [new_scene(f"macbeth_chart_{ill}", "spectral_accuracy", 64,
                        f"ColorChecker (N. Ohta's reflectances) under a uniform CIE {ill} environment",
                        resolution=(620, 420)) for ill in ("D65", "D50")]
    first = scenes[0]
    board = add_object(first, "chart_board", square, material("board_0.042", "DIFFUSE", reflectance=0.042),
                       "RECTANGLE", rotation=(math.radians(90), 0, 0))
    board.scale = (7.0, 5.0, 1.0)
    objects = [board]
    for k, patch in enumerate(spectra.colorchecker_patches()):
        row, col = divmod(k, 6)
        mat = material(patch, "DIFFUSE", reflectance_named=patch)
        # patches sit 1 mm in front of the board, so nothing is above their planes
        objects.append(add_object(first, f"patch_{patch[len('colorchecker_'):]}", square, mat, "RECTANGLE",
                                  location=(-5 + 2 * col, -0.001, 3 - 2 * row),
                                  rotation=(math.radians(90), 0, 0), scale=0.95))
    camera = add_camera(first, "chart_camera", origin=(0, -20, 0))
    for ill, scene in zip(("D65", "D50"), scenes):
        scene.world = uniform_world(f"uniform_{ill}", "NAMED", f"cie_{ill.lower()}")
        if scene is not first:
            for obj in objects + [camera]:
                scene.collection.objects.link(obj)
            scene.camera = camera


def build_polarization(square, sphere):
    """Section 3.3.3: Brewster reflection through a linear polariser, and Stokes spheres."""
    from spectral_bench.exporters import spectra
    brewster = math.degrees(math.atan(1.52))  # tan(theta_B) = n2 / n1, n1 = 1
    glass = material("glass_1.52", "DIELECTRIC", int_ior=1.52, ext_ior=1.0, distribution="SMOOTH")
    scenes = []
    for angle in (0, 90):
        scene = new_scene(f"polarizing_plane_{angle}", "polarization", 128,
                          f"Smooth glass (n = 1.52) reflecting a D65 light at Brewster's angle ({brewster:.2f} deg) "
                          f"into the camera through a linear polariser at {angle} degrees (0 = horizontal)")
        scenes.append((angle, scene))
    first = scenes[0][1]
    plane = add_object(first, "glass_plane", square, glass, "RECTANGLE",
                       rotation=(math.radians(90.0 - brewster), 0, 0))
    # the camera's central ray meets the plane (normal 90 - theta_B off the vertical) at the
    # origin at Brewster's angle and leaves 2 theta_B - 90 degrees off the vertical: centre the
    # light on that ray at height 2
    light_y = 2.0 * math.tan(math.radians(2 * brewster - 90.0))
    light = add_area_light(first, "plane_light", 2.0, (0, light_y, 2), "cie_d65", 4.0)
    for angle, scene in scenes:
        if scene is not first:
            for obj in (plane, light):
                scene.collection.objects.link(obj)
        add_camera(scene, f"plane_camera_{angle}", origin=(0, -6, 0), polarizer=float(angle))

    scene = new_scene("polarizing_spheres", "polarization", 128,
                      "Two smooth glass spheres before a smooth conductor sphere (eta 0.27, k 2.78) under uniform "
                      "light, all values at 550 nm; Stokes S0..S3 output")
    scene.spectral_bench.output = "STOKES"
    d65_550 = float(spectra.evaluate({"type": "named", "name": "cie_d65"}, [550.0])[0])
    red_550 = float(spectra.evaluate({"type": "named", "name": "colorchecker_red"}, [550.0])[0])
    scene.world = uniform_world("uniform_d65_at_550nm", "CONSTANT", round(d65_550, 6))
    add_object(scene, "red_floor", square, material("red_at_550nm", "DIFFUSE", reflectance=round(red_550, 6)),
               "RECTANGLE", location=(0, 5, -1), scale=15.0)
    for side, x in (("left", -1.1), ("right", 1.1)):
        add_object(scene, f"glass_sphere_{side}", sphere, glass, "SPHERE", location=(x, -1, 0))
    metal = material("conductor_0.27_2.78", "CONDUCTOR", conductor_named=False, eta=0.27, k=2.78,
                     distribution="SMOOTH")
    add_object(scene, "conductor_sphere", sphere, metal, "SPHERE", location=(0, 1.5, 0.75), scale=1.5)
    add_camera(scene, "spheres_camera", origin=(0, -7, 4))


MONO_450 = ((440.0, 0.0), (450.0, 30.0), (460.0, 0.0))  # a triangle, 10 nm FWHM: "monochromatic" 450 nm
YELLOW_BAND_STRENGTH = 0.01  # 1/nm; the thesis' 0.025 re-emits 2.3 photons per absorbed photon (refused)


def sampled_world(name, points):
    world = bpy.data.worlds.new(name)
    a = world.spectral_bench
    a.enabled = True
    a.radiance.kind = "SAMPLED"
    for wavelength, value in points:
        item = a.radiance.samples.add()
        item.wavelength, item.value = wavelength, value
    return world


def fluorescent_material(name, absorption, emission):
    """The thesis' yellow-based fluorescent material (ColorChecker yellow for its base, as ART's
    CONST_FLUORESCENT_COLOUR: bands 40 nm and 50 nm wide)."""
    return material(name, "DIFFUSE", reflectance_named="colorchecker_yellow", fluorescence="BANDS",
                    absorption_peak=absorption, absorption_width=40.0, emission_peak=emission, emission_width=50.0,
                    strength=YELLOW_BAND_STRENGTH)


def build_fluorescence(square, sphere):
    """Section 3.3.4 (after Mojzik et al. 2018): a yellow-based sphere on a grey floor under uniform
    light, the camera 6 units from its centre (the thesis' geometry); plus a lone sphere under
    uniform light for the exact probe."""
    scenes = {
        "fluorescent_sphere_D50_red": ("cie_d50", 370.0, "under a uniform CIE D50 environment: yellow base plus red"),
        "fluorescent_sphere_mono_invisible": ("mono", 370.0, "under 450 nm light only (a 10 nm FWHM triangle): "
                                              "nothing to absorb, dark"),
        "fluorescent_sphere_mono_red": ("mono", 450.0, "under 450 nm light only (a 10 nm FWHM triangle): "
                                        "absorbs it, bright red"),
        "yellow_sphere_F8": ("cie_fl8", None, "a non-fluorescent yellow sphere under a uniform CIE F8 (FL8) "
                             "environment"),
    }
    floor_mat = material("grey_0.8", "DIFFUSE", reflectance=0.8)
    first = None
    for name, (light, absorption, what) in scenes.items():
        fl = (f", absorbing at {absorption:g} nm (40 nm) and emitting at 650 nm (50 nm), "
              f"strength {YELLOW_BAND_STRENGTH:g}/nm" if absorption else "")
        scene = new_scene(name, "fluorescence", 64, f"Yellow (ColorChecker) sphere on a grey floor{fl}, {what}")
        scene.world = (sampled_world("mono_450", MONO_450) if light == "mono"
                       else uniform_world(f"uniform_{light}", "NAMED", light))
        if first is None:
            first = scene
            floor = add_object(scene, "fluo_floor", square, floor_mat, "RECTANGLE", location=(0, 0, -1), scale=20.0)
            camera = add_camera(scene, "fluo_camera", origin=(0, -6, 0))
        else:
            for obj in (floor, camera):
                scene.collection.objects.link(obj)
            scene.camera = camera
        mat = (fluorescent_material(f"yellow_fluorescent_{absorption:g}_650", absorption, 650.0) if absorption
               else material("yellow", "DIFFUSE", reflectance_named="colorchecker_yellow"))
        add_object(scene, f"sphere_{name}", sphere, mat, "SPHERE")
    scene = new_scene("fluorescent_sphere_lone", "fluorescence", 64,
                      "A lone yellow (ColorChecker) fluorescent sphere, absorbing at 360 nm (40 nm, half of it below "
                      "Mitsuba's 360 nm) and emitting at 600 nm (50 nm), under a uniform CIE D65 environment, "
                      "no floor: rho L + integral P L at every pixel", resolution=(128, 128))
    scene.world = uniform_world("uniform_D65_lone", "NAMED", "cie_d65")
    lone = material("yellow_fluorescent_360_600", "DIFFUSE", reflectance_named="colorchecker_yellow",
                    fluorescence="BANDS", absorption_peak=360.0, absorption_width=40.0, emission_peak=600.0,
                    emission_width=50.0, strength=YELLOW_BAND_STRENGTH)
    add_object(scene, "lone_sphere", sphere, lone, "SPHERE")
    add_camera(scene, "lone_camera", origin=(0, -6, 0))


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
    build_spectral_accuracy(square)
    build_polarization(square, sphere)
    build_fluorescence(square, sphere)
    for s in list(bpy.data.scenes):
        if not s.spectral_bench.case or s.name == "Scene":
            bpy.data.scenes.remove(s)
    bpy.ops.wm.save_as_mainfile(filepath=str(OUT), compress=True)
    print("wrote", OUT, [s.name for s in bpy.data.scenes])


if __name__ == "__main__":
    build()
