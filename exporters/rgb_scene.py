"""The IR scene as an RGB renderer sees it: spectra reduced by rgb_reduction's rule, geometry
in world space, and the list of what an RGB renderer cannot express (per object and field).

Shared by the Cycles and LuxCore backends, so both render the same reduced scene. The result
(``build``) is a JSON-compatible dict:
    name, render {width, height, spp, max_depth}, camera {to_world, fov, fov_axis},
    environment {rgb} | None, objects [{name, shape, material, emission}],
    lights [{name, type (point, spot, directional), intensity | irradiance (rgb), and the IR's
    position | to_world, cutoff_angle, beam_width | direction}],
    film_scale (1, or 1/2 for an approximated polariser), stokes (bool: add S0 = RGB, S1..S3 = 0),
    reduced [{object, field, rgb, note}], approximated [text]
where material is {type: diffuse, albedo} | {type: conductor, eta, k, distribution, alpha, fit}
| {type: dielectric, ior (int/ext), int_ior, ext_ior, distribution, alpha} | None (black), and
shape is {type: rectangle, corners (4 world points, counter-clockwise about the IR normal)}
| {type: sphere, center, radius} | {type: mesh, vertices (world), faces}.

What cannot be expressed (``problems``): polarisation (the camera's polariser, Stokes output),
and the phenomena with no RGB mapping here yet (fluorescence, dispersion, thin film: their IR
fields are being added; their mappings are a follow-up). A microfacet distribution the renderer
lacks, a roughness beyond its range, and max_depth 1 (only emitters visible) are reported too.
With ``approximate`` a problem that has a stated approximation is rendered that way and listed
in ``approximated``; the rest stay unsupported.
"""
import json
from pathlib import Path

import numpy as np

from . import ir, mesh_io, rgb_reduction
from . import textures as tex_mod

UNMAPPED_NEEDS = ("fluorescence", "dispersion", "thin_film")
SPHERE_LEVEL = 6  # icosphere subdivisions for the renderers without analytic spheres (both)
POLARIZER_TRANSMITTANCE = 0.5  # an ideal linear polariser passes half of unpolarised light (Malus)


