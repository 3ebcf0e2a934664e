"""Write an ordinary .blend, made with bpy as any Blender user makes one, with no spectral
annotation: scene "ordinary" (four Principled BSDF spheres of different base colours, one of them
metallic gold, on a Principled floor; a 100 W point light, a 300 W area light, a world colour)
scene "zoo" (one of each conversion and loss the export warns about), and small plane scenes whose every light has a closed form (a Diffuse BSDF plane seen straight
down through a 1-degree camera: under a world colour, a point, spot, sun, area and disk light,
and a blackbody point light), and scene "textured" (Principled spheres at Blender's defaults, a
floor whose base colour is an image texture, a world lit by an HDRI, an emissive panel; its two
images are written beside the .blend). tests/exporters/test_blender_conversion.py and
tests/studies/test_spectral_vs_rgb.py export and render them.

    python scripts/make_ordinary_blend.py OUT.blend      (or: blender -b -P this -- OUT.blend)
"""
import math
import sys
from pathlib import Path

import bpy

RHO = 0.5  # the planes' diffuse reflectance
HEIGHT = 2.0  # lights above the plane
PLANE_LIGHTS = {
    # scene: (light type, settings)
    "plane_point": ("POINT", {"energy": 100.0, "color": (1.0, 0.8, 0.6), "shadow_soft_size": 0.0}),
    "plane_spot": ("SPOT", {"energy": 100.0, "spot_size": math.radians(60), "spot_blend": 0.0, "shadow_soft_size": 0.0}),
    "plane_sun": ("SUN", {"energy": 3.0, "angle": 0.0}),
    "plane_area": ("AREA", {"energy": 300.0, "shape": "RECTANGLE", "size": 1.0, "size_y": 0.5}),
    "plane_disk": ("AREA", {"energy": 300.0, "shape": "DISK", "size": 1.0}),
    "plane_blackbody": ("POINT", {"energy": 100.0, "use_temperature": True, "temperature": 3000.0, "shadow_soft_size": 0.0}),
    "plane_warm_tint": ("POINT", {"energy": 100.0, "use_temperature": True, "temperature": 3000.0,
                                  "color": (0.6, 0.8, 1.0), "shadow_soft_size": 0.0}),
}
PLANE_CAMERA = (1.0, 1.0)  # the plane scenes' camera: height above the plane, horizontal fov in degrees
SUN_TILT = math.radians(30)  # the sun shines 30 degrees off the vertical
WORLD_COLOUR, WORLD_STRENGTH = (0.2, 0.4, 0.8), 2.0


def principled(name, colour, metallic=0.0, roughness=0.5):
    m = bpy.data.materials.new(name)
    p = m.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (*colour, 1.0)
    p.inputs["Metallic"].default_value = metallic
    p.inputs["Roughness"].default_value = roughness
    return m


def diffuse(name, rho):
    m = bpy.data.materials.new(name)
    nt = m.node_tree
    node = nt.nodes.new("ShaderNodeBsdfDiffuse")
    node.inputs["Color"].default_value = (rho, rho, rho, 1.0)
    nt.links.new(node.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    return m


def link(scene, name, data, location=(0, 0, 0), rotation=(0, 0, 0)):
    obj = bpy.data.objects.new(name, data)
    obj.location, obj.rotation_euler = location, rotation
    scene.collection.objects.link(obj)
    return obj


def quad(name, half, material):
    me = bpy.data.meshes.new(name)
    me.from_pydata([(-half, -half, 0), (half, -half, 0), (half, half, 0), (-half, half, 0)], [], [(0, 1, 2, 3)])
    me.materials.append(material)
    return me


def uv_sphere(name, radius, material):
    import bmesh
    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=radius)
    bm.to_mesh(me)
    bm.free()
    me.materials.append(material)
    return me


def world(name, colour, strength):
    w = bpy.data.worlds.new(name)
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*colour, 1.0)
    bg.inputs["Strength"].default_value = strength
    return w


def camera(scene, location, rotation, fov_deg=40.0, size=(320, 240)):
    cd = bpy.data.cameras.new(f"{scene.name}_camera")
    cd.sensor_fit = "HORIZONTAL"
    cd.angle = math.radians(fov_deg)
    scene.camera = link(scene, f"{scene.name}_camera", cd, location, rotation)
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100


