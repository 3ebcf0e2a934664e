"""Blender -> scene IR. The only module of exporters/ that imports bpy.

One Blender scene is one test scene. Exported: the scene camera, render-visible mesh objects,
Blender's lights (point, spot, sun, area of every shape) and the world. A material, light or
world with a spectral annotation is exported as annotated; one without is converted from what
Blender has (Principled BSDF and the other BSDF nodes, light power and colour, the world's
Background node) by exporters/blender_conversion.py, and every approximation or loss is a warning
(object, field, message) in the IR's ``warnings``. What makes a scene impossible to export (no
camera, an empty mesh) is an error naming object and field.
"""
import math
import os

import bpy
import numpy as np
from mathutils import Matrix

from . import blend_safety
from . import blender_conversion as conv
from . import ir, names, textures, validate


def _clean(x):
    """Blender stores float32: six decimals are all it has at unit scale; keeps goldens stable."""
    v = round(float(x), 6)
    return 0.0 if v == 0 else v


def _world(obj):
    """World matrix from the object's own transform and its parents. Computed here because a
    scene that was never evaluated (every scene but the active one) has a stale matrix_world.
    Constraints and drivers are not evaluated."""
    m = obj.matrix_basis.copy()
    if obj.parent is not None:
        m = _world(obj.parent) @ obj.matrix_parent_inverse @ m
    return m


def _matrix(m):
    return [[_clean(m[i][j]) for j in range(4)] for i in range(4)]


def spectrum(props):
    """SpectrumProps -> IR spectrum dict."""
    kind = props.kind
    if kind == "CONSTANT":
        return {"type": "constant", "value": float(props.value)}
    if kind == "SAMPLED":
        pts = sorted((s.wavelength, s.value) for s in props.samples)
        return {"type": "sampled", "wavelengths": [float(w) for w, _ in pts], "values": [float(v) for _, v in pts]}
    if kind == "NAMED":
        return {"type": "named", "name": props.named, "scale": float(props.scale)}
    return {"type": "blackbody", "temperature": float(props.temperature), "scale": float(props.scale)}


def _digits(x):
    """Blender stores float32: eight significant digits keep Sellmeier coefficients (which span
    1e-3 to 1e2) as entered."""
    return float(f"{float(x):.8g}")


def _ior(a):
    """The interior IOR: a number, or an IOR model (exporters/dispersion.py)."""
    if a.ior_model == "NAMED":
        return {"type": "named", "name": a.glass}
    if a.ior_model == "SELLMEIER":
        return {"type": "sellmeier", "B": [_digits(x) for x in a.sellmeier_b], "C": [_digits(x) for x in a.sellmeier_c]}
    if a.ior_model == "CAUCHY":
        return {"type": "cauchy", "A": _digits(a.cauchy_a), "B": _digits(a.cauchy_b), "C": _digits(a.cauchy_c)}
    return _clean(a.int_ior)


def fluorescence(a):
    """The IR ``fluorescence`` of a material's annotation (None when not fluorescent); raises
    ValueError when the matrix file cannot be read."""
    if a.fluorescence == "BANDS":
        return {"type": "bands", **{k: _clean(getattr(a, k)) for k in
                                    ("absorption_peak", "absorption_width", "emission_peak", "emission_width",
                                     "strength")}}
    if a.fluorescence == "MATRIX":
        import json
        from pathlib import Path
        path = bpy.path.abspath(a.fluorescence_matrix_file) if a.fluorescence_matrix_file else ""
        refused = blend_safety.file_problem(path) if path and os.path.lexists(path) else None
        if refused:
            raise ValueError(f"cannot read a re-radiation matrix: {refused}")
        try:
            data = json.loads(Path(path).read_text())
            return {"type": "matrix", "wavelengths": [float(w) for w in data["wavelengths"]],
                    "matrix": [[float(v) for v in row] for row in data["matrix"]]}
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"cannot read a re-radiation matrix (JSON: wavelengths, matrix) from {path!r}: {exc}")
    return None


def material_bsdf(mat):
    a = mat.spectral_bench
    if a.kind == "DIFFUSE":
        out = {"type": "diffuse", "reflectance": spectrum(a.reflectance)}
        try:
            fl = fluorescence(a)
        except ValueError:
            fl = None  # reported by _mesh_object (and the material panel) with its field
        if fl is not None:
            out["fluorescence"] = fl
        return out
    out = {}
    if a.kind == "CONDUCTOR":
        out = {"type": "conductor"}
        if a.conductor_named:
            out["material"] = a.conductor
        else:
            out["eta"], out["k"] = spectrum(a.eta), spectrum(a.k)
        if a.thin_film:
            out["thin_film"] = {"ior": _clean(a.film_ior), "thickness": _clean(a.film_thickness),
                                "ext_ior": _clean(a.film_ext_ior)}
    elif a.kind == "DIELECTRIC":
        out = {"type": "dielectric", "int_ior": _ior(a), "ext_ior": _clean(a.ext_ior)}
    elif a.kind == "COATED":
        # the coat takes one IOR (the IR's coated_diffuse has no dispersion model): int_ior itself
        out = {"type": "coated_diffuse", "reflectance": spectrum(a.reflectance), "int_ior": _clean(a.int_ior),
               "ext_ior": _clean(a.ext_ior)}
    if a.distribution != "SMOOTH":
        out["roughness"] = {"distribution": a.distribution.lower(), "alpha": _clean(a.alpha)}
    return out


