"""Cycles in the bpy module, as a child process: build a .blend from an RGB scene, or render a
.blend in independent passes.

    python batch/backends/cycles/worker.py build --scene scene_rgb.json --blend scene.blend
    python batch/backends/cycles/worker.py render --blend scene.blend --spp 64 --passes 2 \
        --seed 0 --out render.exr --result result.json
    python batch/backends/cycles/worker.py serve    # warm: JSON requests on stdin (``serve``)

The .blend holds everything a user needs to re-render it in Blender (Cycles, CPU). How the
reduced scene (exporters/rgb_scene.py) maps to Cycles (bpy 5.0.1; Cycles source
intern/cycles/kernel/svm/closure.h for the roughness conventions):
- Film: pixel filter BOX of width 1 (one pixel: pixels independent, a reference downsamples
  exactly; ``tests/backends/test_rgb_backends.py`` checks it on an edge), sampling pattern Tabulated Sobol
  (Cycles' "Classic"; the default blue noise correlates neighbouring pixels on purpose), a new
  seed per pass, no adaptive sampling, no denoiser, no clamping (direct and indirect 0), no
  Filter Glossy, caustics on, light threshold 0, view transform Standard, look None, exposure 0,
  gamma 1 (EXR output is scene-linear Linear Rec.709, i.e. linear sRGB with a D65 white).
- Bounces: Cycles' max_bounces 0 is direct lighting, Mitsuba's max_depth 2, so every bounce
  limit is max_depth - 2 (checked: a floor lit by a uniform environment and through a wall gives
  Mitsuba's region mean within 0.3 % at max_depth 2, 3 and 4; LuxCore's total depth d within
  0.6 %).
- Diffuse: Diffuse BSDF (roughness 0: Lambert). Conductor: Metallic BSDF, fresnel_type
  PHYSICAL_CONDUCTOR, IOR = eta_rgb, Extinction = k_rgb. Dielectric: Glass BSDF, IOR = int/ext.
  Roughness: Cycles squares its Roughness input (alpha = r^2), so r = sqrt(alpha); distribution
  GGX or BECKMANN (single scattering, as Mitsuba's), never MULTI_GGX.
- One-sidedness: Mitsuba's diffuse and conductor BSDFs are black seen from behind; Cycles' are
  two-sided, so they are mixed with nothing (no closure: black) by the Backfacing output.
  Emitters emit on their front only (Backfacing again; emission sampling FRONT) with Emission
  strength = the largest RGB component and colour = rgb / strength (radiance = rgb).
- Shapes: rectangles are quads in world space wound about the IR normal; meshes are meshes;
  spheres are the same icospheres as LuxCore's (rgb_scene.icosphere, level 6: within 4e-5 r of
  the sphere) with exact radial custom normals, smooth-shaded. Cycles' point primitives are exact
  spheres but a ray inside one never finds its exit (measured on ggx_glass: the refracted view of
  the light through the bottom of the sphere was black, max |z| 988 against the reference).
- World: Background colour rgb / strength, strength = the largest component (radiance = rgb); an
  environment map as an Environment Texture (the export's linear OpenEXR, Linear Rec.709) of
  strength its scale, turned by a Point Mapping node of Z rotation -rotation.
- Image textures: an Image Texture node (the export's linear OpenEXR) into the Diffuse BSDF's
  Color, on a UV map holding the mesh's per-vertex uvs: texels are RGB already (no reduction).
- Delta lights (make_light): point and spot lights of power 4 pi I (Cycles' point intensity is
  P / (4 pi), measured), radius 0; a spot's size is twice the cutoff angle and its blend
  1 - beam_width / cutoff (Cycles' smoothstep falloff: an approximation unless beam = cutoff); a
  sun of strength E, angle 0.
"""
import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path


def _bootstrap():
    sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
    import pkg_bootstrap
    pkg_bootstrap.package()


def _strength(rgb):
    s = max(float(max(rgb)), 0.0)
    return s, [float(c) / s if s > 0 else 0.0 for c in rgb]