def ordinary(scene):
    camera(scene, (0.0, -7.0, 2.5), (math.radians(75), 0.0, 0.0))
    link(scene, "floor", quad("floor", 6.0, principled("floor_grey", (0.5, 0.5, 0.5))))
    for i, (name, colour, metallic) in enumerate((("red", (0.8, 0.1, 0.1), 0.0), ("green", (0.1, 0.6, 0.2), 0.0),
                                                  ("blue", (0.1, 0.2, 0.8), 0.0), ("gold", (1.0, 0.78, 0.34), 1.0))):
        link(scene, f"sphere_{name}", uv_sphere(name, 0.6, principled(name, colour, metallic, 0.3)),
             (-2.4 + 1.6 * i, 0.0, 0.6))
    point = bpy.data.lights.new("point", "POINT")
    point.energy, point.color = 100.0, (1.0, 0.9, 0.8)
    link(scene, "point_light", point, (2.0, -2.0, 3.0))
    area = bpy.data.lights.new("area", "AREA")
    area.energy, area.shape, area.size = 300.0, "SQUARE", 1.0
    link(scene, "area_light", area, (-1.0, -1.0, 4.0))
    scene.world = world("sky", (0.05, 0.07, 0.1), 1.0)


def plane_scene(name):
    scene = bpy.data.scenes.new(name)
    camera(scene, (0.0, 0.0, PLANE_CAMERA[0]), (0.0, 0.0, 0.0), fov_deg=PLANE_CAMERA[1], size=(16, 16))
    link(scene, "plane", quad(f"{name}_plane", 50.0, diffuse(f"{name}_rho", RHO)))
    return scene