def _mesh_object(obj, depsgraph, problems, warnings, used=None):
    name = obj.name
    mat = obj.active_material
    emitter = None
    if mat is None:
        bsdf = {"type": "diffuse", "reflectance": {"type": "constant", "value": 0.8}}
        warnings.append((name, "material", "mesh object has no material: rendered as Blender renders it, a "
                         "diffuse reflectance 0.8 (Blender's default surface)"))
    elif mat.spectral_bench.kind == "NONE":
        n_problems = len(problems)
        bsdf, emitter = _converted_material(obj, mat, warnings, problems)
        if len(problems) > n_problems:
            return None
    else:
        bsdf = _completed(obj, mat, material_bsdf(mat), warnings)
        emitter = _annotated_emission(obj, mat, warnings)
    if len({s.material for s in obj.material_slots if s.material is not None}) > 1:
        warnings.append((name, "material_slots", f"{len(obj.material_slots)} material slots: the IR has one "
                         f"material per object; the active one ({mat.name if mat else None}) is used for every face"))
    if mat is not None and mat.spectral_bench.kind == "DIFFUSE":
        try:
            fluorescence(mat.spectral_bench)
        except ValueError as exc:
            problems.append((name, f"material[{mat.name}].spectral_bench.fluorescence_matrix_file", str(exc)))
            return None
    kind = obj.spectral_bench.shape
    mw = _world(obj)
    if (bsdf or {}).get("reflectance_texture") is not None and (kind in ("RECTANGLE", "SPHERE")
                                                                 or not obj.data.uv_layers):
        why = f"an analytic {kind.lower()}" if kind in ("RECTANGLE", "SPHERE") else "a mesh without a UV map"
        warnings.append((name, "data.uv_layers", f"the image texture needs texture coordinates and this is {why}: "
                         "the texture's mean colour is used"))
        bsdf = {k: v for k, v in bsdf.items() if k != "reflectance_texture"}
    if kind == "RECTANGLE":
        m3 = mw.to_3x3()
        if m3.col[0].cross(m3.col[1]).length == 0:
            warnings.append((name, "scale", f"{_scale_text(mw)}: the rectangle has zero area in the world (Blender "
                             "renders nothing of it): not exported"))
            return None
        shape = {"type": "rectangle", "to_world": _matrix(_flat_frame(mw, name, "scale", warnings))}
    elif kind == "SPHERE":
        loc, _rot, scale = mw.decompose()
        if max(abs(s) for s in scale) == 0:
            warnings.append((name, "scale", f"{_scale_text(mw)}: a sphere of radius 0 (Blender renders nothing of "
                             "it): not exported"))
            return None
        if max(scale) - min(scale) > 1e-6 * max(scale):
            problems.append((name, "scale", f"an analytic sphere needs a uniform scale, got {tuple(scale)}"))
            return None
        shape = {"type": "sphere", "center": [_clean(c) for c in loc], "radius": _clean(scale[0])}
    else:
        # modifiers are applied when the scene has been evaluated, the base mesh is used otherwise
        refused = _mesh_size_problem(obj, depsgraph, used=used)
        if refused:
            problems.append((name, *refused))
            return None
        source = obj.evaluated_get(depsgraph) if depsgraph is not None else obj
        mesh = source.to_mesh()
        try:
            refused = _mesh_size_problem(obj, depsgraph, mesh, used)
            if refused:
                problems.append((name, *refused))
                return None
            mesh.calc_loop_triangles()
            verts = [[_clean(c) for c in v.co] for v in mesh.vertices]
            faces = [list(t.vertices) for t in mesh.loop_triangles]
            uvs = None
            if (bsdf or {}).get("reflectance_texture") is not None and faces:
                verts, faces, uvs = _split_by_uv(mesh, verts, faces)
        finally:
            source.to_mesh_clear()
        if not faces:
            problems.append((name, "data", "mesh has no faces (missing mesh)"))
        elif any(p.use_smooth for p in obj.data.polygons):
            warnings.append((name, "data.polygons.use_smooth", "smooth shading: the IR's mesh faces are flat (no "
                             "interpolated normals): rendered faceted"))
        shape = {"type": "mesh", "to_world": _matrix(mw), "vertices": verts, "faces": faces}
        if uvs is not None:
            shape["uvs"] = uvs
        if faces:
            shape = _mesh_in_world(name, shape, mw, warnings)
            if shape is None:
                return None
    return {"name": name, "shape": shape, "bsdf": bsdf, "emitter": emitter}


def _split_by_uv(mesh, verts, faces):
    """(vertices, faces, uvs) with one (u, v) per vertex from the active UV map: a vertex whose
    face corners carry different texture coordinates (a seam) is split into one vertex per pair."""
    uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    mesh.uv_layers.active.data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    loops = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
    mesh.loop_triangles.foreach_get("loops", loops)
    corner_v = np.asarray(faces, dtype=np.int64).reshape(-1)
    corner_uv = uv[loops]
    key = np.concatenate([corner_v[:, None].astype(np.float64), corner_uv.astype(np.float64)], axis=1)
    unique, inverse = np.unique(key, axis=0, return_inverse=True)
    v = np.asarray(verts, dtype=np.float64)[unique[:, 0].astype(np.int64)]
    return (v.tolist(), inverse.reshape(-1, 3).tolist(),
            [[_clean(a), _clean(b)] for a, b in unique[:, 1:].astype(np.float32).tolist()])


def _scale_text(mw):
    """The world scale of a matrix, for a message: "scale (0, 0, 0)"."""
    return f"scale {conv.fmt(tuple(mw.to_3x3().col[i].length for i in range(3)))}"


def _invertible(m):
    """Whether the IR takes ``m`` (a to_world, nested lists) as a frame (exporters/validate.py)."""
    return validate.transform_problem(m) is None


def _mesh_in_world(name, shape, mw, warnings):
    """A mesh as Blender renders it: its faces of zero area in the world (a degenerate face, or every
    face of an object scaled to 0) dropped, exactly (they show nothing); None, warned, when no face
    is left. A transform that flattens space (a scale of 0 along one axis) cannot be the IR's
    to_world (writers and probes invert it): the vertices are then given in world space, exactly."""
    m = np.asarray(shape["to_world"], dtype=np.float64)
    v = np.asarray(shape["vertices"], dtype=np.float64) @ m[:3, :3].T + m[:3, 3]
    f = np.asarray(shape["faces"], dtype=np.int64)
    areas = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    finite = bool(np.isfinite(areas).all())  # else validation names the coordinates that are not
    if finite and not areas.any():
        singular = not _invertible(shape["to_world"])
        warnings.append((name, "scale" if singular else "data", (f"{_scale_text(mw)}: " if singular else "")
                         + f"every face ({len(f)}) has zero area in the world (Blender renders nothing of it): not "
                         "exported"))
        return None
    keep = areas > 0 if finite else np.ones(len(f), dtype=bool)  # exactly 0 only: a fine detail of a big mesh stays
    out = dict(shape, faces=f[keep].tolist()) if not keep.all() else dict(shape)
    if not _invertible(shape["to_world"]) and finite:
        out["vertices"] = [[_clean(c) for c in p] for p in v]
        out["to_world"] = _matrix(Matrix.Identity(4))
        warnings.append((name, "scale", f"{_scale_text(mw)} flattens the object (the IR's transform must be "
                         "invertible): its vertices are exported in world space, the same geometry"))
    return out


def _flat_frame(m, name, field, warnings):
    """``m`` (a Matrix) for a flat shape (a rectangle, a disk in its z = 0 plane): when its z axis is
    lost (scaled to 0) while x and y span the shape, z becomes their unit normal, warned (Blender's
    flat shape has the same extent; the IR's to_world must be invertible)."""
    if _invertible(_matrix(m)):
        return m
    x, y, z = (m.to_3x3().col[i] for i in range(3))
    n = x.cross(y)
    if n.length == 0:
        return m  # refused by validation, naming the field
    n.normalize()
    if z.dot(n) < 0:
        n = -n
    out = m.copy()
    for i in range(3):
        out[i][2] = n[i]
    warnings.append((name, field, f"{_scale_text(m)}: the flat shape's z axis is scaled to 0: taken as its unit "
                     "normal (the shape's extent is unchanged)"))
    return out


