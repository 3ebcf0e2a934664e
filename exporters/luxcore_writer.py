"""LuxCoreRender SDL writer: an RGB scene (rgb_scene.build) -> folder with scene.scn (the scene),
render.cfg (the render settings; ``luxcoreconsole render.cfg`` renders it), meshes/*.ply and
reduction.json (every spectrum the rule of rgb_reduction reduced, with its RGB and notes, and
what was approximated).

Geometry is in world space (no transforms). Rectangles are two triangles wound about the IR
normal; spheres are icospheres (level 6, every point within 4e-5 r of the sphere, exact radial
vertex normals), as LuxCore has no analytic sphere.

Materials (LuxCore 2.x names, src/slg/scene/parsematerials.cpp):
- diffuse: ``matte`` (kd = albedo, or an ``imagemap`` of the export's linear texture on the mesh's
  uvs, gamma 1); conductor: ``metal2`` with RGB ``n``/``k`` and
  ``uroughness = vroughness = alpha``. LuxCore's microfacet distribution (SchlickDistribution_D in
  materialdefs_funcs_generic.cl) is r / (pi (r cos^2 + sin^2)^2) with r = u * v = alpha^2: GGX's
  D with the IR's alpha; its shadowing term is Schlick's approximation of Smith's G
  (cos / (cos (1 - r) + r) per direction), not Smith-GGX's, and it has no Beckmann
  (reported by rgb_scene). alpha 0 is LuxCore's smallest roughness (it clamps u to 1e-9).
- dielectric: ``glass`` (smooth) or ``roughglass`` (same roughness convention), with
  ``interiorior``/``exteriorior`` from the IR.
- Mitsuba's diffuse and conductor BSDFs are one-sided (black seen from behind): both are wrapped
  in ``twosided`` with a black matte back; dielectrics are two-sided in both renderers.
- Emission: ``emission = rgb`` with the default gain 1 and power 0 (Material::UpdateEmittedFactor:
  the radiance is exactly rgb) and theta 90 (TriangleLight: emits on the front side only, like
  the IR's +Z-only rectangles); an emitter without BSDF is a black matte.
- The uniform environment: ``constantinfinite`` with ``color = rgb``, gain 1 (radiance rgb); an
  environment map: ``infinite`` (``env_map_lines``).
- Delta lights: ``point`` (gain 4 pi: LuxCore's point intensity is gain x color / (4 pi)), ``spot``
  (coneangle = cutoff, conedeltaangle = cutoff - beam_width; intensity gain x color; its falloff
  is LuxCore's, an approximation unless beam = cutoff) and ``sharpdistant`` (irradiance gain x
  color): all measured on a diffuse plane against the closed form (tests/exporters/test_blender_conversion.py;
  LuxCore's point and spot read 1.0e-5 and 1.6e-5 high, its ray offsets).

Render settings (render.cfg): PATHCPU with the RANDOM sampler (independent, uniformly jittered
samples; adaptive strength 0), ``batch.haltspp`` = the scene's spp (the backend polls the session:
see batch/backends/luxcore/worker.py), pixel filter NONE (each sample lands in the pixel it was
drawn in, uniformly over that pixel: a one-pixel box; the backend's test checks it), no variance
clamping, no hybrid back/forward (light tracing) or PhotonGI caches, path depths = the IR's
max_depth (LuxCore's total depth d >= 2 allows d path segments, as Mitsuba's max_depth does:
pathtracer.cpp's IsLastPathVertex), film output RGB (raw radiance, no image pipeline).
Camera: LuxCore's perspective camera maps film row y to raster row height - y - 1
(PerspectiveCamera::InitRay), one pixel above where it belongs (measured: the horizon of a test
scene one row lower than in Mitsuba and Cycles); the screen window written here is moved down
by one pixel to render the IR's framing.
"""
import math
from pathlib import Path

import numpy as np

from . import mesh_io, names, rgb_scene



# gain per delta light type so that the IR's intensity / irradiance is gain x color in LuxCore's terms
# (measured on a diffuse plane, LuxCore 2.11: a point light's intensity is color / (4 pi), a spot's
# and a sharpdistant's color itself)
LIGHT_GAIN = {"point": 4 * math.pi, "spot": 1.0, "directional": 1.0}


def _v(x):
    return " ".join(repr(round(float(c), 9)) for c in np.ravel(x))