def problems(scene, distributions, light_types=frozenset(), env_maps=False, textures=False):
    """[(object, field, message, approximation or None)]: what an RGB renderer with the given
    microfacet ``distributions`` and delta ``light_types`` cannot express in ``scene`` (an
    environment map unless ``env_maps``, an image texture unless ``textures``)."""
    out = []
    cam = scene["camera"]
    if cam.get("polarizer"):
        out.append((cam.get("name", "camera"), "polarizer",
                    "polarisation: an RGB renderer carries no Stokes vector",
                    f"the polariser is replaced by a neutral filter of transmittance {POLARIZER_TRANSMITTANCE} "
                    "(an ideal polariser on unpolarised light): the light's polarisation is ignored"))
    if scene["render"].get("output") == "stokes":
        out.append(("render", "output", "Stokes output: an RGB renderer carries no Stokes vector",
                    "S0 = the RGB render and S1 = S2 = S3 = 0 (all light taken as unpolarised)"))
    for need in UNMAPPED_NEEDS:
        if need in scene.get("needs", []):
            out.append(("scene", "needs", f"{need}: no RGB mapping yet (a follow-up of issue 14)", None))
    depth = scene["render"].get("max_depth", 64)
    if depth == 1:
        out.append(("render", "max_depth", "max_depth 1 (emitters seen directly, nothing lit) has no "
                    "counterpart: both renderers always sample direct light at the first hit", None))
    for light in scene.get("lights", []):
        if light["type"] not in light_types:
            out.append((light["name"], "type", f"a {light['type']} light: no mapping to this renderer's lights yet "
                        "(Mitsuba renders it)", None))
        elif light["type"] == "spot" and light["beam_width"] < light["cutoff_angle"]:
            out.append((light["name"], "beam_width", "a spot's linear falloff in angle between beam_width and "
                        "cutoff_angle has no counterpart",
                        "rendered with the renderer's own smooth falloff over the same angles"))
    if (scene.get("environment") or {}).get("type") == "map" and not env_maps:
        out.append(("environment", "type", "an environment map: not mapped to this renderer's world textures "
                    "yet (Mitsuba, pbrt-v4, Cycles and LuxCore render it)", None))
    for obj in scene["objects"]:
        if (obj.get("bsdf") or {}).get("reflectance_texture") is not None and not textures:
            out.append((obj["name"], "bsdf.reflectance_texture", "an image texture: not mapped to this renderer's "
                        "textures yet (Mitsuba, pbrt-v4, Cycles and LuxCore render it)", None))
            continue
        if (obj.get("bsdf") or {}).get("type") == "coated_diffuse":
            out.append((obj["name"], "bsdf.type", "a coated diffuse (Mitsuba 3's plastic: a closed form of the coat's "
                        "internal reflections) has no counterpart: Cycles' Principled BSDF and LuxCore's glossy2 are "
                        "other layering models", None))
            continue
        rough = (obj.get("bsdf") or {}).get("roughness")
        if rough and rough["alpha"] > 0:
            if rough["distribution"] not in distributions:
                out.append((obj["name"], "bsdf.roughness.distribution",
                            f"no {rough['distribution']} microfacet distribution (has {', '.join(sorted(distributions))})",
                            f"rendered as {sorted(distributions)[-1]} with the same alpha instead of {rough['distribution']}"))
            if rough["alpha"] > 1:
                out.append((obj["name"], "bsdf.roughness.alpha",
                            f"alpha {rough['alpha']} > 1: the renderer clamps roughness at alpha = 1", None))
    return out


def _is_constant(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) or (
        isinstance(value, dict) and value.get("type") == "constant")


def wavelength_dependent(scene):
    """[(object, field, why)]: what makes ``scene``'s light transport depend on wavelength, so that
    an RGB render of it is not exact (empty: it is exact per channel, docs/backends.md "RGB
    renderers as cross-checks"). Exact needs every BSDF wavelength-independent: a diffuse of
    constant reflectance, a conductor of constant eta and k, a dielectric of constant IORs, none
    with a thin film or fluorescence; emitters and the environment may have any spectrum (the
    image is linear in each). Anything else, an unknown BSDF type included, is named."""
    out = []
    for obj in scene.get("objects", []):
        b, name = obj.get("bsdf"), obj.get("name", "?")
        if not b:
            continue
        kind = b.get("type")
        fields = {"diffuse": ("reflectance",), "conductor": ("eta", "k"),
                  "dielectric": ("int_ior", "ext_ior")}.get(kind)
        if fields is None:
            out.append((name, "bsdf.type", f"{kind!r}: not known to be wavelength-independent"))
            continue
        for field in fields:
            value = b.get(field, ir.AIR_IOR if field == "ext_ior" else None)
            if value is None and b.get("material"):
                out.append((name, f"bsdf.{field}", f"the measured conductor {b['material']!r}"))
                break
            if not _is_constant(value):
                what = value.get("type") if isinstance(value, dict) else type(value).__name__
                out.append((name, f"bsdf.{field}", f"a {what} spectrum, not a constant"))
        for field in ("thin_film", "fluorescence"):
            if b.get(field):
                out.append((name, f"bsdf.{field}", f"a {field.replace('_', ' ')} depends on wavelength"))
    return out