def _mesh_size_problem(obj, depsgraph, mesh=None, used=None):
    """(field, message) when a mesh object is above the caps of exporters/blend_safety.py, else
    None: before evaluation its size predicted from its base mesh and subdivision levels (a level-9
    subdivision of a cube is 3 million triangles), after it (``mesh``) the evaluated counts, both
    before any of its data is read. ``used`` ({"triangles": n, "vertices": n}) holds what the
    scene's meshes read so far: the scene's total is capped too, and an evaluated mesh that passes
    is added to it."""
    cap_v, cap_t = blend_safety.MAX_MESH_VERTICES, blend_safety.MAX_MESH_TRIANGLES
    if mesh is None:
        base = obj.data
        counts = (len(base.vertices), len(base.polygons), len(base.loops))
        render = depsgraph is not None and depsgraph.mode == "RENDER"
        mods = obj.modifiers if depsgraph is not None else ()
        verts, tris, fields = blend_safety.subdivided(counts, mods, render)
        field = fields[-1] if fields else "data"
        what = (f"predicted from its base mesh ({counts[1]} faces) and {', '.join(fields)}, before evaluating it"
                if fields else "its base mesh")
    else:
        verts, tris = len(mesh.vertices), len(mesh.loops) - 2 * len(mesh.polygons)
        field, what = "modifiers" if depsgraph is not None and len(obj.modifiers) else "data", (
            "evaluated (modifiers applied), before reading it")
    for count, cap, noun, cap_name in ((tris, cap_t, "triangles", "MAX_MESH_TRIANGLES"),
                                       (verts, cap_v, "vertices", "MAX_MESH_VERTICES")):
        if count > cap:
            return field, (f"the mesh has {count} {noun} ({what}), above the cap of {cap} ({cap_name}, "
                           f"exporters/blend_safety.py): not exported")
    if used is None:
        return None
    for count, key, cap, cap_name in ((tris, "triangles", blend_safety.MAX_SCENE_TRIANGLES, "MAX_SCENE_TRIANGLES"),
                                      (verts, "vertices", blend_safety.MAX_SCENE_VERTICES, "MAX_SCENE_VERTICES")):
        if used[key] + count > cap:
            return field, (f"the mesh has {count} {key} ({what}): with the {used[key]} of the scene's meshes read "
                           f"before it, {used[key] + count}, above the scene's cap of {cap} ({cap_name}, "
                           "exporters/blend_safety.py): not exported")
    if mesh is not None:
        used["triangles"] += tris
        used["vertices"] += verts
    return None


def _value(v):
    if hasattr(v, "__len__") and not isinstance(v, str):
        return tuple(float(x) for x in v)
    return float(v) if isinstance(v, (int, float, bool)) else v


def _node_inputs(node, warn, problems=None):
    """conv.Inputs of a node: each input's unlinked value and the type of a node linked into it,
    and for an input linked from an Image Texture node, the IR texture it converts to
    (``_image_texture``; what cannot be read a problem in ``problems``)."""
    values = {i.name: (_value(i.default_value), i.links[0].from_node.bl_idname if i.is_linked else None)
              for i in node.inputs if hasattr(i, "default_value")}
    images = {}
    for i in node.inputs:
        src = i.links[0].from_node if i.is_linked else None
        if src is not None and src.bl_idname == "ShaderNodeTexImage" and i.name in conv.TEXTURED_INPUTS:
            tex = _image_texture(src, f"inputs[{i.name}]", warn, problems)
            if tex is not None:
                images[i.name] = tex
    return conv.Inputs(values, warn, images)


# Blender colour spaces whose values are linear Rec.709 / sRGB primaries, or sRGB-encoded
LINEAR_SPACES = ("Non-Color", "Linear Rec.709", "Linear", "Raw", "Linear Rec.709 (sRGB)")
SRGB_SPACES = ("sRGB",)


def _image_file(img, base, what):
    """({"file": relative to ``base``, "colour_space"}, None) of a Blender image read from a file
    in the .blend's folder ``base`` or below, checked by exporters/textures.py before a pixel is
    read; or (None, why not)."""
    path = os.path.normpath(bpy.path.abspath(img.filepath, library=img.library))
    if os.path.lexists(path):  # what it is first (a FIFO, a device: never opened), then where
        refused = blend_safety.file_problem(path)
        if refused:
            return None, refused
    if os.path.commonpath([os.path.realpath(path), os.path.realpath(base)]) != os.path.realpath(base):
        return None, (f"{path!r} is outside the .blend's folder {base!r}: a {what} is read from that folder or below "
                      "(copy it there)")
    space = img.colorspace_settings.name
    if space not in LINEAR_SPACES + SRGB_SPACES:
        return None, f"colour space {space!r}: a {what} is sRGB or linear Rec.709 (Non-Color) here"
    found = {"file": os.path.relpath(path, base).replace(os.sep, "/"),
             "colour_space": "srgb" if space in SRGB_SPACES else "linear"}
    _path, why = textures.resolve(found, base)
    return (None, why) if why else (found, None)


def _image_texture(node, field, warn, problems):
    """The IR texture of an Image Texture node feeding ``field`` (exporters/textures.py): its file
    relative to the .blend's folder (outside it, missing, a FIFO, too large: a problem naming the
    node), its colour space and filter, and its mean linear colour (``mean``, for the BSDF's
    reflectance); what Blender does beyond it is warned. None when it is not converted (a problem
    or a warning says why)."""
    where = f"{field} <- nodes[{node.name}]"
    img = node.image
    if img is None:
        warn(field, f"linked to the Image Texture node {node.name!r} without an image (Blender renders it magenta): "
                    "not converted, the socket's unlinked value is used")
        return None
    base = os.path.dirname(bpy.data.filepath) if bpy.data.filepath else None

    def refuse(message):
        if problems is not None:
            problems.append((f"nodes[{node.name}].image", f"image {img.name!r}: {message}"))
        else:
            warn(where, f"image {img.name!r}: {message}: not converted")
        return None
    if img.packed_file is not None or img.source != "FILE" or not img.filepath:
        return refuse(f"source {img.source}{', packed' if img.packed_file is not None else ''}: a texture is read from "
                      "an image file beside the .blend (unpack it: File > External Data > Unpack Resources)")
    if base is None:
        return refuse("the .blend is not saved: its texture paths have no folder to be relative to")
    found, why = _image_file(img, base, "texture")
    if why:
        return refuse(why)
    tex = dict(found, filter="nearest" if node.interpolation == "Closest" else "bilinear")
    try:
        mean = textures.mean_rgb(tex, base)
    except Exception as exc:  # noqa: BLE001 - an unreadable image fails this scene, named
        return refuse(f"cannot be read: {type(exc).__name__}: {exc}")
    for setting, value, default, what in (
            ("projection", node.projection, "FLAT", "its flat UV projection"),
            ("extension", node.extension, "REPEAT", "repeat outside [0, 1]"),
            ("interpolation", node.interpolation, None, "bilinear filtering")):
        if default is not None and value != default:
            warn(f"{where}.{setting}", f"{setting} {value}: the IR's texture has {what}")
    if node.interpolation not in ("Linear", "Closest"):
        warn(f"{where}.interpolation", f"interpolation {node.interpolation}: filtered bilinearly")
    if node.inputs["Vector"].is_linked and node.inputs["Vector"].links[0].from_node.bl_idname != "ShaderNodeUVMap":
        warn(f"{where}.inputs[Vector]", f"linked to a {node.inputs['Vector'].links[0].from_node.bl_idname} node: the "
                                        "mesh's active UV map is used instead")
    return dict(tex, _base_dir=base, _mean=[float(c) for c in mean], _image=img.name)