def setup_render(sc, rgb):
    r = rgb["render"]
    sc.render.engine = "CYCLES"
    c = sc.cycles
    c.device = "CPU"
    c.samples = r["spp"]
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.sampling_pattern = "TABULATED_SOBOL"
    c.seed = 0
    c.use_animated_seed = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.light_sampling_threshold = 0.0
    c.use_guiding = False
    bounces = max(0, r["max_depth"] - 2)
    for name in ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                 "volume_bounces", "transparent_max_bounces"):
        setattr(c, name, bounces)
    c.min_light_bounces = 0
    c.min_transparent_bounces = 0
    sc.render.resolution_x, sc.render.resolution_y = r["width"], r["height"]
    sc.render.resolution_percentage = 100
    sc.render.pixel_aspect_x = sc.render.pixel_aspect_y = 1.0
    sc.render.film_transparent = False
    sc.render.use_compositing = False
    sc.render.use_sequencer = False
    sc.render.use_persistent_data = True
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    im = sc.render.image_settings
    im.file_format = "OPEN_EXR"
    im.color_depth = "32"
    im.color_mode = "RGB"
    im.exr_codec = "ZIP"


def _new_material(bpy, name):
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    return m, nt, nt.nodes.new("ShaderNodeOutputMaterial")


def _front_only(nt, out, shader_output):
    """Surface = shader on the front face, nothing (black, absorbing) on the back face."""
    geo = nt.nodes.new("ShaderNodeNewGeometry")
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(geo.outputs["Backfacing"], mix.inputs[0])
    nt.links.new(shader_output, mix.inputs[1])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])


def _linear_image(bpy, rel):
    """An export's linear OpenEXR (relative to the .blend, which is saved beside it) as a Blender
    image in Linear Rec.709."""
    img = bpy.data.images.load(str(Path(bpy.context.scene["export_dir"]) / rel), check_existing=True)
    img.filepath = "//" + rel
    img.colorspace_settings.name = "Linear Rec.709"
    return img


def make_material(bpy, name, material, emission):
    m, nt, out = _new_material(bpy, name)
    m.cycles.emission_sampling = "FRONT" if emission is not None else "NONE"
    shader = None
    if material is not None:
        kind = material["type"]
        if kind == "diffuse":
            node = nt.nodes.new("ShaderNodeBsdfDiffuse")
            node.inputs["Color"].default_value = (*material["albedo"], 1.0)
            node.inputs["Roughness"].default_value = 0.0
            if material.get("texture"):  # linear sRGB texels on the mesh's UV map (its active one)
                tex = nt.nodes.new("ShaderNodeTexImage")
                tex.image = _linear_image(bpy, material["texture"])
                tex.interpolation = "Closest" if material.get("filter") == "nearest" else "Linear"
                tex.extension = "REPEAT"
                nt.links.new(tex.outputs["Color"], node.inputs["Color"])
        else:
            rough = math.sqrt(max(material["alpha"], 0.0))
            if kind == "conductor":
                node = nt.nodes.new("ShaderNodeBsdfMetallic")
                node.fresnel_type = "PHYSICAL_CONDUCTOR"
                node.inputs["IOR"].default_value = material["eta"]
                node.inputs["Extinction"].default_value = material["k"]
            else:
                node = nt.nodes.new("ShaderNodeBsdfGlass")
                node.inputs["IOR"].default_value = material["ior"]
                node.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            node.distribution = material["distribution"].upper()
            node.inputs["Roughness"].default_value = rough
        shader = node.outputs[0]
    if emission is not None:
        strength, colour = _strength(emission)
        em = nt.nodes.new("ShaderNodeEmission")
        em.inputs["Color"].default_value = (*colour, 1.0)
        em.inputs["Strength"].default_value = strength
        if shader is not None:
            add = nt.nodes.new("ShaderNodeAddShader")
            nt.links.new(shader, add.inputs[0])
            nt.links.new(em.outputs[0], add.inputs[1])
            shader = add.outputs[0]
        else:
            shader = em.outputs[0]
    if shader is None:
        return m  # no closure: black
    if material is not None and material["type"] == "dielectric" and emission is None:
        nt.links.new(shader, out.inputs["Surface"])  # a dielectric is two-sided
    else:
        _front_only(nt, out, shader)
    return m


