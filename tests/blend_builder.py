"""Build a .blend of ordinary Blender scenes from a JSON description, with real bpy, as a user's
file would hold them: run in a child process (one per file, however many scenes it holds)

    python tests/blend_builder.py SPEC.json OUT.blend [SPEC2.json OUT2.blend ...]

(several pairs: the files one after the other in the same child, each from Blender's factory
settings, so that many files pay for one bpy start-up)

SPEC.json is a list of scenes, each
    {"name": str,
     "objects": [{"name": str, "mesh": "quad" | "cube" | "degenerate" | "no_faces", "scale": [x, y, z],
                  "sphere": bool (the extension's analytic sphere), "material": null |
                  {"kind": "principled", "emission": float} | {"kind": "image", "path": PATH} | {"kind": "mix"}}],
     "lights": [{"name": str, "type": "POINT" | "SPOT" | "SUN" | "AREA", "scale": [x, y, z],
                 "settings": {bpy light attribute: value}, "blackbody": null | kelvin}],
     "world": null | {"colour": [r, g, b], "strength": float, "image": null | PATH | "packed",
                      "blackbody": null | kelvin}}
where PATH is a file path kept as given (missing, a folder, ...). Used by tests/exporters/test_blend_values.py
and the .blend fuzzing of tests/hostile/test_fuzz_scenes.py (tests/scene_fuzz.py ``blend_scenes``).
"""
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build(specs, out):
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sys.path.insert(0, str(ROOT))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.exporters import blender_properties
    blender_properties.register()  # the annotated sphere of "sphere": true (a no-op when already registered)
    first = True
    for spec in specs:
        scene = bpy.context.scene if first else bpy.data.scenes.new(spec["name"])
        scene.name, first = spec["name"], False
        _scene(bpy, scene, spec)
    bpy.ops.wm.save_as_mainfile(filepath=str(out))


def _link(bpy, scene, name, data, location, scale=(1.0, 1.0, 1.0)):
    obj = bpy.data.objects.new(name, data)
    obj.location, obj.scale = location, scale
    scene.collection.objects.link(obj)
    return obj


MESHES = {
    "quad": ([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [(0, 1, 2, 3)]),
    "cube": ([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
             [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]),
    "degenerate": ([(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 0, 0)], [(0, 1, 2), (0, 1, 3)]),  # collinear, repeated
    "no_faces": ([(0, 0, 0), (1, 0, 0)], []),
}


def _material(bpy, name, spec):
    if spec is None:
        return None
    mat = bpy.data.materials.new(name)
    nt = mat.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    if spec["kind"] == "principled":
        bsdf.inputs["Emission Strength"].default_value = spec.get("emission", 0.0)
        bsdf.inputs["Emission Color"].default_value = (1.0, 0.5, 0.2, 1.0)
    elif spec["kind"] == "image":
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = _image(bpy, f"{name}_image", spec["path"])
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    elif spec["kind"] == "mix":
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(bsdf.outputs[0], mix.inputs[1])
        nt.links.new(mix.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    return mat


def _image(bpy, name, path):
    if path == "packed":
        img = bpy.data.images.new(name, 4, 2, float_buffer=True)
        img.pixels.foreach_set([0.5] * (4 * 2 * 4))
        img.pack()
        return img
    img = bpy.data.images.new(name, 4, 2)
    img.source, img.filepath = "FILE", path  # a file that may not exist, or a folder: as a moved .blend has it
    return img


def _scene(bpy, scene, spec):
    cd = bpy.data.cameras.new(f"{spec['name']}_camera")
    cam = _link(bpy, scene, f"{spec['name']}_camera", cd, (0.0, -8.0, 2.0))
    cam.rotation_euler = (math.radians(80), 0.0, 0.0)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 32, 24, 100
    for i, o in enumerate(spec.get("objects", [])):
        verts, faces = MESHES[o.get("mesh", "quad")]
        me = bpy.data.meshes.new(f"{spec['name']}_{o['name']}")
        me.from_pydata(verts, [], faces)
        mat = _material(bpy, f"{spec['name']}_{o['name']}_mat", o.get("material"))
        if mat is not None:
            me.materials.append(mat)
        obj = _link(bpy, scene, o["name"], me, (i - 1.0, 0.0, 0.5), o.get("scale", (1, 1, 1)))
        if o.get("sphere"):
            obj.spectral_bench.shape = "SPHERE"
    for i, light in enumerate(spec.get("lights", [])):
        data = bpy.data.lights.new(f"{spec['name']}_{light['name']}", light["type"])
        for key, value in light.get("settings", {}).items():
            setattr(data, key, value)
        if light.get("blackbody") is not None:
            data.use_nodes = True
            emission = next(n for n in data.node_tree.nodes if n.bl_idname == "ShaderNodeEmission")
            black = data.node_tree.nodes.new("ShaderNodeBlackbody")
            black.inputs["Temperature"].default_value = light["blackbody"]
            data.node_tree.links.new(black.outputs[0], emission.inputs["Color"])
        _link(bpy, scene, light["name"], data, (i - 1.0, -1.0, 3.0), light.get("scale", (1, 1, 1)))
    w = spec.get("world")
    if w is not None:
        world = bpy.data.worlds.new(f"{spec['name']}_world")
        bg = world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (*w.get("colour", (0.2, 0.3, 0.4)), 1.0)
        bg.inputs["Strength"].default_value = w.get("strength", 1.0)
        if w.get("image") is not None:
            env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
            env.image = _image(bpy, f"{spec['name']}_sky", w["image"])
            world.node_tree.links.new(env.outputs["Color"], bg.inputs["Color"])
        elif w.get("blackbody") is not None:
            black = world.node_tree.nodes.new("ShaderNodeBlackbody")
            black.inputs["Temperature"].default_value = w["blackbody"]
            world.node_tree.links.new(black.outputs[0], bg.inputs["Color"])
        scene.world = world


if __name__ == "__main__":
    if len(sys.argv) < 3 or len(sys.argv) % 2 == 0:
        sys.exit("usage: blend_builder.py SPEC.json OUT.blend [SPEC2.json OUT2.blend ...]")
    for spec_path, out_path in zip(sys.argv[1::2], sys.argv[2::2]):
        build(json.loads(Path(spec_path).read_text()), Path(out_path))