def _surface(tree, socket="Surface"):
    """The node linked into the active output's ``socket`` (None when there is none)."""
    if tree is None:
        return None
    out = tree.get_output_node("CYCLES") if hasattr(tree, "get_output_node") else None
    if out is None or socket not in out.inputs or not out.inputs[socket].is_linked:
        return None
    return out.inputs[socket].links[0].from_node


def _converted_material(obj, mat, warnings, problems=None):
    """(bsdf, emitter) of a material without a spectral annotation, from its shader nodes; what
    cannot be read (an image texture's file) a problem in ``problems``."""
    where = f"material[{mat.name}]"

    def warn(field, message):
        warnings.append((obj.name, f"{where}.{field}", message))
    node = _surface(mat.node_tree)
    convert = conv.SURFACE_NODES.get(node.bl_idname) if node is not None else None
    if convert is None:
        what = f"the {node.bl_idname} node {node.name!r}" if node is not None else "no shader node at the Surface"
        warn("node_tree" if node is not None else "surface",
             f"{what} has no IR conversion (textures, mixes and other shaders are not converted): substituted a "
             f"diffuse of the material's viewport colour")
        return {"type": "diffuse", "reflectance": conv.colour_reflectance(
            mat.diffuse_color[:3], "diffuse_color", warn)}, None

    def node_warn(field, message):
        warn(f"node_tree.nodes[{node.name}].{field}", message)
    node_problems = [] if problems is not None else None
    out = convert(_node_inputs(node, node_warn, node_problems), getattr(node, "distribution", None))
    for field, message in node_problems or []:
        problems.append((obj.name, f"{where}.node_tree.{field}", message))
    return out


SPECTRUM_FIELDS = ("kind", "value", "named", "scale", "temperature", "samples")


def spectrum_set(props):
    """Whether any field of a spectrum annotation was ever set (else it holds the defaults)."""
    return any(props.is_property_set(k) for k in SPECTRUM_FIELDS)


def _completed(obj, mat, bsdf, warnings):
    """An annotated material whose Model was set but not its data (a diffuse without a reflectance
    spectrum, a named conductor never chosen) takes that data from Blender's own material (a
    warning), instead of the annotation's defaults (0.5 grey, Cu)."""
    a = mat.spectral_bench
    if a.kind in ("DIFFUSE", "COATED") and not spectrum_set(a.reflectance):
        where = f"material[{mat.name}].spectral_bench.reflectance"
        converted, _ = _converted_material(obj, mat, [])
        colour, source = _base_colour(mat)
        own = {"DIFFUSE": "diffuse", "COATED": "coated_diffuse"}[a.kind]
        spec = converted["reflectance"] if converted["type"] in ("diffuse", "coated_diffuse") \
            else conv.reflectance(colour)[0]
        model = "Diffuse" if a.kind == "DIFFUSE" else "Coated Diffuse"
        warnings.append((obj.name, where, f"Model {model} without a reflectance spectrum: Blender's {source} "
                         f"{conv.fmt(colour)} is used ({spec['type']} reflectance; {conv.UPLIFT_METHOD} where not "
                         "grey), not the default 0.5"
                         + ("" if converted["type"] == own else f"; Blender's material would convert to a "
                            f"{converted['type']}: the Model wins")))
        bsdf = dict(bsdf, reflectance=spec)
    if a.kind == "CONDUCTOR" and a.conductor_named and not a.is_property_set("conductor"):
        converted, _ = _converted_material(obj, mat, [])
        if converted["type"] == "conductor":
            bsdf = {**{k: v for k, v in bsdf.items() if k != "material"},
                    **{k: v for k, v in converted.items() if k in ("material", "eta", "k")}}
            what = converted.get("material") or "eta and k fitted to the base colour"
            warnings.append((obj.name, f"material[{mat.name}].spectral_bench.conductor", "Model Conductor without a "
                             f"chosen conductor: Blender's metallic base colour gives {what} (not the default Cu)"))
        else:
            warnings.append((obj.name, f"material[{mat.name}].spectral_bench.conductor", "Model Conductor without a "
                             f"chosen conductor and Blender's material is not metallic (it converts to a "
                             f"{converted['type']}): the default {a.conductor} is used"))
    return bsdf


def _annotated_emission(obj, mat, warnings):
    """The emission of an annotated material's Principled BSDF or Emission node (the annotation
    describes the surface only): an area emitter, warned; None when it emits nothing."""
    node = _surface(mat.node_tree)
    key = {"ShaderNodeBsdfPrincipled": "Emission Strength", "ShaderNodeEmission": "Strength"}.get(
        node.bl_idname if node is not None else None)
    if key is None or float(node.inputs[key].default_value) <= 0:
        return None

    def node_warn(field, message):
        warnings.append((obj.name, f"material[{mat.name}].node_tree.nodes[{node.name}].{field}",
                         message + " (beside the annotated surface)"))
    inp = _node_inputs(node, node_warn)
    colour_key = "Emission Color" if key == "Emission Strength" else "Color"
    return conv.surface_emission(inp, colour_key, key, node_warn)


def _base_colour(mat):
    """(linear sRGB, where it came from) of a material's colour: its Surface node's Base Color or
    Color (unlinked value), else the viewport colour."""
    node = _surface(mat.node_tree)
    for key in ("Base Color", "Color"):
        if node is not None and key in node.inputs and hasattr(node.inputs[key], "default_value"):
            return tuple(node.inputs[key].default_value[:3]), f"{node.name} {key}"
    return tuple(mat.diffuse_color[:3]), "viewport colour"


def light_annotated(light):
    """Whether a light has a spectral annotation: any field of its radiance (or collimated) was
    ever set; a light never annotated is converted from its power and colour."""
    return spectrum_set(light.spectral_bench.radiance) or light.spectral_bench.is_property_set("collimated")