def make_light(bpy, sc, light):
    """A delta light as a Cycles light (conventions measured with bpy 5.0.1, docs/scene-format.md
    section 11): point and spot of power P = 4 pi I, radius 0; sun of strength E, angle 0; colour
    rgb / the largest component."""
    import mathutils
    kind = light["type"]
    rgb = light["irradiance" if kind == "directional" else "intensity"]
    strength, colour = _strength(rgb)
    data = bpy.data.lights.new(light["name"], {"point": "POINT", "spot": "SPOT", "directional": "SUN"}[kind])
    data.color = colour
    if kind == "directional":
        data.energy, data.angle = strength, 0.0
        d = mathutils.Vector(light["direction"]).normalized()
        matrix = (-d).to_track_quat("Z", "Y").to_matrix().to_4x4()  # the sun shines along its local -Z
    else:
        data.energy, data.shadow_soft_size = 4 * math.pi * strength, 0.0
        if kind == "spot":
            data.spot_size = math.radians(2 * light["cutoff_angle"])
            data.spot_blend = 1.0 - light["beam_width"] / light["cutoff_angle"]
            data.use_soft_falloff = False
            # the IR's spot points along its local +Z, Blender's along -Z
            matrix = mathutils.Matrix(light["to_world"]) @ mathutils.Matrix.Rotation(math.pi, 4, "X")
        else:
            matrix = mathutils.Matrix.Translation(light["position"])
    obj = bpy.data.objects.new(light["name"], data)
    sc.collection.objects.link(obj)
    obj.matrix_world = matrix


def build(rgb, blend_path):
    import bpy
    import mathutils
    from spectral_bench.exporters import rgb_scene
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.name = rgb["name"]
    if bpy.data.colorspace.working_space != "Linear Rec.709":  # read-only; a new file's default
        raise RuntimeError(f"scene-linear space is {bpy.data.colorspace.working_space}, not Linear Rec.709 (sRGB)")
    setup_render(sc, rgb)
    sc["export_dir"] = str(Path(blend_path).parent)
    world = bpy.data.worlds.new("environment")
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    env_map = (rgb["environment"] or {}).get("map")
    if env_map:
        # the IR's map is Blender's equirectangular convention; its rotation rho turns it about +Z,
        # which a Point mapping does by -rho (Blender looks the map up at R d)
        nt = world.node_tree
        env = nt.nodes.new("ShaderNodeTexEnvironment")
        env.image = _linear_image(bpy, env_map["file"])
        coords, mapping = nt.nodes.new("ShaderNodeTexCoord"), nt.nodes.new("ShaderNodeMapping")
        mapping.vector_type = "POINT"
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(-env_map["rotation"]))
        nt.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
        nt.links.new(env.outputs["Color"], bg.inputs["Color"])
        bg.inputs["Strength"].default_value = env_map["scale"]
    else:
        strength, colour = _strength(rgb["environment"]["rgb"]) if rgb["environment"] else (0.0, [0.0, 0.0, 0.0])
        bg.inputs["Color"].default_value = (*colour, 1.0)
        bg.inputs["Strength"].default_value = strength
    sc.world = world
    cam = rgb["camera"]
    cd = bpy.data.cameras.new("camera")
    cd.sensor_fit = "HORIZONTAL" if cam["fov_axis"] == "x" else "VERTICAL"
    cd.angle = math.radians(cam["fov"])
    cd.clip_start, cd.clip_end = 1e-3, 1e6
    co = bpy.data.objects.new("camera", cd)
    sc.collection.objects.link(co)
    co.matrix_world = mathutils.Matrix(cam["to_world"])  # rows, as the IR's
    sc.camera = co
    for obj in rgb["objects"]:
        mat = make_material(bpy, obj["name"], obj["material"], obj["emission"])
        shape = obj["shape"]
        normals = None
        if shape["type"] == "sphere":
            verts, faces, normals = rgb_scene.icosphere(shape["center"], shape["radius"], rgb_scene.SPHERE_LEVEL)
        elif shape["type"] == "rectangle":
            verts, faces = shape["corners"], [(0, 1, 2, 3)]
        else:
            verts, faces = shape["vertices"], shape["faces"]
        me = bpy.data.meshes.new(obj["name"])
        me.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
        if shape.get("uvs") is not None:  # one (u, v) per vertex: each face corner takes its vertex's
            layer = me.uv_layers.new(name="UVMap")
            for loop in me.loops:
                layer.data[loop.index].uv = shape["uvs"][loop.vertex_index]
        if normals is not None:
            me.shade_smooth()
            me.normals_split_custom_set_from_vertices([tuple(n) for n in normals])  # exact radial normals
        me.materials.append(mat)
        o = bpy.data.objects.new(obj["name"], me)
        sc.collection.objects.link(o)
    for light in rgb.get("lights", []):
        make_light(bpy, sc, light)
    sc["spectral_bench"] = json.dumps({k: rgb[k] for k in ("film_scale", "stokes", "approximated")})
    if "export_dir" in sc:
        del sc["export_dir"]  # the images are named relative to the .blend
    bpy.ops.wm.save_as_mainfile(filepath=str(blend_path), compress=True)


