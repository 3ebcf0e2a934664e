"""Build scenes.blend, the canonical test scenes, one Blender scene per test scene.

    .venv/bin/python scripts/build_scenes_blend.py            (or blender -b -P scripts/build_scenes_blend.py)

Once built, scenes.blend is the source of truth a user edits in Blender; this script records
how it was first made (geometry, light, camera and sample counts after the 2020 thesis,
section 3.3.1; our own scenes). golden/ir/*.json shows every change as a readable diff
(tests/exporters/test_blender_ir.py fails until they are regenerated with scripts/update_golden.py).
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


IRIDESCENT_X = (-3.6, -1.2, 1.2, 3.6)  # four unit spheres in a row, left to right in the image


def build_iridescence(square, sphere):
    """Section 3.3.5: four slightly rough (Beckmann alpha 0.1, the thesis plugin's default
    distribution) conductor spheres with and without a dielectric thin film, under uniform
    daylight, a grey backdrop behind them; and a lone smooth filmed sphere for the Airy probe."""
    resolution = (800, 256)

    def row(name, description, materials):
        scene = new_scene(name, "iridescence", 64, description, resolution=resolution)
        scene.world = uniform_world(f"uniform_{name}", "NAMED", "cie_d65")
        scene.world.spectral_bench.radiance.scale = 0.8
        for k, (x, mat) in enumerate(zip(IRIDESCENT_X, materials)):
            add_object(scene, f"{name}_sphere_{k + 1}", sphere, mat, "SPHERE", location=(x, 0, 0))
        add_object(scene, f"{name}_backdrop", square, material("backdrop_0.6", "DIFFUSE", reflectance=0.6),
                              "RECTANGLE", location=(0, 3, 0), rotation=(math.radians(90), 0, 0), scale=10.0)
        add_camera(scene, f"{name}_camera", origin=(0, -12, 0))

    def base(name, film=None, conductor=None, distribution="BECKMANN", alpha=0.1):
        fields = dict(distribution=distribution, alpha=alpha)
        if conductor:
            fields.update(conductor_named=True, conductor=conductor)
        else:
            fields.update(conductor_named=False, eta=1.9, k=1.5)
        if film is not None:
            fields.update(thin_film=True, film_ior=film[0], film_thickness=film[1], film_ext_ior=1.0)
        return material(name, "CONDUCTOR", **fields)

    row("iridescent_spheres_height", "Conductor spheres (eta 1.9, k 1.5; Beckmann alpha 0.1) under films of index "
        "1.33, 300, 550 and 1500 nm thick, and without a film (left to right), uniform D65",
        [base(f"film_1.33_{d}nm", (1.33, float(d))) for d in (300, 550, 1500)] + [base("film_none")])
    row("iridescent_spheres_film", "Conductor spheres (eta 1.9, k 1.5; Beckmann alpha 0.1) under 550 nm films of "
        "index 1.2, 1.5, 1.8 and 2.8 (left to right), uniform D65",
        [base(f"film_{n}_550nm", (n, 550.0)) for n in (1.2, 1.5, 1.8, 2.8)])
    row("iridescent_spheres_materials", "Copper with and without a 550 nm film of index 1.33, then mercury with and "
        "without it (left to right; Beckmann alpha 0.1), uniform D65",
        [base("Cu_film_1.33_550nm", (1.33, 550.0), "Cu"), base("Cu_bare", None, "Cu"),
         base("Hg_film_1.33_550nm", (1.33, 550.0), "Hg"), base("Hg_bare", None, "Hg")])
    scene = new_scene("iridescent_sphere_smooth", "iridescence", 64,
                      "A lone smooth conductor sphere (eta 1.9, k 1.5) under a 550 nm film of index 1.33 in a "
                      "uniform D65 environment: the Airy probe's scene", resolution=(256, 256))
    scene.world = uniform_world("uniform_d65_smooth", "NAMED", "cie_d65")
    add_object(scene, "smooth_film_sphere", sphere, base("smooth_film_1.33_550nm", (1.33, 550.0), distribution="SMOOTH"),
               "SPHERE")
    add_camera(scene, "smooth_film_camera", origin=(0, -4, 0))
def build_coated(sphere):
    """A lone smooth coated diffuse sphere (a dielectric coat of IOR 1.5 over the ColorChecker's red
    as its Lambertian base: Mitsuba 3's plastic) in a uniform D65 environment: the coat probe's
    scene (batch/verdict/probes/coated.py)."""
    scene = new_scene("coated_sphere", "coated", 64,
                      "A lone smooth coated diffuse sphere (coat IOR 1.5 over ColorChecker red) in a uniform D65 "
                      "environment: the coat probe's scene", resolution=(256, 256))
    scene.world = uniform_world("uniform_d65_coated", "NAMED", "cie_d65")
    coat = material("coated_red_1.5", "COATED", reflectance_named="colorchecker_red", int_ior=1.5,
                    ext_ior=1.000277, distribution="SMOOTH")
    add_object(scene, "coated_sphere", sphere, coat, "SPHERE")
    add_camera(scene, "coated_camera", origin=(0, -4, 0))


def prism_mesh(name, apex_deg, side, height):
    """A triangular prism: apex angle ``apex_deg`` at +Y, sides of length ``side``, extruded
    along Z over ``height`` (centred); faces wound so their normals point outwards."""
    half = math.radians(apex_deg) / 2
    b, h = side * math.sin(half), side * math.cos(half)
    apex_y = 0.6 * h  # the beam crosses the faces near their middle (the scene places it there)
    tri = [(0.0, apex_y), (-b, apex_y - h), (b, apex_y - h)]
    verts = [(x, y, -height / 2) for x, y in tri] + [(x, y, height / 2) for x, y in tri]
    faces = [(0, 2, 1), (3, 4, 5), (0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    return mesh


def build_dispersion(square, sphere):
    """Dispersion (the thesis' empty section 3.3.6): a collimated D65 beam through an N-BK7
    prism fanned out on a white screen (rendered by light tracing: no camera path reaches a
    collimated beam), and an N-SF11 sphere before fine black-and-white stripes (chromatic fringes)."""
    from spectral_bench.exporters import dispersion
    apex, lam0 = 30.0, 550.0
    n0 = float(dispersion.ior({"type": "named", "name": "N-BK7"}, [lam0])[0])
    # minimum deviation at 550 nm: inside, the ray runs parallel to the base; the beam goes along
    # +X, so the prism turns until the entry face meets it at theta_i = asin(n sin(apex / 2))
    theta_i = math.asin(n0 * math.sin(math.radians(apex / 2)))
    turn = math.radians(apex / 2) - theta_i
    deviation = 2 * theta_i - math.radians(apex)
    # Lengths are 10x a lab bench's (the beam 0.08 x 0.5, the screen 40 away): Mitsuba offsets every
    # spawned ray by 8.9e-5 x (1 + |p|) along the normal, which moves a refracted beam sideways;
    # at this size that is ~0.002 px (at 1x, measured: ~0.01 px, as large as the noise at 64 spp)
    u = 10.0
    scene = new_scene("dispersion_prism", "dispersion", 128,  # 128 spp: 1 % detectable (benchmarks/CALIBRATION.md)
                      f"A collimated D65 beam (0.08 x 0.5) through a {apex:g} degree N-BK7 prism (sides 5) at minimum "
                      f"deviation for {lam0:g} nm, fanned out on a white screen 40 away; light tracing (ptracer)",
                      resolution=(256, 128))
    scene.spectral_bench.integrator = "PTRACER"
    bk7 = material("N-BK7", "DIELECTRIC", ior_model="NAMED", glass="N-BK7", ext_ior=1.000277, distribution="SMOOTH")
    add_object(scene, "prism", prism_mesh("prism", apex, 0.5 * u, 0.3 * u), bk7, "MESH", rotation=(0, 0, turn))
    # the entry face's middle, turned with the prism: the beam's height
    half = math.radians(apex / 2)
    h = 0.5 * u * math.cos(half)
    mx, my = -0.25 * u * math.sin(half), 0.6 * h - 0.5 * h
    beam_y = mx * math.sin(turn) + my * math.cos(turn)
    exit_x, exit_y = -mx * math.cos(turn) - my * math.sin(turn), -mx * math.sin(turn) + my * math.cos(turn)
    light = bpy.data.lights.new("beam", "AREA")
    light.shape, light.size, light.size_y = "RECTANGLE", 0.05 * u, 0.008 * u  # tall, narrow across the fan
    light.spectral_bench.collimated = True
    r = light.spectral_bench.radiance
    r.kind, r.named, r.scale = "NAMED", "cie_d65", 40.0
    light.energy = 1.0
    beam = bpy.data.objects.new("beam", light)
    beam.location = (-2.0 * u, beam_y, 0.0)
    beam.rotation_euler = (0.0, math.radians(-90.0), 0.0)  # the light's -Z (its emission) along +X
    scene.collection.objects.link(beam)
    dx, dy = math.cos(-deviation), math.sin(-deviation)
    distance = 4.0 * u
    centre = (exit_x + distance * dx, exit_y + distance * dy, 0.0)
    gamma = math.atan2(-dx, dy)  # turns the square's normal (-Y after the X turn) to face the prism
    screen = add_object(scene, "screen", square, material("screen_0.8", "DIFFUSE", reflectance=0.8), "RECTANGLE",
                        location=centre, rotation=(math.radians(90), 0, gamma))
    screen.scale = (0.6 * u, 0.3 * u, 1.0)
    # the camera faces the screen from 10, aimed 0.55 to the less deviated side, so that a fan
    # 2 degrees less deviated (fused silica in place of N-BK7) is in view as well
    along = (math.cos(gamma), math.sin(gamma))  # the screen's local x: towards more deviation
    target = (centre[0] - 0.055 * u * along[0], centre[1] - 0.055 * u * along[1], 0.0)
    origin = (target[0] - 1.0 * u * dx, target[1] - 1.0 * u * dy, 0.25 * u)
    cam = add_camera(scene, "prism_camera", origin=origin, target=target)
    cam.data.lens = cam.data.sensor_width / (2 * math.tan(math.radians(18.0) / 2))  # 18 degrees wide

    scene = new_scene("dispersion_fringes", "dispersion", 256,
                      "A smooth N-SF11 sphere (Abbe number 25.7) before black and white stripes 0.15 wide under a "
                      "uniform D65 environment: chromatic fringes where the sphere refracts the stripes' edges",
                      resolution=(256, 256))
    scene.world = uniform_world("uniform_d65_fringes", "NAMED", "cie_d65")
    sf11 = material("N-SF11", "DIELECTRIC", ior_model="NAMED", glass="N-SF11", ext_ior=1.000277, distribution="SMOOTH")
    add_object(scene, "sf11_sphere", sphere, sf11, "SPHERE")
    # The board and its stripes lie in one plane, edge to edge: 19 black stripes 0.15 wide every 0.3
    # between white strips, the board 8 x 8. (Black stripes 0.001 in front of a white board made
    # the reference depend on the renderer's ray offset: Mitsuba's board saw past the stripes' edges
    # and read 0.22 % brighter than pbrt-v4 and ART, docs/findings.md, pbrt-v4 (7).)
    white, black = material("white_0.8", "DIFFUSE", reflectance=0.8), material("black_0", "DIFFUSE", reflectance=0.0)

    def strip(name, mat, x0, x1):
        obj = add_object(scene, name, square, mat, "RECTANGLE", location=((x0 + x1) / 2, 3, 0),
                         rotation=(math.radians(90), 0, 0))
        obj.scale = ((x1 - x0) / 2, 4.0, 1.0)
    edges = [-4.0] + [e for k in range(-9, 10) for e in (0.3 * k - 0.075, 0.3 * k + 0.075)] + [4.0]
    for i, (x0, x1) in enumerate(zip(edges[:-1], edges[1:])):
        if i % 2:
            strip(f"stripe_{i // 2:02d}", black, x0, x1)
        else:
            strip(f"white_board_{i // 2:02d}", white, x0, x1)
    add_camera(scene, "fringes_camera", origin=(0, -6, 0), target=(0, 0, 0))
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


# The spectral furnaces (issue 41): a closed diffuse enclosure around the camera, every face
# emitting the same radiance Le and reflecting rho, so L = Le sum_k<d rho^k (d = max_depth)
# everywhere (batch/verdict/probes/furnace.py). Any closed enclosure gives the same closed form
# (irradiance pi L on every face), so the sphere is an icosphere, its faces turned inwards.
FURNACE_EMISSION = 0.25  # Principled Emission Strength on a white colour: Le = 0.25 x D65 / Y(D65)
# a spiky reflectance (no RGB can hold it): 0.05 with three 10 nm (FWHM) triangles up to 0.9
FURNACE_SPIKES = ((440.0, 0.05), (450.0, 0.9), (460.0, 0.05), (530.0, 0.05), (540.0, 0.9), (550.0, 0.05),
                  (600.0, 0.05), (610.0, 0.9), (620.0, 0.05))


def furnace_mesh(name, radius=2.0):
    """An icosphere (bmesh's subdivisions 2: 42 vertices, 80 flat faces) of ``radius`` with its faces wound inwards:
    the IR's one-sided surfaces face the camera at the centre."""
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_icosphere(bm, subdivisions=2, radius=radius)
    bmesh.ops.reverse_faces(bm, faces=bm.faces[:])
    bm.to_mesh(mesh)
    bm.free()
    return mesh


def build_furnace():
    """Spectral furnaces: the camera at the centre of a closed diffuse sphere that emits a uniform
    D65 radiance and reflects a measured saturated spectrum (ColorChecker yellow, N. Ohta's data)
    or a spiky one (FURNACE_SPIKES), nothing else in the scene."""
    # spp: the image mean detects 0.06 % (yellow, 256 spp) and 0.32 % (spiky, 512 spp: its peaks make
    # the wavelength samples' values spread; 0.46 % at 256) with 90 % power (Mitsuba, measured)
    for name, what, reflectance, spp in (
            ("furnace_colorchecker_yellow", "ColorChecker yellow (N. Ohta's reflectance)", "colorchecker_yellow", 256),
            ("furnace_spiky", "a spiky reflectance (0.05, three 10 nm peaks of 0.9 at 450, 540, 610 nm)", None, 512)):
        scene = new_scene(name, "furnace", spp,
                          f"Camera at the centre of a closed diffuse sphere (an icosphere, faces inwards) of {what} "
                          f"emitting a uniform D65 radiance ({FURNACE_EMISSION:g} x D65 / Y): "
                          "L = Le (1 - rho^d) / (1 - rho) per wavelength, d = max_depth", resolution=(64, 64))
        if reflectance:
            mat = material(f"furnace_{reflectance}", "DIFFUSE", reflectance_named=reflectance)
        else:
            mat = material("furnace_spiky", "DIFFUSE")
            r = mat.spectral_bench.reflectance
            r.kind = "SAMPLED"
            for wavelength, value in FURNACE_SPIKES:
                item = r.samples.add()
                item.wavelength, item.value = wavelength, value
        node = mat.node_tree.nodes.get("Principled BSDF")
        node.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        node.inputs["Emission Strength"].default_value = FURNACE_EMISSION
        add_object(scene, f"{name}_sphere", furnace_mesh(f"{name}_sphere"), mat, "MESH")
        add_camera(scene, f"{name}_camera", origin=(0, 0, 0), target=(0, 1, 0))


# The GGX white furnace (issue 41 item 2): a lone rough sphere of a perfect conductor under a uniform
# environment, so that L = E(mu_o, alpha) L_env at every pixel (batch/verdict/probes/white_furnace.py).
# A perfect conductor is eta 0, k 1: a purely imaginary index reflects totally, Fresnel exactly 1 at
# every angle (Born and Wolf 14.2; Mitsuba's, pbrt-v4's and Cycles' conductor formulas all give 1).
WHITE_FURNACE_ALPHAS = (0.1, 0.3, 0.6, 1.0)
WHITE_FURNACE_SPP = 128


def build_white_furnace(sphere):
    """Four scenes, one sphere each (in one scene the spheres would light each other: no closed
    form), GGX alpha 0.1, 0.3, 0.6 and 1.0, under a uniform D65 environment."""
    for alpha in WHITE_FURNACE_ALPHAS:
        tag = f"{round(alpha * 100):03d}"
        name = f"furnace_ggx_{tag}"
        scene = new_scene(name, "furnace", WHITE_FURNACE_SPP,
                          f"A lone sphere of a perfect conductor (eta 0, k 1: Fresnel 1) with GGX alpha {alpha:g} "
                          "under a uniform D65 environment, nothing else: L = E(mu_o, alpha) L_env, E the "
                          "single-scattering directional albedo", resolution=(128, 128))
        scene.world = uniform_world(f"uniform_d65_{name}", "NAMED", "cie_d65")
        mat = material(f"perfect_conductor_ggx_{tag}", "CONDUCTOR", conductor_named=False, eta=0.0, k=1.0,
                       distribution="GGX", alpha=alpha)
        add_object(scene, f"{name}_sphere", sphere, mat, "SPHERE")
        add_camera(scene, f"{name}_camera", origin=(0, -4, 0))


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
        plate = add_object(scene, f"copper_plate_{angle}", square, copper, "RECTANGLE",
                           rotation=(math.radians(angle), 0, 0))
        if scene is not first:
            for obj in (floor, light, camera):
                scene.collection.objects.link(obj)
            scene.camera = camera
        # the same plate, light and camera without the floor: direct light is all the plate gets,
        # so every pixel has a closed form (the GGX quadrature probe, batch/verdict/probes/ggx.py)
        alone = new_scene(f"ggx_copper_{angle}_isolated", "reflectance", 64,
                          f"ggx_copper_{angle} without its floor: the copper plate lit by the D65 area light alone")
        for obj in (plate, light, camera):
            alone.collection.objects.link(obj)
        alone.camera = camera
    # grazing view and grazing light (80 degrees from the normal) on a lone plate: where the
    # shadowing-masking of both directions matters (separable and height-correlated Smith differ
    # by 4 % here, by < 0.1 % in the copper scenes above)
    grazing = new_scene("ggx_copper_grazing", "reflectance", 64,
                        "Rough GGX copper plate (alpha 0.2) seen and lit at 80 degrees from its normal, D65 area light")
    add_object(grazing, "copper_plate_grazing", square, copper, "RECTANGLE")
    elevation = math.radians(10.0)
    light_pos = Vector((0.0, 3.0 * math.cos(elevation), 3.0 * math.sin(elevation)))
    glight = add_area_light(grazing, "grazing_light", 1.0, tuple(light_pos), "cie_d65", 4.0)
    glight.rotation_euler = (-light_pos).to_track_quat("-Z", "Y").to_euler()
    add_camera(grazing, "grazing_camera", origin=(0.0, -4.0 * math.cos(elevation), 4.0 * math.sin(elevation)))
    scene = new_scene("ggx_glass", "reflectance", 256,
                      "Rough GGX glass sphere (alpha 0.2, IOR 1.5046) under a D65 area light, clear of the sphere")
    add_object(scene, "glass_sphere", sphere, glass, "SPHERE")
    # The thesis' light touched the sphere's top (z = 1.000002 vs 1.0), which made the image
    # ill-conditioned; ours leaves a 0.25 gap.
    add_area_light(scene, "glass_light", 2.0, (0, 0, 1.25), "cie_d65", 5.0)
    glass_camera = add_camera(scene, "glass_camera")
    glass_light = bpy.data.objects["glass_light"]
    # the thesis' Figure 3.5: the same sphere with the Beckmann distribution of the same alpha
    beckmann = material("beckmann_glass", "DIELECTRIC", int_ior=1.5046, ext_ior=1.000277,
                        distribution="BECKMANN", alpha=0.2)
    twin = new_scene("beckmann_glass", "reflectance", 256,
                     "ggx_glass with a Beckmann distribution of the same alpha (0.2), as in the thesis' Figure 3.5")
    add_object(twin, "beckmann_glass_sphere", sphere, beckmann, "SPHERE")
    for obj in (glass_light, glass_camera):
        twin.collection.objects.link(obj)
    twin.camera = glass_camera
    build_spectral_accuracy(square)
    build_polarization(square, sphere)
    build_iridescence(square, sphere)
    build_coated(sphere)
    build_dispersion(square, sphere)
    build_fluorescence(square, sphere)
    build_furnace()
    build_white_furnace(sphere)
    for s in list(bpy.data.scenes):
        if not s.spectral_bench.case or s.name == "Scene":
            bpy.data.scenes.remove(s)
    bpy.ops.wm.save_as_mainfile(filepath=str(OUT), compress=True)
    print("wrote", OUT, [s.name for s in bpy.data.scenes])


if __name__ == "__main__":
    build()