def _light_spectrum(obj, factor, quantity, warnings):
    """IR spectrum of an unannotated light: its colour (or blackbody temperature) times ``factor``,
    the light's radiometric ``quantity`` for white."""
    light = obj.data
    warn = lambda field, message: warnings.append((obj.name, field, message))  # noqa: E731
    colour = np.asarray(light.color[:3], dtype=np.float64)
    temperature, field = None, None
    if getattr(light, "use_temperature", False):
        temperature, field = float(light.temperature), "data.temperature"
    node = _surface(light.node_tree) if getattr(light, "use_nodes", False) else None
    if node is not None:
        if node.bl_idname != "ShaderNodeEmission":
            warn("data.node_tree", f"a {node.bl_idname} node at the light's output is not converted: ignored")
        else:
            strength = node.inputs["Strength"]
            if strength.is_linked:
                warn("data.node_tree.Strength", "linked: its unlinked value is used")
            factor *= float(strength.default_value)
            col = node.inputs["Color"]
            src = col.links[0].from_node if col.is_linked else None
            if src is not None and src.bl_idname == "ShaderNodeBlackbody" and not src.inputs[0].is_linked:
                field = f"data.node_tree.nodes[{src.name}].Temperature"
                temperature = _node_temperature(float(src.inputs[0].default_value), field, warn)
            elif src is not None:
                warn("data.node_tree.Color", f"linked to a {src.bl_idname} node: not converted, its unlinked value used")
                colour = colour * np.asarray(col.default_value[:3])
            else:
                colour = colour * np.asarray(col.default_value[:3])
    if temperature is not None and np.abs(colour - 1).max() < 1e-6:
        warn(field, f"blackbody {temperature:g} K kept exact (a blackbody spectrum), scaled to {quantity} "
                    "(Cycles' blackbody colour has luminance 1)")
        return conv.blackbody(temperature, factor)
    if temperature is not None:
        spec, note = conv.tinted_blackbody(temperature, colour, factor)
        warn(field, f"blackbody {temperature:g} K with the colour {conv.fmt(colour)}, {quantity}: the blackbody "
                    f"times the colour's smooth uplift (no longer a pure blackbody), {note}")
        return spec
    spec = conv.emission(colour, factor)
    warn("data.color", f"colour {conv.fmt(colour)} x {quantity} -> {conv.emission_note(spec)}")
    return spec


def _light_object(obj, problems, warnings):
    """(object or None, light or None) of a Blender light: an area light is an emitting shape
    (``objects``), point, spot and sun are the IR's delta ``lights``."""
    light = obj.data
    annotated = light_annotated(light)
    world = _world(obj)
    warn = lambda field, message: warnings.append((obj.name, field, message))  # noqa: E731
    power = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
    if getattr(light, "exposure", 0.0):
        warn("data.exposure", f"exposure {light.exposure:g}: power (a sun's strength) x 2^exposure = {power:.6g}")
    if not annotated and not math.isfinite(power):
        problems.append((obj.name, "data.energy", f"power {power!r} (energy x 2^exposure) is not a finite number"))
        return None, None
    if not annotated and power < 0:
        warn("data.energy", f"negative power {power:.6g}: Blender subtracts light, the IR's emission is >= 0: not "
             "exported (emits nothing)")
        return None, None
    if light.type == "AREA":
        return _area_light(obj, light, world, power, annotated, problems, warn, warnings), None
    if annotated and light.spectral_bench.collimated:
        problems.append((obj.name, "spectral_bench.collimated", f"a collimated beam needs a square or rectangle "
                         f"area light, got a {light.type} light"))
        return None, None
    loc, rot, _scale = world.decompose()
    if light.type != "SUN" and light.shadow_soft_size > 0:
        warn("data.shadow_soft_size", f"radius {light.shadow_soft_size:g}: the IR's {light.type.lower()} light is a "
             "point (irradiance beyond the radius unchanged; soft shadows and highlight size lost)")
    if light.type == "SUN":
        if light.angle > 0:
            warn("data.angle", f"angular diameter {math.degrees(light.angle):.4g} deg: the IR's directional light is "
                 "a delta (sharp shadows)")
        direction = [_clean(-c) for c in rot.to_matrix().col[2]]  # Blender's sun shines along local -Z
        e = conv.sun_irradiance(power)
        spec = spectrum(light.spectral_bench.radiance) if annotated else _light_spectrum(
            obj, e, f"irradiance E = strength = {e:.6g} W/m^2", warnings)
        return None, {"type": "directional", "direction": direction, "irradiance": spec}
    intensity = conv.point_intensity(power)
    spec = spectrum(light.spectral_bench.radiance) if annotated else _light_spectrum(
        obj, intensity, f"intensity I = P / (4 pi) = {intensity:.6g} W/sr", warnings)
    if light.type == "POINT":
        return None, {"type": "point", "position": [_clean(c) for c in loc], "intensity": spec}
    cutoff, beam = conv.spot_cone(light.spot_size, light.spot_blend)
    if not cutoff > 0:
        warn("data.spot_size", f"spot size {light.spot_size:g}: a cone of zero angle emits nothing: not exported")
        return None, None
    if light.spot_blend > 0:
        warn("data.spot_blend", f"blend {light.spot_blend:g}: Blender's smooth falloff over the cone's outer part "
             f"becomes the IR's linear falloff in angle from {beam:.4g} to {cutoff:.4g} deg")
    if getattr(light, "use_square", False):
        warn("data.use_square", "a square spot cone: the IR's spot is round")
    # Blender's spot points along local -Z, the IR's along +Z: turn it over; no scale
    to_world = Matrix.LocRotScale(loc, rot, None) @ Matrix.Rotation(math.pi, 4, "X")
    return None, {"type": "spot", "to_world": _matrix(to_world), "intensity": spec,
                  "cutoff_angle": _clean(cutoff), "beam_width": _clean(beam)}