def zoo(scene):
    """Scene "zoo": one of each conversion and loss the export warns about (a textured base colour,
    a mix shader, glass, an unnamed metal, a coat, an emissive Principled, a disk and an ellipse
    light, a soft sun, a blended spot, a light with exposure and a Blackbody node, an HDRI world,
    a curve object, an instanced collection, smooth shading, a mesh without material, depth of field,
    a transparent film)."""
    camera(scene, (0.0, -8.0, 3.0), (math.radians(72), 0.0, 0.0), size=(64, 48))
    textured = principled("textured", (0.3, 0.3, 0.3))
    tex = textured.node_tree.nodes.new("ShaderNodeTexChecker")
    textured.node_tree.links.new(tex.outputs["Color"], textured.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    mixed = bpy.data.materials.new("mixed")
    nt = mixed.node_tree
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(nt.nodes["Principled BSDF"].outputs[0], mix.inputs[1])
    nt.links.new(mix.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    glass = principled("glass", (1.0, 1.0, 1.0), roughness=0.0)
    glass.node_tree.nodes["Principled BSDF"].inputs["Transmission Weight"].default_value = 1.0
    glass.node_tree.nodes["Principled BSDF"].inputs["IOR"].default_value = 1.45
    violet = principled("violet_metal", (0.6, 0.2, 0.9), metallic=1.0, roughness=0.2)
    coated = principled("coated", (0.2, 0.5, 0.5))
    coated.node_tree.nodes["Principled BSDF"].inputs["Coat Weight"].default_value = 1.0
    glowing = principled("glowing", (0.1, 0.1, 0.1))
    glowing.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 3.0
    glowing.node_tree.nodes["Principled BSDF"].inputs["Emission Color"].default_value = (1.0, 0.5, 0.2, 1.0)
    for i, m in enumerate((textured, mixed, glass, violet, coated, glowing)):
        me = uv_sphere(m.name, 0.4, m)
        if m is coated:
            me.shade_smooth()
        link(scene, f"ball_{m.name}", me, (-2.5 + i, 0.0, 0.4))
    link(scene, "bare", quad("bare", 0.3, principled("unused", (0.5, 0.5, 0.5))), (0.0, 2.0, 0.01)).data.materials.clear()
    for name, kind, settings, location in (
            ("disk", "AREA", {"shape": "DISK", "size": 0.6, "energy": 50.0}, (-1.0, 0.0, 3.0)),
            ("ellipse", "AREA", {"shape": "ELLIPSE", "size": 0.8, "size_y": 0.4, "energy": 50.0}, (1.0, 0.0, 3.0)),
            ("soft_sun", "SUN", {"energy": 1.0, "angle": math.radians(5)}, (0.0, 0.0, 5.0)),
            ("blended_spot", "SPOT", {"energy": 200.0, "spot_size": math.radians(50), "spot_blend": 0.4,
                                      "shadow_soft_size": 0.1}, (0.0, -2.0, 4.0)),
            ("exposed", "POINT", {"energy": 20.0, "exposure": 1.0, "shadow_soft_size": 0.0}, (2.0, -1.0, 2.0))):
        light = bpy.data.lights.new(name, kind)
        for key, value in settings.items():
            setattr(light, key, value)
        link(scene, name, light, location)
    bb = bpy.data.lights["exposed"]
    bb.use_nodes = True
    emission = next(n for n in bb.node_tree.nodes if n.bl_idname == "ShaderNodeEmission")
    black = bb.node_tree.nodes.new("ShaderNodeBlackbody")
    black.inputs["Temperature"].default_value = 4000.0
    bb.node_tree.links.new(black.outputs[0], emission.inputs["Color"])
    curve = bpy.data.curves.new("path", "CURVE")
    link(scene, "path", curve)
    group = bpy.data.collections.new("props")
    group.objects.link(bpy.data.objects["ball_glass"])
    inst = link(scene, "prop_instance", None, (0.0, 1.5, 0.0))
    inst.instance_type, inst.instance_collection = "COLLECTION", group
    scene.camera.data.dof.use_dof = True
    scene.render.film_transparent = True
    img = bpy.data.images.new("sky_hdri", 8, 4, float_buffer=True)
    img.pixels.foreach_set([v for row in range(4) for _ in range(8) for v in ((0.5, 0.6, 0.9, 1.0) if row >= 2 else (0.2, 0.15, 0.1, 1.0))])
    img.pack()
    w = world("hdri_world", (0.0, 0.0, 0.0), 1.5)
    env = w.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    w.node_tree.links.new(env.outputs["Color"], w.node_tree.nodes["Background"].inputs["Color"])
    scene.world = w


CHECKER = ((0.8, 0.8, 0.8), (0.1, 0.1, 0.3))  # the floor texture's two colours (sRGB-encoded)
SUN = (-60.0, 35.0, 3000.0)  # the sky map's sun: azimuth from +X (towards +Y) and elevation in degrees, radiance


# the textured scene's spheres: Blender's default roughness is 0.5; at 0.3 (as the "ordinary" scene's)
# the coat's highlight lifts each sphere's brightest block above the diffuse-only export's (issue 42)
SPHERE_ROUGHNESS = 0.3


def _saved_image(path, rows_top_down, float_buffer):
    """An image file written with OpenImageIO (Blender's Image.save would pass a float image
    through the scene's view transform), loaded into Blender as a user's image is."""
    import numpy as np
    import OpenImageIO as oiio
    px = np.asarray(rows_top_down, dtype=np.float32)
    if not float_buffer:
        px = np.round(np.clip(px, 0, 1) * 255).astype(np.uint8)
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2],
                                                            "float" if float_buffer else "uint8")):
        raise RuntimeError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(px)
    out.close()
    return bpy.data.images.load(str(path), check_existing=False)


