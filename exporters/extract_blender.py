"""Blender -> scene IR. The only module of exporters/ that imports bpy.

One Blender scene is one test scene. Exported: the scene camera, render-visible mesh objects
(with an annotated material), area lights (square or rectangle), and the world's uniform
environment. Anything that cannot be expressed is reported by object and field.
"""
import math

import bpy
from mathutils import Matrix

from . import ir, names, validate


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
    if a.distribution != "SMOOTH":
        out["roughness"] = {"distribution": a.distribution.lower(), "alpha": _clean(a.alpha)}
    return out


def _mesh_object(obj, depsgraph, problems):
    name = obj.name
    mat = obj.active_material
    if mat is None:
        problems.append((name, "material", "mesh object has no material"))
        return None
    if mat.spectral_bench.kind == "NONE":
        problems.append((name, f"material[{mat.name}].spectral_bench.kind",
                         "material has no spectral annotation (set its Model)"))
        return None
    if mat.spectral_bench.kind == "DIFFUSE":
        try:
            fluorescence(mat.spectral_bench)
        except ValueError as exc:
            problems.append((name, f"material[{mat.name}].spectral_bench.fluorescence_matrix_file", str(exc)))
            return None
    kind = obj.spectral_bench.shape
    mw = _world(obj)
    if kind == "RECTANGLE":
        shape = {"type": "rectangle", "to_world": _matrix(mw)}
    elif kind == "SPHERE":
        loc, _rot, scale = mw.decompose()
        if max(scale) - min(scale) > 1e-6 * max(scale):
            problems.append((name, "scale", f"an analytic sphere needs a uniform scale, got {tuple(scale)}"))
            return None
        shape = {"type": "sphere", "center": [_clean(c) for c in loc], "radius": _clean(scale[0])}
    else:
        # modifiers are applied when the scene has been evaluated, the base mesh is used otherwise
        source = obj.evaluated_get(depsgraph) if depsgraph is not None else obj
        mesh = source.to_mesh()
        try:
            mesh.calc_loop_triangles()
            verts = [[_clean(c) for c in v.co] for v in mesh.vertices]
            faces = [list(t.vertices) for t in mesh.loop_triangles]
        finally:
            source.to_mesh_clear()
        if not faces:
            problems.append((name, "data", "mesh has no faces (missing mesh)"))
        shape = {"type": "mesh", "to_world": _matrix(mw), "vertices": verts, "faces": faces}
    return {"name": name, "shape": shape, "bsdf": material_bsdf(mat), "emitter": None}


def _light_object(obj, problems):
    light = obj.data
    if light.type != "AREA" or light.shape not in ("SQUARE", "RECTANGLE"):
        problems.append((obj.name, "data.type", f"only square/rectangle area lights are exported, got {light.type}"
                         + (f"/{light.shape}" if light.type == "AREA" else "")))
        return None
    sx = light.size / 2
    sy = (light.size_y if light.shape == "RECTANGLE" else light.size) / 2
    # Blender area lights emit along local -Z; the IR rectangle emits along +Z: turn it over
    # (180 degrees about X), then size it.
    local = Matrix.Diagonal((sx, sy, 1.0, 1.0)) @ Matrix.Rotation(math.pi, 4, "X")
    emitter = {"type": "area", "radiance": spectrum(light.spectral_bench.radiance)}
    if light.spectral_bench.collimated:
        emitter = {"type": "collimated", "irradiance": spectrum(light.spectral_bench.radiance)}
    return {"name": obj.name, "shape": {"type": "rectangle", "to_world": _matrix(_world(obj) @ local)},
            "bsdf": None, "emitter": emitter}


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
    fov = math.degrees(2 * math.atan(sensor / (2 * d.lens)))
    out = {**_named(cam.name, ()), "to_world": _matrix(_world(cam)), "fov": _clean(fov), "fov_axis": axis}
    if d.spectral_bench.polarizer:
        out["polarizer"] = {"angle": _clean(d.spectral_bench.polarizer_angle)}
    return out


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
    if world is not None and world.spectral_bench.enabled:
        out["environment"] = {"type": "uniform", "radiance": spectrum(world.spectral_bench.radiance)}
    depsgraph = scene.view_layers[0].depsgraph if scene.view_layers else None
    taken = []
    for obj in sorted(scene.objects, key=lambda o: o.name):
        if obj.hide_render:
            continue
        if obj.type == "MESH":
            item = _mesh_object(obj, depsgraph, problems)
        elif obj.type == "LIGHT":
            item = _light_object(obj, problems)
        else:
            continue
        if item is not None:
            named = _named(obj.name, taken, names.object_problem)
            item = {**named, **{k: v for k, v in item.items() if k != "name"}}
            taken.append(named["name"])
            out["objects"].append(item)
    if problems:
        raise validate.SceneError(out["name"], problems)
    validate.check(out)
    out["needs"] = ir.derived_needs(out)
    return out


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
    return results