def _area_light(obj, light, world, power, annotated, problems, warn, warnings):
    sx = light.size / 2
    sy = (light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size) / 2
    # Blender area lights emit along local -Z; the IR's shapes emit along +Z: turn it over
    # (180 degrees about X), then size it.
    flip = Matrix.Rotation(math.pi, 4, "X")
    m3 = world.to_3x3()
    area = (m3.col[0].cross(m3.col[1])).length * 4 * sx * sy  # the world-space area of the 2 sx x 2 sy light
    if not area > 0:
        field = "data.size" if sx <= 0 else "data.size_y" if sy <= 0 else "scale"
        what = {"data.size": f"size {light.size:g}", "data.size_y": f"size_y {light.size_y:g}"}.get(field) or \
            _scale_text(world)
        warn(field, f"{what}: an area light of zero area emits nothing (in Blender too): not exported")
        return None
    world = _flat_frame(world, obj.name, "scale", warnings)
    if light.shape in ("SQUARE", "RECTANGLE"):
        shape = {"type": "rectangle", "to_world": _matrix(world @ Matrix.Diagonal((sx, sy, 1.0, 1.0)) @ flip)}
    else:
        area *= math.pi / 4
        verts, faces = conv.ellipse_polygon(sx, sy)
        shape = {"type": "mesh", "to_world": _matrix(world @ flip), "vertices": [[_clean(c) for c in v] for v in verts],
                 "faces": faces}
        warn("data.shape", f"{light.shape.lower()} area light -> a mesh of {conv.DISK_SEGMENTS} triangles of the "
             "ellipse's exact area")
    if annotated:
        emitter = {"type": "area", "radiance": spectrum(light.spectral_bench.radiance)}
        if light.spectral_bench.collimated:
            if shape["type"] != "rectangle":
                problems.append((obj.name, "spectral_bench.collimated", "a collimated beam needs a square or "
                                 f"rectangle area light, got {light.shape}"))
            emitter = {"type": "collimated", "irradiance": spectrum(light.spectral_bench.radiance)}
    else:
        normalize = getattr(light, "normalize", True)
        radiance = conv.area_radiance(power, area, normalize)
        if not obj.visible_camera:
            warn("visible_camera", "Blender's light is invisible to the camera (Cycles, the default); the IR's area "
                 "emitter is seen directly wherever the camera sees it")
        if getattr(light, "spread", math.pi) < math.pi - 1e-6:
            warn("data.spread", f"spread {math.degrees(light.spread):.4g} deg: the IR's area emitter is Lambertian "
                 "(180 deg): light outside the spread is added")
        formula = f"radiance L = P / (pi A) = {power:.6g} / (pi {area:.6g})" if normalize else \
            f"radiance L = P / pi = {power:.6g} / pi (Normalize off: not divided by the area)"
        emitter = {"type": "area", "radiance": _light_spectrum(obj, radiance, f"{formula} = {radiance:.6g}", warnings)}
    return {"name": obj.name, "shape": shape, "bsdf": None, "emitter": emitter}


def _node_temperature(t, field, warn):
    """A Blackbody node's temperature as Cycles renders it: below 800 K (0, negative) its colour is
    that of 800 K (Cycles' lower limit), warned."""
    if math.isfinite(t) and t >= BLACKBODY_MIN_K:
        return t
    warn(field, f"temperature {t:g} K: Cycles' Blackbody node gives the colour of {BLACKBODY_MIN_K:g} K below "
                f"{BLACKBODY_MIN_K:g} K: {BLACKBODY_MIN_K:g} K used")
    return BLACKBODY_MIN_K


BLACKBODY_MIN_K = 800.0  # Cycles' Blackbody node (and a light's temperature, whose minimum it is)


def _converted_world(world, warnings, problems=None):
    """The IR environment of a world without an annotation: its Background node's colour x strength
    as a uniform environment; anything else a warning naming the world and field; what cannot be
    converted (an environment map whose image has no pixels) a problem in ``problems``."""
    name = f"world[{world.name}]"
    warn = lambda field, message: warnings.append((name, field, message))  # noqa: E731
    if _surface(world.node_tree, "Volume") is not None:
        warn("node_tree.Volume", "a world volume is not converted: ignored")
    node = _surface(world.node_tree) if getattr(world, "use_nodes", True) else None
    if node is None:
        colour, strength = np.asarray(world.color[:3], dtype=np.float64), 1.0
        field = "color"
    elif node.bl_idname != "ShaderNodeBackground":
        warn("node_tree", f"a {node.bl_idname} node at the world's Surface is not converted: no environment")
        return None
    else:
        field = f"node_tree.nodes[{node.name}].Color"
        strength = float(node.inputs["Strength"].default_value)
        if node.inputs["Strength"].is_linked:
            warn(f"node_tree.nodes[{node.name}].Strength", "linked: its unlinked value is used")
        colour = np.asarray(node.inputs["Color"].default_value[:3], dtype=np.float64)
        src = node.inputs["Color"].links[0].from_node if node.inputs["Color"].is_linked else None
        if src is not None and src.bl_idname == "ShaderNodeBlackbody" and not src.inputs[0].is_linked:
            t = _node_temperature(float(src.inputs[0].default_value), field, warn)
            warn(field, f"blackbody {t:g} K kept exact, luminance = strength {strength:g} (Cycles' normalisation)")
            return {"type": "uniform", "radiance": conv.blackbody(t, strength)}
        if src is not None and src.bl_idname == "ShaderNodeTexEnvironment" and src.image is not None \
                and src.image.source == "FILE" and src.image.packed_file is None and bpy.data.filepath:
            return _environment_map(src, strength, field, name, warn, problems)
        if src is not None and src.bl_idname == "ShaderNodeTexEnvironment" and src.image is not None:
            refused = _image_problem(src.image)
            if refused:
                (problems if problems is not None else []).append(
                    (name, f"node_tree.nodes[{src.name}].image", f"image {src.image.name!r}: {refused}"))
                return None
            colour = _image_mean(src.image)
            if colour is None:
                img = src.image
                path = os.path.normpath(bpy.path.abspath(img.filepath)) if img.filepath else ""
                (problems if problems is not None else []).append((name, f"node_tree.nodes[{src.name}].image", (
                    f"image {img.name!r} has no pixels (file {path!r}: missing, a folder or not an image): the "
                    "environment map's mean radiance is unknown (Blender renders a missing image magenta)")))
                return None
            warn(field, f"environment map {src.image.name!r} is {'packed' if src.image.packed_file else 'generated'} "
                 "(a map is read from an image file beside the .blend: unpack it): substituted the map's mean radiance "
                 f"over the sphere {conv.fmt(colour)} (solid-angle weighted, equirectangular)")
        elif src is not None:
            warn(field, f"linked to a {src.bl_idname} node: not converted, its unlinked colour {conv.fmt(colour)} used")
    if strength < 0:
        warn(f"{field.rsplit('.', 1)[0]}.Strength" if node is not None else "color", f"negative strength "
             f"{strength:g}: Blender subtracts light, the IR's emission is >= 0: no environment")
        return None
    if strength * colour.max() <= 0:
        return None
    spec = conv.emission(colour, strength)
    warn(field, f"background colour {conv.fmt(colour)} x strength {strength:g} -> a uniform environment of that "
         f"radiance (Cycles' convention): {conv.emission_note(spec)}")
    return {"type": "uniform", "radiance": spec}