def render(args):
    import bpy
    import numpy as np
    from spectral_bench.batch import exr
    from spectral_bench.batch.backends import rgb_common
    t0 = time.perf_counter()
    bpy.ops.wm.open_mainfile(filepath=str(args.blend), use_scripts=False)  # a .blend runs nothing here
    sc = bpy.context.scene
    meta = json.loads(sc.get("spectral_bench", "{}"))
    per_pass = rgb_common.split_spp(args.spp, args.passes)
    sc.cycles.samples = per_pass
    settings = {k: getattr(sc.cycles, k) for k in ("pixel_filter_type", "filter_width", "sampling_pattern",
                                                   "use_adaptive_sampling", "use_denoising", "max_bounces")}
    settings["view_transform"] = sc.view_settings.view_transform
    images, render_s = [], 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.passes):
            sc.cycles.seed = args.seed + k
            sc.render.filepath = str(Path(tmp) / f"pass{k}.exr")
            t = time.perf_counter()
            bpy.ops.render.render(write_still=True)
            render_s += time.perf_counter() - t
            ch = exr.read(sc.render.filepath)
            images.append(np.stack([ch[c] for c in "RGB"], axis=-1))
    names = rgb_common.write_passes(args.out, images, meta.get("film_scale", 1.0), meta.get("stokes", False))
    result = {"variant": args.mode, "spp": per_pass * args.passes, "passes": args.passes, "seed": args.seed,
              "time_s": render_s, "wall_s": time.perf_counter() - t0,
              "resolution": [int(images[0].shape[1]), int(images[0].shape[0])], "channels": names,
              "settings": settings, "approximated": meta.get("approximated", []),
              "versions": {"blender": bpy.app.version_string, "cycles": "bpy " + bpy.app.version_string,
                           "numpy": np.__version__, "python": sys.version.split()[0]}}
    Path(args.result).write_text(json.dumps(result, indent=1))
    return result


SERVE = {"build": lambda req: build(json.loads(Path(req["scene"]).read_text()), Path(req["blend"]).resolve()),
         "render": lambda req: render(argparse.Namespace(
             blend=req["blend"], mode=req.get("mode", "rgb"), spp=int(req["spp"]), passes=int(req.get("passes", 1)),
             seed=int(req.get("seed", 0)), out=req["out"], result=req["result"]))}


def serve():
    """A warm worker (batch/backends/cycles/backend.py keeps one across jobs): bpy is imported
    once, then ``{"build": {"scene", "blend"}, "log": path}`` and ``{"render": {"blend", "mode",
    "spp", "passes", "seed", "out", "result"}, "log": path}`` requests run exactly what the
    ``build`` and ``render`` subcommands run (a build starts from factory settings and an empty
    file, a render opens its .blend: no request sees another's data); the loop, replies and logs:
    batch/backends/serve_requests.py."""
    def start():
        import bpy
        return {"blender": bpy.app.version_string}
    _bootstrap()
    from spectral_bench.batch.backends import serve_requests
    serve_requests.serve(start, SERVE)


def main(argv=None):
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("serve", help="warm worker: JSON requests on stdin (serve's docstring)")
    b = sub.add_parser("build")
    b.add_argument("--scene", required=True)
    b.add_argument("--blend", required=True)
    r = sub.add_parser("render")
    r.add_argument("--blend", required=True)
    r.add_argument("--mode", default="rgb")
    r.add_argument("--spp", type=int, required=True)
    r.add_argument("--passes", type=int, default=1)
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--out", required=True)
    r.add_argument("--result", required=True)
    args = ap.parse_args(argv)
    if args.cmd == "serve":
        return serve()
    _bootstrap()
    if args.cmd == "build":
        build(json.loads(Path(args.scene).read_text()), Path(args.blend).resolve())
    else:
        render(args)


if __name__ == "__main__":
    main()