def camera_lines(cam, width, height):
    m = np.asarray(cam["to_world"], dtype=np.float64)
    orig, forward, up = m[:3, 3], -m[:3, 2], m[:3, 1]
    if cam.get("fov_axis", "x") == "x":
        window = [-1.0, 1.0, -height / width, height / width]
    else:
        window = [-width / height, width / height, -1.0, 1.0]
    # LuxCore maps film row y to raster height - y - 1 (PerspectiveCamera::InitRay), one pixel above
    # where it belongs: the window is moved down by one pixel so the IR's framing is rendered
    pixel = (window[3] - window[2]) / height
    window[2] -= pixel
    window[3] -= pixel
    return ['scene.camera.type = "perspective"',
            f"scene.camera.lookat.orig = {_v(orig)}",
            f"scene.camera.lookat.target = {_v(orig + forward)}",
            f"scene.camera.up = {_v(up)}",
            f"scene.camera.fieldofview = {_v(cam['fov'])}",
            f"scene.camera.screenwindow = {_v(window)}",
            "scene.camera.lensradius = 0"]


def material_lines(name, material, emission):
    """SDL lines defining material ``name`` (and its helpers)."""
    p = f"scene.materials.{name}"
    out = [f'scene.materials.{name}_black.type = "matte"', f"scene.materials.{name}_black.kd = 0 0 0"]
    if material is None:
        out += [f'{p}.type = "matte"', f"{p}.kd = 0 0 0"]
    elif material["type"] == "dielectric":
        smooth = material["alpha"] <= 0
        out += [f'{p}.type = "{"glass" if smooth else "roughglass"}"', f"{p}.kr = 1 1 1", f"{p}.kt = 1 1 1",
                f"{p}.interiorior = {_v(material['int_ior'])}", f"{p}.exteriorior = {_v(material['ext_ior'])}"]
        if not smooth:
            out += [f"{p}.uroughness = {_v(material['alpha'])}", f"{p}.vroughness = {_v(material['alpha'])}"]
    else:
        front = f"scene.materials.{name}_front"
        if material["type"] == "diffuse" and material.get("texture"):
            tex = f"scene.textures.{name}_kd"
            out += [f'{tex}.type = "imagemap"', f'{tex}.file = "{material["texture"]}"', f"{tex}.gamma = 1",
                    f'{tex}.channel = "rgb"', f'{tex}.wrap = "repeat"',
                    f'{tex}.filter = "{"nearest" if material.get("filter") == "nearest" else "linear"}"',
                    f'{tex}.mapping.type = "uvmapping2d"',
                    f'{front}.type = "matte"', f'{front}.kd = "{name}_kd"']
        elif material["type"] == "diffuse":
            out += [f'{front}.type = "matte"', f"{front}.kd = {_v(material['albedo'])}"]
        else:
            out += [f'{front}.type = "metal2"', f"{front}.n = {_v(material['eta'])}", f"{front}.k = {_v(material['k'])}",
                    f"{front}.uroughness = {_v(material['alpha'])}", f"{front}.vroughness = {_v(material['alpha'])}"]
        out += [f'{p}.type = "twosided"', f'{p}.frontmaterial = "{name}_front"', f'{p}.backmaterial = "{name}_black"']
    if emission is not None:
        out += [f"{p}.emission = {_v(emission)}", f"{p}.emission.gain = 1 1 1", f"{p}.emission.power = 0",
                f"{p}.emission.efficency = 0", f"{p}.emission.theta = 90"]
    return out


def shape_geometry(shape):
    """(vertices, faces, normals or None) in world space."""
    if shape["type"] == "rectangle":
        return np.asarray(shape["corners"]), np.array([[0, 1, 2], [0, 2, 3]]), None
    if shape["type"] == "sphere":
        return rgb_scene.icosphere(shape["center"], shape["radius"], rgb_scene.SPHERE_LEVEL)
    return np.asarray(shape["vertices"]), np.asarray(shape["faces"]), None


def _uvs(shape):
    """The mesh's per-vertex texture coordinates as LuxCore reads them (or None): its PLY loader
    takes them as s, t (not u, v: measured, those are ignored) and its imagemap reads t down, so
    the IR's v up is written as 1 - v (measured: a 2 x 2 texture upside down otherwise)."""
    uvs = shape.get("uvs")
    return None if uvs is None else [[u, 1.0 - v] for u, v in uvs]


ENV_FLIP = True   # write the map mirrored left to right (LuxCore's azimuth runs the other way)
ENV_TURN = 180.0  # then turn it about +Z by this many degrees besides the map's own rotation