def _environment_map(node, strength, field, name, warn, problems):
    """The IR's environment map of an Environment Texture node (docs/scene-format.md 7.1): its file
    relative to the .blend's folder, checked as a texture's is (a problem naming the world and node
    otherwise), its colour space, the Background strength as its scale and its mean radiance."""
    img = node.image
    base = os.path.dirname(bpy.data.filepath)
    where = f"node_tree.nodes[{node.name}].image"

    def refuse(message):
        (problems if problems is not None else []).append((name, where, f"image {img.name!r}: {message}"))
        return None
    found, why = _image_file(img, base, "map")
    if why:
        return refuse(why)
    env = {"type": "map", **found, "scale": float(strength), "rotation": 0.0}
    if strength < 0:
        warn(f"{field.rsplit('.', 1)[0]}.Strength", f"negative strength {strength:g}: Blender subtracts light, the "
             "IR's emission is >= 0: no environment")
        return None
    try:
        mean = textures.map_mean_rgb(textures.read_linear(env, base))
    except Exception as exc:  # noqa: BLE001 - an unreadable image fails this scene, named
        return refuse(f"cannot be read: {type(exc).__name__}: {exc}")
    if node.projection != "EQUIRECTANGULAR":
        warn(f"node_tree.nodes[{node.name}].projection", f"projection {node.projection}: read as equirectangular")
    if node.inputs["Vector"].is_linked:
        rotation, why = _map_rotation(node.inputs["Vector"].links[0].from_node)
        if why is None:
            env["rotation"] = rotation
        else:
            warn(f"node_tree.nodes[{node.name}].inputs[Vector]", f"{why}: not converted, the map is placed as "
                 "Blender places it unlinked")
    env["radiance"] = conv.emission(np.clip(mean, 0.0, None), strength)
    warn(field, f"environment map {img.name!r} ({env['file']}, {env['colour_space']}) x strength {strength:g}: "
         "each texel's linear sRGB uplifted by the renderer as an illuminant (Mitsuba: D65 times Jakob and Hanika's "
         f"model); its mean radiance {conv.fmt(mean * strength)} is recorded beside it")
    return env


def _map_rotation(src):
    """(IR rotation in degrees, None) of a Mapping node that only turns an environment about Z, fed
    by the Texture Coordinate's Generated or Object output (the world direction), or (None, why
    not). A Point mapping looks the map up at R d, which turns the map by -angle; a Texture mapping
    at R^-1 d, which turns it by +angle."""
    if src.bl_idname != "ShaderNodeMapping":
        return None, f"linked to a {src.bl_idname} node"
    vec = src.inputs["Vector"]
    feed = vec.links[0].from_node if vec.is_linked else None
    if feed is None or feed.bl_idname != "ShaderNodeTexCoord" or vec.links[0].from_socket.name not in ("Generated", "Object"):
        return None, "a Mapping node not fed by the Texture Coordinate's Generated or Object output"
    if src.vector_type not in ("POINT", "TEXTURE") or any(src.inputs[k].is_linked for k in ("Location", "Rotation", "Scale")):
        return None, f"a {src.vector_type.lower()} Mapping node, or one with linked inputs"
    loc, rot, scale = (tuple(src.inputs[k].default_value) for k in ("Location", "Rotation", "Scale"))
    if any(abs(v) > 1e-9 for v in (*loc, rot[0], rot[1])) or any(abs(s - 1) > 1e-9 for s in scale):
        return None, (f"a Mapping node with location {conv.fmt(loc)}, rotation {conv.fmt(tuple(math.degrees(r) for r in rot))} "
                      f"degrees and scale {conv.fmt(scale)}: only a rotation about Z converts")
    angle = math.degrees(rot[2])
    return round(-angle if src.vector_type == "POINT" else angle, 4), None  # float32 radians: 4 decimals of a degree


def _image_problem(image):
    """Why the pixels of ``image`` are not read (text), or None: its file must be a regular file
    (exporters/blend_safety.py) and its size, read from the file's header (a packed image's bytes,
    a generated image's settings) without loading it, at most MAX_IMAGE_PIXELS. A file that is
    missing is left to Blender (it has no pixels then)."""
    cap = blend_safety.MAX_IMAGE_PIXELS
    size = None
    if image.source == "GENERATED":
        size = (image.generated_width, image.generated_height)
    elif image.packed_file is not None:
        size = blend_safety.image_bytes_size(bytes(image.packed_file.data))
        if size is None:
            return "its packed data is no image file whose size can be read from its header: not read"
    elif image.source != "FILE":
        return f"source {image.source}: only a single image file, packed or generated image is read"
    else:
        path = os.path.normpath(bpy.path.abspath(image.filepath, library=image.library)) if image.filepath else ""
        if not path or not os.path.lexists(path):
            return None
        refused = blend_safety.file_problem(path)
        if refused:
            return refused
        size = blend_safety.image_header_size(path)
        if size is None:
            return f"{path!r} is no image file whose size can be read from its header: not read"
    if size[0] * size[1] > cap:
        return (f"{size[0]} x {size[1]} = {size[0] * size[1]} pixels, above the cap of {cap} (MAX_IMAGE_PIXELS, "
                "exporters/blend_safety.py): not read")
    return None


def _image_mean(image):
    """Mean linear RGB of an equirectangular image over the sphere (rows weighted by cos latitude);
    None when the image has no pixels (its file missing, a folder, not an image)."""
    w, h = image.size
    channels = image.channels
    if w * h * channels == 0 or len(image.pixels) != w * h * channels:
        return None
    px = np.empty(w * h * channels, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, channels)
    rgb = (px[..., :3] if channels >= 3 else np.repeat(px[..., :1], 3, axis=-1)).astype(np.float64)  # grey: 1-2
    lat = (np.arange(h) + 0.5) / h * math.pi - math.pi / 2
    wts = np.cos(lat)[:, None]
    return (rgb * wts[..., None]).sum(axis=(0, 1)) / (wts.sum() * w)


def _camera(scene, problems):
    cam = scene.camera
    if cam is None:
        problems.append(("camera", "scene.camera", "scene has no camera"))
        return None
    d = cam.data
    if d.type != "PERSP":
        problems.append((cam.name, "data.type", f"only perspective cameras are exported, got {d.type}"))
    if d.shift_x or d.shift_y:
        problems.append((cam.name, "data.shift", "lens shift is not exported"))
    r = scene.render
    w, h = r.resolution_x, r.resolution_y
    fit = d.sensor_fit
    if fit == "AUTO":
        axis, sensor = ("x" if w >= h else "y"), d.sensor_width
    elif fit == "HORIZONTAL":
        axis, sensor = "x", d.sensor_width
    else:
        axis, sensor = "y", d.sensor_height
    if not (sensor > 0 and d.lens > 0):  # Blender's minimum is 1 mm for both: a file can hold less
        field = "data.lens" if not d.lens > 0 else ("data.sensor_height" if fit == "VERTICAL" else "data.sensor_width")
        problems.append((cam.name, field, f"focal length {d.lens:g} mm and sensor {sensor:g} mm: both must be > 0 "
                                          "(a camera's field of view is 2 atan(sensor / (2 lens)))"))
        return None
    fov = math.degrees(2 * math.atan(sensor / (2 * d.lens)))
    out = {**_named(cam.name, ()), "to_world": _matrix(_world(cam)), "fov": _clean(fov), "fov_axis": axis}
    if d.spectral_bench.polarizer:
        out["polarizer"] = {"angle": _clean(d.spectral_bench.polarizer_angle)}
    return out