def rectangle_corners(shape):
    """The IR rectangle's 4 world corners, ordered counter-clockwise about its world normal
    (the transformed local +Z, i.e. inverse-transpose: also right for a mirroring to_world)."""
    m = np.asarray(shape["to_world"], dtype=np.float64)
    corners = np.array([m @ np.array([x, y, 0.0, 1.0]) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))])[:, :3]
    normal = np.linalg.inv(m[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
    if np.cross(corners[1] - corners[0], corners[2] - corners[0]) @ normal < 0:
        corners = corners[::-1]
    return corners


def icosphere(center, radius, level):
    """(vertices, faces, normals) of a subdivided icosahedron on the sphere, outward winding,
    with exact (radial) vertex normals. Edge length about 1.1 r / 2^level: level 6 puts every
    point of the mesh within 4e-5 r of the sphere."""
    t = (1.0 + 5 ** 0.5) / 2.0
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
         [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    verts = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in v]
    for _ in range(level):
        cache, new_faces = {}, []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                p = verts[a] + verts[b]
                verts.append(p / np.linalg.norm(p))
                cache[key] = len(verts) - 1
            return cache[key]
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new_faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = new_faces
    unit = np.array(verts)
    return np.asarray(center, dtype=np.float64) + radius * unit, np.array(f, dtype=np.int64), unit


def _shape(obj, base_dir):
    s = obj["shape"]
    if s["type"] == "rectangle":
        return {"type": "rectangle", "corners": rectangle_corners(s).tolist()}
    if s["type"] == "sphere":
        return {"type": "sphere", "center": list(map(float, s["center"])), "radius": float(s["radius"])}
    verts, faces = mesh_io.load_mesh(s, base_dir)
    v = np.asarray(verts, dtype=np.float64)
    if "to_world" in s:
        m = np.asarray(s["to_world"], dtype=np.float64)
        v = (np.c_[v, np.ones(len(v))] @ m.T)[:, :3]
    out = {"type": "mesh", "vertices": v.tolist(), "faces": np.asarray(faces, dtype=np.int64).tolist()}
    if s.get("uvs") is not None:
        out["uvs"] = [list(map(float, uv)) for uv in s["uvs"]]
    return out


def _material(obj, distributions, reduced):
    b = obj.get("bsdf")
    if not b:
        return None
    name = obj["name"]
    if b["type"] == "diffuse":
        rgb, note = rgb_reduction.reflectance_rgb(b["reflectance"])
        reduced.append({"object": name, "field": "bsdf.reflectance", "rgb": rgb.round(8).tolist(), "note": note})
        return {"type": "diffuse", "albedo": rgb.tolist()}
    rough = b.get("roughness") or {"distribution": "ggx", "alpha": 0.0}
    dist = rough["distribution"] if rough["distribution"] in distributions else sorted(distributions)[-1]
    out = {"distribution": dist, "alpha": float(rough["alpha"])}
    if b["type"] == "conductor":
        eta, k, info = rgb_reduction.conductor_rgb(b)
        field = "bsdf.material" if "material" in b else "bsdf.eta, bsdf.k"
        reduced.append({"object": name, "field": field, "rgb": {"eta": eta.round(6).tolist(), "k": k.round(6).tolist()},
                        "note": info.get("note"), "fit": info})
        out.update(type="conductor", eta=eta.tolist(), k=k.tolist())
        return out
    int_ior, ext_ior = float(b["int_ior"]), float(b.get("ext_ior", ir.AIR_IOR))
    out.update(type="dielectric", ior=int_ior / ext_ior, int_ior=int_ior, ext_ior=ext_ior)
    return out


def _light(light, reduced):
    """A delta light as an RGB renderer takes it: its spectrum reduced to RGB, its geometry as is."""
    key = "irradiance" if light["type"] == "directional" else "intensity"
    rgb, note = rgb_reduction.emission_rgb(light[key])
    reduced.append({"object": light["name"], "field": key, "rgb": rgb.round(8).tolist(), "note": note})
    geometry = {k: light[k] for k in ("position", "to_world", "direction", "cutoff_angle", "beam_width") if k in light}
    return {"name": light["name"], "type": light["type"], key: rgb.tolist(), **geometry}


def build(scene, distributions, approximate=False, light_types=frozenset(), out_dir=None, env_maps=False,
          textures=False):
    """The RGB scene (see the module docstring). Raises ValueError naming object and field when
    something cannot be expressed (and, with ``approximate``, has no stated approximation). An
    environment map (``env_maps``) and image textures (``textures``) are written into ``out_dir``
    as linear OpenEXR (exporters/textures.py), named relative to it: an RGB renderer reads their
    texels as linear sRGB, with no uplift."""
    found = problems(scene, distributions, light_types, env_maps, textures)
    blocking = [p for p in found if not approximate or p[3] is None]
    if blocking:
        raise ValueError("; ".join(f"{o}.{f}: {m}" for o, f, m, _ in blocking))
    r, cam = scene["render"], scene["camera"]
    depth = r.get("max_depth", 64)
    reduced = []
    env = scene.get("environment")
    env_rgb = env_map = None
    if tex_mod.env_map(env):
        env_map = {"file": tex_mod.write_linear(env, "environment", scene.get("_base_dir"), out_dir, stem="environment"),
                   "scale": float(env.get("scale", 1.0)), "rotation": float(env.get("rotation", 0.0))}
        reduced.append({"object": "environment", "field": "file", "rgb": None,
                        "note": "an environment map: its texels are linear sRGB already (no reduction)"})
    elif env:
        rgb, note = rgb_reduction.emission_rgb(env["radiance"])
        reduced.append({"object": "environment", "field": "radiance", "rgb": rgb.round(8).tolist(), "note": note})
        env_rgb = rgb.tolist()
    objects = []
    for obj in scene["objects"]:
        emission = None
        if obj.get("emitter"):
            rgb, note = rgb_reduction.emission_rgb(obj["emitter"]["radiance"])
            reduced.append({"object": obj["name"], "field": "emitter.radiance", "rgb": rgb.round(8).tolist(), "note": note})
            emission = rgb.tolist()
        material = _material(obj, distributions, reduced)
        tex = tex_mod.textured(obj)
        if tex is not None and material is not None and material["type"] == "diffuse":
            material["texture"] = tex_mod.write_linear(tex, obj["name"], scene.get("_base_dir"), out_dir)
            material["filter"] = tex.get("filter", "bilinear")
            reduced.append({"object": obj["name"], "field": "bsdf.reflectance_texture", "rgb": None,
                            "note": "an image texture: its texels are linear sRGB already (no reduction)"})
        objects.append({"name": obj["name"], "shape": _shape(obj, scene.get("_base_dir")),
                        "material": material, "emission": emission})
    fields = {(o, f) for o, f, _, _ in found}
    return {"name": scene["name"], "case": scene.get("case"),
            "render": {"width": int(r["width"]), "height": int(r["height"]), "spp": int(r["spp"]),
                       "max_depth": 1024 if depth is None or depth < 0 else int(depth)},
            "camera": {"to_world": cam["to_world"], "fov": float(cam["fov"]), "fov_axis": cam.get("fov_axis", "x")},
            "environment": {"map": env_map} if env_map else None if env_rgb is None else {"rgb": env_rgb},
            "objects": objects,
            "lights": [_light(light, reduced) for light in scene.get("lights", [])],
            "film_scale": POLARIZER_TRANSMITTANCE if (cam.get("name", "camera"), "polarizer") in fields else 1.0,
            "stokes": ("render", "output") in fields,
            "reduced": reduced,
            "approximated": [f"{o}.{f}: {a}" for o, f, _, a in found]}


def write_reduction(rgb, out_dir):
    """reduction.json beside an export: what was reduced (with the RGB and any note) and approximated."""
    path = Path(out_dir) / "reduction.json"
    path.write_text(json.dumps({k: rgb[k] for k in ("name", "reduced", "approximated", "film_scale", "stokes")},
                               indent=1) + "\n")
    return path