def textured(scene, folder):
    """Scene "textured": Principled spheres at Blender's defaults but their colour and roughness
    (SPHERE_ROUGHNESS; a specular layer: a coat), a floor whose base colour is a checker image (floor_checker.png, 64 x 64 in squares of 8), a
    world lit by an equirectangular HDRI (sky.exr: a blue gradient and a small sun 35 degrees up, in front of the spheres to the right),
    an emissive panel; the images are written beside the .blend (``folder``)."""
    import math as m
    camera(scene, (0.0, -7.0, 2.5), (math.radians(75), 0.0, 0.0))
    checker = _saved_image(Path(folder) / "floor_checker.png",
                           [[CHECKER[(x // 8 + y // 8) % 2] for x in range(64)] for y in range(64)], False)
    checker.colorspace_settings.name = "sRGB"
    w, h = 128, 64
    sky = []
    for row in range(h):  # top to bottom: row 0 is the zenith
        elevation = 90.0 - (row + 0.5) / h * 180.0
        line = []
        for col in range(w):
            azimuth = 180.0 - (col + 0.5) / w * 360.0  # u = 1/2 - phi / 2 pi (docs/scene-format.md 7.1)
            sun = abs(elevation - SUN[1]) < 2.0 and abs((azimuth - SUN[0] + 180.0) % 360.0 - 180.0) < 2.0
            base = (0.15, 0.22, 0.4) if elevation > 0 else (0.08, 0.06, 0.05)
            line.append((SUN[2],) * 3 if sun else
                        tuple(c * (1.0 if elevation <= 0 else 0.6 + 0.4 * m.sin(m.radians(elevation))) for c in base))
        sky.append(line)
    hdri = _saved_image(Path(folder) / "sky.exr", sky, True)
    hdri.colorspace_settings.name = "Linear Rec.709"
    floor_mat = principled("floor_checker", (0.5, 0.5, 0.5))
    nt = floor_mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = checker
    nt.links.new(tex.outputs["Color"], nt.nodes["Principled BSDF"].inputs["Base Color"])
    floor = quad("floor_tiled", 6.0, floor_mat)
    uv = floor.uv_layers.new(name="UVMap")
    for loop, corner in zip(uv.data, ((0, 0), (3, 0), (3, 3), (0, 3))):  # the checker repeated 3 x 3
        loop.uv = corner
    link(scene, "tex_floor", floor)
    for i, (name, colour) in enumerate((("red", (0.8, 0.1, 0.1)), ("green", (0.1, 0.6, 0.2)), ("blue", (0.1, 0.2, 0.8)))):
        mat = bpy.data.materials.new(f"{name}_default")
        mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*colour, 1.0)
        mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = SPHERE_ROUGHNESS
        link(scene, f"tex_sphere_{name}", uv_sphere(f"{name}_ball", 0.6, mat), (-1.6 + 1.6 * i, 0.0, 0.6))
    glow = bpy.data.materials.new("panel_glow")
    gnt = glow.node_tree
    emission = gnt.nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (1.0, 0.8, 0.6, 1.0)
    emission.inputs["Strength"].default_value = 5.0
    gnt.links.new(emission.outputs[0], gnt.nodes["Material Output"].inputs["Surface"])
    link(scene, "tex_panel", quad("panel", 0.5, glow), (2.5, 1.5, 1.5), (math.radians(90), 0.0, math.radians(-30)))
    w_sky = bpy.data.worlds.new("hdri_sky")
    env = w_sky.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = hdri
    w_sky.node_tree.links.new(env.outputs["Color"], w_sky.node_tree.nodes["Background"].inputs["Color"])
    scene.world = w_sky


def build(folder=None):
    """Every scene; "textured" too when ``folder`` (where the .blend goes: its images are written
    there) is given."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.name = "ordinary"
    ordinary(scene)
    if folder is not None:
        textured(bpy.data.scenes.new("textured"), folder)
    zoo(bpy.data.scenes.new("zoo"))
    sc = plane_scene("plane_world")
    sc.world = world("plane_world", WORLD_COLOUR, WORLD_STRENGTH)
    for name, (kind, settings) in PLANE_LIGHTS.items():
        sc = plane_scene(name)
        sc.world = world(f"{name}_black", (0.0, 0.0, 0.0), 0.0)
        light = bpy.data.lights.new(name, kind)
        for key, value in settings.items():
            setattr(light, key, value)
        link(sc, f"{name}_light", light, (0.0, 0.0, HEIGHT), (SUN_TILT, 0.0, 0.0) if kind == "SUN" else (0, 0, 0))


if __name__ == "__main__":
    out = Path(sys.argv[sys.argv.index("--") + 1] if "--" in sys.argv else sys.argv[1]).resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    build(out.parent)
    bpy.ops.wm.save_as_mainfile(filepath=str(out))