def _scene_losses(scene):
    """(object, field, message) of the scene's and camera's settings that change Blender's image
    and that the IR has no field for."""
    cam = scene.camera
    if cam is not None and cam.type == "CAMERA" and cam.data.dof.use_dof:
        yield cam.name, "data.dof.use_dof", "depth of field: the IR's camera is a pinhole (all in focus)"
    if scene.render.use_motion_blur:
        yield "scene", "render.use_motion_blur", "motion blur: the IR's scene is static (no blur)"
    if scene.render.film_transparent:
        yield "scene", "render.film_transparent", ("a transparent film: the IR renders the environment where Blender "
                                                   "leaves the background transparent")
    exposure = getattr(getattr(scene, "cycles", None), "film_exposure", 1.0)
    if abs(exposure - 1.0) > 1e-6:
        yield "scene", "cycles.film_exposure", f"film exposure {exposure:g}: the IR's pixels are radiance (exposure 1)"


def extract_scene(scene):
    """IR dict of one Blender scene; raises validate.SceneError naming every problem."""
    problems = []
    a = scene.spectral_bench
    r = scene.render
    pct = r.resolution_percentage / 100.0
    out = {
        "format": ir.FORMAT, "version": ir.VERSION, **_named(scene.name, (), names.scene_problem), "case": a.case,
        "needs": [n for n, on in (("polarization", a.needs_polarization),
                                  ("fluorescence", a.needs_fluorescence)) if on],
        "render": {"spp": a.spp, "max_depth": a.max_depth, "width": int(r.resolution_x * pct),
                   "height": int(r.resolution_y * pct), "filter": "box", "integrator": a.integrator.lower()},
        "camera": _camera(scene, problems),
        "environment": None,
        "objects": [],
    }
    if a.description:
        out["description"] = a.description
    if a.output != "RGB":
        out["render"]["output"] = a.output.lower()
    world = scene.world
    warnings = list(_scene_losses(scene))
    try:
        if world is not None and world.spectral_bench.enabled:
            out["environment"] = {"type": "uniform", "radiance": spectrum(world.spectral_bench.radiance)}
        elif world is not None:
            out["environment"] = _converted_world(world, warnings, problems)
        if world is not None and world.spectral_bench.enabled and not spectrum_set(world.spectral_bench.radiance):
            out["environment"] = _converted_world(world, warnings, problems)
            warnings.append((f"world[{world.name}]", "spectral_bench.radiance", "Uniform Environment on without a "
                             "radiance spectrum: Blender's world colour x strength is used, not the default 0.5"))
    except Exception as exc:  # noqa: BLE001 - an exporter fault fails this scene, naming the world
        problems.append((f"world[{world.name}]", "(conversion)", _fault(exc)))
    lights = []
    depsgraph = scene.view_layers[0].depsgraph if scene.view_layers else None
    used = {"triangles": 0, "vertices": 0}  # by the scene's meshes (exporters/blend_safety.py caps it)
    taken = []
    for obj in sorted(scene.objects, key=lambda o: o.name):
        if obj.hide_render:
            continue
        light = None
        if obj.type in ("MESH", "LIGHT"):
            try:
                if obj.type == "MESH":
                    item = _mesh_object(obj, depsgraph, problems, warnings, used)
                else:
                    item, light = _light_object(obj, problems, warnings)
            except Exception as exc:  # noqa: BLE001 - an exporter fault fails this scene, naming the object
                problems.append((obj.name, "(conversion)", _fault(exc)))
                continue
        else:
            if obj.type not in ("CAMERA", "EMPTY"):
                warnings.append((obj.name, "type", f"a {obj.type} object is not exported (only meshes and lights)"))
            elif obj.type == "EMPTY" and obj.instance_type == "COLLECTION" and obj.instance_collection is not None:
                warnings.append((obj.name, "instance_collection", f"the instanced collection "
                                 f"{obj.instance_collection.name!r} is not exported (instances are not)"))
            continue
        for entry, target in ((item, out["objects"]), (light, lights)):
            if entry is not None:
                named = _named(obj.name, taken, names.object_problem)
                target.append({**named, **{k: v for k, v in entry.items() if k != "name"}})
                taken.append(named["name"])
    if lights:
        out["lights"] = lights
    if warnings:
        out["warnings"] = [{"object": o, "field": f, "message": m} for o, f, m in warnings]
    if problems:
        raise validate.SceneError(out["name"], problems)
    if any((o.get("bsdf") or {}).get("reflectance_texture") for o in out["objects"]) \
            or (out.get("environment") or {}).get("type") == "map":
        out["_base_dir"] = os.path.dirname(bpy.data.filepath)  # texture files are relative to the .blend
    validate.check(out, own_records=True)  # its warnings are the exporter's own records: not capped
    out["needs"] = ir.derived_needs(out)
    return out


def _fault(exc):
    """The message of an unexpected exception in a conversion (a fault of the exporter, not of the
    file): what it was, for the user's report."""
    return (f"the conversion failed: {type(exc).__name__}: {exc} (a fault of the exporter, not a value it "
            "refuses: please report it with the .blend file)")


def _named(blender_name, taken, problem=names.problem):
    """{"name": a valid IR name} for a Blender name, and {"label": the Blender name} when the two
    differ: Blender allows any text in a name ("Key Light", "Würfel", "a/b"), the IR's names name
    files (exporters/names.py)."""
    if problem(blender_name) is None and blender_name.lower() not in {t.lower() for t in taken}:
        return {"name": blender_name}
    return {"name": names.safe_id(blender_name, taken), "label": blender_name}


def scene_names():
    return [s.name for s in bpy.data.scenes]


def extract(wanted=None):
    """[(scene name, IR dict or SceneError)] for the named Blender scenes (all by default)."""
    results = []
    for name in wanted or scene_names():
        ir_name = _named(name, (), names.scene_problem)["name"]
        scene = bpy.data.scenes.get(name)
        if scene is None:
            results.append((ir_name, validate.SceneError(ir_name, [("scene", "name", f"no scene {name!r} in the .blend file")])))
            continue
        try:
            results.append((ir_name, extract_scene(scene)))
        except validate.SceneError as exc:
            results.append((ir_name, exc))
        except Exception as exc:  # noqa: BLE001 - one scene's fault fails that scene alone, named
            results.append((ir_name, validate.SceneError(ir_name, [("scene", "(conversion)", _fault(exc))])))
    return results