def env_map_lines(env_map, out):
    """An environment map (rgb_scene: the export's linear equirectangular OpenEXR) as LuxCore's
    ``infinite`` light: gain the map's scale, gamma 1; LuxCore reads u = phi / 2 pi about +Z (the
    IR: u = 1/2 - phi / 2 pi), so the map is written mirrored and turned (measured against Cycles'
    render of Blender's world: tests/exporters/test_envmap.py)."""
    from . import textures
    src = {"file": env_map["file"], "colour_space": "linear"}
    rgb = textures.read_linear(src, out)
    if ENV_FLIP:
        rgb = rgb[:, ::-1]
    rel = "textures/environment_luxcore.exr"
    textures.write_exr(rgb, Path(out) / rel)
    a = math.radians(ENV_TURN + env_map["rotation"])
    m = np.eye(4)
    m[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    s = env_map["scale"]
    return ['scene.lights.environment.type = "infinite"', f'scene.lights.environment.file = "{rel}"',
            "scene.lights.environment.gamma = 1", f"scene.lights.environment.gain = {_v([s, s, s])}",
            f"scene.lights.environment.transformation = {_v(m.T)}",
            "scene.lights.environment.visibilitymapcache.enable = 0"]


def config_lines(rgb, seed=0):
    r = rgb["render"]
    depth = max(2, r["max_depth"])
    return ['scene.file = "scene.scn"',
            'renderengine.type = "PATHCPU"', 'sampler.type = "RANDOM"', "sampler.random.adaptive.strength = 0",
            f"renderengine.seed = {seed + 1}",  # LuxCore seeds start at 1
            f"batch.haltspp = {r['spp']}",
            f"film.width = {r['width']}", f"film.height = {r['height']}",
            'film.filter.type = "NONE"',
            f"path.pathdepth.total = {depth}", f"path.pathdepth.diffuse = {depth}",
            f"path.pathdepth.glossy = {depth}", f"path.pathdepth.specular = {depth}",
            "path.clamping.variance.maxvalue = 0", "path.hybridbackforward.enable = 0",
            "path.forceblackbackground.enable = 0",
            'film.outputs.0.type = "RGB"', 'film.outputs.0.filename = "render.exr"']


def light_lines(k, light):
    """SDL lines of a delta light (``lightK``): point, spot and sharpdistant with power 0 and
    efficacy 0 (the radiometric value is gain x color; see the module docstring)."""
    p = f"scene.lights.light{k}"
    kind = light["type"]
    rgb = light["irradiance" if kind == "directional" else "intensity"]
    out = [f"{p}.color = {_v(rgb)}", f"{p}.gain = {_v(LIGHT_GAIN[kind])} {_v(LIGHT_GAIN[kind])} {_v(LIGHT_GAIN[kind])}"]
    if kind == "directional":
        return [f'{p}.type = "sharpdistant"', f"{p}.direction = {_v(light['direction'])}"] + out
    out += [f"{p}.power = 0", f"{p}.efficency = 0"]
    if kind == "point":
        return [f'{p}.type = "point"', f"{p}.position = {_v(light['position'])}"] + out
    m = np.asarray(light["to_world"], dtype=np.float64)
    return [f'{p}.type = "spot"', f"{p}.position = {_v(m[:3, 3])}", f"{p}.target = {_v(m[:3, 3] + m[:3, 2])}",
            f"{p}.coneangle = {_v(light['cutoff_angle'])}",
            f"{p}.conedeltaangle = {_v(light['cutoff_angle'] - light['beam_width'])}"] + out


def write(rgb, out_dir):
    """Write the RGB scene ``rgb`` into ``out_dir``; returns the path of render.cfg."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lines = [f"# {names.comment_text(rgb['name'])} ({names.comment_text(rgb.get('case'))}), reduced to linear sRGB by spectral_bench (see reduction.json)"]
    lines += camera_lines(rgb["camera"], rgb["render"]["width"], rgb["render"]["height"])
    env_map = (rgb["environment"] or {}).get("map")
    if env_map:
        lines += env_map_lines(env_map, out)
    elif rgb["environment"]:
        lines += ['scene.lights.environment.type = "constantinfinite"',
                  f"scene.lights.environment.color = {_v(rgb['environment']['rgb'])}",
                  "scene.lights.environment.gain = 1 1 1",
                  "scene.lights.environment.visibilitymapcache.enable = 0"]
    for k, obj in enumerate(rgb["objects"]):
        name = f"obj{k}"
        lines.append(f"# {names.comment_text(obj['name'])}")
        lines += material_lines(name, obj["material"], obj["emission"])
        verts, faces, normals = shape_geometry(obj["shape"])
        rel = f"meshes/{name}.ply"
        mesh_io.write_ply(out / rel, verts, faces, normals=normals, uvs=_uvs(obj["shape"]), uv_names=("s", "t"))
        lines += [f'scene.shapes.{name}.type = "mesh"', f'scene.shapes.{name}.ply = "{rel}"',
                  f'scene.objects.{name}.shape = "{name}"', f'scene.objects.{name}.material = "{name}"']
    for k, light in enumerate(rgb.get("lights", [])):
        lines.append(f"# {names.comment_text(light['name'])}")
        lines += light_lines(k, light)
    (out / "scene.scn").write_text("\n".join(lines) + "\n")
    cfg = out / "render.cfg"
    cfg.write_text("\n".join(config_lines(rgb)) + "\n")
    rgb_scene.write_reduction(rgb, out)
    return cfg
