"""Validation of an IR scene: JSON Schema for shape, then value checks.

Every problem names the scene, the object (or camera / render / environment) and the field,
so a user can find it in Blender or in the JSON file.
"""
import json
import math
from functools import lru_cache
from pathlib import Path

import jsonschema
import numpy as np

from . import dispersion, fluorescence, inline_data, ir, mesh_io, names, spectra, textures

SCHEMA_PATH = Path(__file__).resolve().parent / "schema" / "scene.schema.json"


class SceneError(ValueError):
    """One or more problems in a scene; ``problems`` is a list of (object, field, message)."""

    def __init__(self, scene, problems):
        self.scene = scene
        self.problems = [(_short(obj), _short(field), _short(msg)) for obj, field, msg in problems]
        lines = [f"scene {_short(scene)!r}, object {obj!r}, field {field!r}: {msg}"
                 for obj, field, msg in self.problems[:MAX_PROBLEMS_SHOWN]]
        if len(self.problems) > MAX_PROBLEMS_SHOWN:
            lines.append(f"... and {len(self.problems) - MAX_PROBLEMS_SHOWN} more problems")
        super().__init__("; ".join(lines) if len(lines) < 2 else "\n  " + "\n  ".join(lines))


# A reason is read by a person (the log, summary.md, report.html): each part of a problem is cut to
# MAX_MESSAGE characters (a value shown in it can be a whole list), at most MAX_PROBLEMS_SHOWN listed
MAX_MESSAGE = 300
MAX_PROBLEMS_SHOWN = 20


def _short(text):
    text = text if isinstance(text, str) else str(text)
    return text if len(text) <= MAX_MESSAGE else f"{text[:MAX_MESSAGE - 40]} ... ({len(text)} characters in all)"


# The longest list each field may hold, by the field's name: the one table of caps, checked before
# any other work (the schema's checks and their messages cost time in the length of a list, and a
# hostile file could ask for any length). Sized for real scenes, far above every shipped one: a
# Blender scene of thousands of objects and hundreds of lights, each object with its conversion
# warnings. A list of a field not named here (a transform's rows, Sellmeier terms, a point, a face's
# indices) holds a handful of numbers: MAX_OTHER_LIST. The exporter's own records (``warnings`` of a
# scene just extracted from Blender, ``check(..., own_records=True)``) are never capped: their length
# follows the scene's.
MAX_SAMPLES = 16384
MAX_MESH_ITEMS = 1 << 22
LIST_LIMITS = {
    "wavelengths": MAX_SAMPLES, "values": MAX_SAMPLES,  # a sampled spectrum's or a fluorescence grid's samples
    "matrix": 1024, "matrix[]": 1024,  # a fluorescence matrix and its rows
    "vertices": MAX_MESH_ITEMS, "faces": MAX_MESH_ITEMS,  # an inline mesh
    "objects": 100_000,  # shapes: meshes, spheres, rectangles, area lights
    "lights": 10_000,  # delta lights: point, spot, directional
    "warnings": 1 << 20,  # what an exporter converted or lost, a few per object and light
}
MAX_OTHER_LIST = 64
OWN_RECORDS = ("warnings",)  # lists an exporter writes about its own conversion: not capped in its own output


def _size_problems(data, own_records=False):
    """Lists longer than their field's LIST_LIMITS (MAX_OTHER_LIST elsewhere), found without looking
    at the items of a list that is too long; (object, field, message) with the object as validation
    names it. With ``own_records`` the top-level OWN_RECORDS are not capped."""
    stack = [(data, "", "scene", "")]
    while stack:
        node, key, obj, where = stack.pop()
        if isinstance(node, dict):
            if where.startswith(("objects[", "lights[")) and where.count(".") == 0 \
                    and names.problem(node.get("name")) is None:
                obj, where = node["name"], ""
            for k, v in reversed(node.items()):  # a stack: reversed, so problems come in the file's order
                if own_records and node is data and k in OWN_RECORDS:
                    continue
                if isinstance(v, (dict, list)):
                    stack.append((v, str(k), obj, f"{where}.{k}" if where else str(k)))
        elif isinstance(node, list):
            limit = LIST_LIMITS.get(key, MAX_OTHER_LIST)
            if len(node) > limit:
                what = f"a scene's {key} (exporters/validate.py LIST_LIMITS)" if key in LIST_LIMITS else \
                    f"a list of a few numbers such as {key or 'this'} (exporters/validate.py LIST_LIMITS names the longer ones)"
                yield obj, where, f"holds {len(node)} items, more than {limit}: the limit for {what}"
                continue
            for i, v in reversed(list(enumerate(node))):
                if isinstance(v, (dict, list)):
                    stack.append((v, f"{key}[]", obj, f"{where}[{i}]"))


@lru_cache(maxsize=1)
def _schema_text():
    return SCHEMA_PATH.read_text()


def schema():
    """The IR's JSON Schema, a fresh copy on every call: a caller that changes it (as
    hypothesis-jsonschema canonicalises a schema in place) cannot change validation."""
    return json.loads(_schema_text())


def _finite(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _within_its_type(err):
    """A oneOf over objects told apart by their "type" (BSDFs, shapes, spectra, fluorescence) fails
    as a whole; the errors of the branch of the object's own type say what is wrong, and where."""
    inst = err.instance
    if err.validator == "oneOf" and isinstance(inst, dict) and "type" in inst:
        own = [e for e in err.context if isinstance(err.validator_value[e.schema_path[0]], dict)
               and err.validator_value[e.schema_path[0]].get("properties", {}).get("type", {}).get("const") == inst["type"]]
        if own:
            return [leaf for e in own for leaf in _within_its_type(e)]
    return [err]


@lru_cache(maxsize=1)
def _validator():
    return jsonschema.Draft202012Validator(schema())


def _schema_problems(data):
    validator = _validator()
    errors = [leaf for err in validator.iter_errors(data) for leaf in _within_its_type(err)]
    for err in sorted(errors, key=lambda e: list(e.absolute_path)):
        path = list(err.absolute_path)
        obj = "scene"
        if len(path) >= 2 and path[0] == "objects" and isinstance(path[1], int):
            objs = data.get("objects", [])
            name = objs[path[1]].get("name") if isinstance(objs[path[1]], dict) else None
            # a name that is itself wrong (not a string, a path) never labels the object
            obj = name if names.problem(name) is None else f"objects[{path[1]}]"
            path = path[2:]
        elif len(path) >= 2 and path[0] == "lights" and isinstance(path[1], int):
            lights = data.get("lights", [])
            name = lights[path[1]].get("name") if isinstance(lights[path[1]], dict) else None
            obj = name if names.problem(name) is None else f"lights[{path[1]}]"
            path = path[2:]
        elif path and path[0] in ("camera", "render", "environment"):
            obj = path[0]
            path = path[1:]
        field = ".".join(str(p) for p in path) or "(root)"
        msg = err.message
        if err.validator in ("pattern", "maxLength") and err.schema.get("pattern") == names.PATTERN:
            # a name: say what a name may be, and show the value with its escapes (a newline as \n)
            msg = f"{names.problem(err.instance, 'name') or 'is not a name'}; got {err.instance!r}"
        elif err.validator == "oneOf":
            msg = "does not match any allowed form: " + "; ".join(sorted({c.message for c in err.context})[:4])
        yield obj, field, msg


FOV_RANGE = (1e-3, 179.0)  # degrees; the writers take 1 / tan(fov / 2), which a denormal fov makes infinite
MAX_PIXELS = 1 << 26  # 8192 x 8192: a render and its reference are held in memory as float32


def _name_problems(scene):
    """Names name files: the pattern of exporters/names.py, checked here with fullmatch (the
    schema's pattern is applied with re.search, where "$" also matches before a final newline)."""
    why = names.scene_problem(scene["name"])
    if why:
        yield "scene", "name", why
    why = names.problem(scene["case"], "case")
    if why:
        yield "scene", "case", why
    if "name" in scene["camera"]:
        why = names.problem(scene["camera"]["name"], "camera name")
        if why:
            yield "camera", "name", why
    seen = {}
    for where, obj in [(f"objects[{i}]", o) for i, o in enumerate(scene["objects"])] + \
            [(f"lights[{i}]", o) for i, o in enumerate(scene.get("lights", []))]:
        why = names.object_problem(obj["name"])
        if why:
            yield where, "name", f"{why}; got {obj['name']!r}"
        elif obj["name"].lower() in seen:
            yield obj["name"], "name", (f"is used by two objects ({seen[obj['name'].lower()]} and "
                                        f"{where}; names are compared ignoring case: they name files)")
        else:
            seen[obj["name"].lower()] = where


def render_limit(field):
    """(minimum, maximum) of an integer field of ``render`` (the schema's bounds)."""
    spec = schema()["properties"]["render"]["properties"][field]
    return spec["minimum"], spec["maximum"]


def _render_problems(r, why=""):
    for field in ("width", "height", "spp", "max_depth"):
        if field in r:
            lo, hi = render_limit(field)
            if not lo <= r[field] <= hi:
                yield "render", field, f"must be {lo} to {hi}, got {r[field]}{why}"
    if r["width"] * r["height"] > MAX_PIXELS:
        yield "render", "width", (f"{r['width']} x {r['height']} is {r['width'] * r['height']} pixels, more than "
                                  f"{MAX_PIXELS} (8192 x 8192){why}")


def check_render(scene, why):
    """Raise SceneError if the scene's render settings, changed by an option (``why`` says which),
    left the IR's bounds."""
    problems = list(_render_problems(scene["render"], why))
    if problems:
        raise SceneError(scene["name"], problems)
    return scene


def _value_problems(scene):
    yield from (p for p in _render_problems(scene["render"]) if p[1] == "width")
    cam = scene["camera"]
    cam_name = cam.get("name", "camera")
    if not _finite(cam["fov"]) or not FOV_RANGE[0] <= cam["fov"] <= FOV_RANGE[1]:
        yield cam_name, "fov", f"must be in [{FOV_RANGE[0]:g}, {FOV_RANGE[1]:g}] degrees, got {cam['fov']!r}"
    yield from ((cam_name, f, m) for f, m in _transform_problems(cam["to_world"], "to_world"))
    pol = cam.get("polarizer")
    if pol is not None and not _finite(pol["angle"]):
        yield cam_name, "polarizer.angle", f"must be a finite angle in degrees, got {pol['angle']!r}"
    env = scene.get("environment")
    if env:
        for field, msg in spectra.check(env["radiance"], "radiance"):
            yield "environment", field, msg
        if env.get("type") == "map":
            _path, why = textures.resolve(env, scene.get("_base_dir"))
            if why:
                yield "environment", "file", why
            for key, lo in (("scale", 0.0), ("rotation", None)):
                v = env.get(key, 0.0)
                if not _finite(v) or (lo is not None and v < lo) or abs(v) > MAX_COORDINATE:
                    yield "environment", key, f"must be finite{' and >= 0' if lo is not None else ''}, got {v!r}"
    for obj in scene["objects"]:
        name = obj["name"]
        yield from ((name, f, m) for f, m in _shape_problems(obj["shape"], scene.get("_base_dir")))
        bsdf = obj.get("bsdf")
        if bsdf:
            yield from ((name, "bsdf." + f, m) for f, m in bsdf_problems(bsdf))
            if bsdf.get("reflectance_texture") is not None:
                yield from ((name, f, m) for f, m in _texture_problems(obj, scene.get("_base_dir")))
        em = obj.get("emitter")
        if em:
            key = "irradiance" if em.get("type") == "collimated" else "radiance"
            yield from ((name, "emitter." + f, m) for f, m in spectra.check(em[key], key))
            if em.get("type") == "collimated" and obj["shape"]["type"] != "rectangle":
                yield name, "emitter.type", "a collimated emitter must be a rectangle (it emits along its normal)"
        if not bsdf and not em:
            yield name, "bsdf", "object has neither a BSDF nor an emitter annotation"
    for light in scene.get("lights", []):
        yield from ((light["name"], f, m) for f, m in light_problems(light))


# a delta light's spectrum and geometry fields, by its type
LIGHT_SPECTRUM = {"point": "intensity", "spot": "intensity", "directional": "irradiance"}


def light_problems(light):
    key = LIGHT_SPECTRUM[light["type"]]
    yield from spectra.check(light[key], key)
    if light["type"] == "point" and not all(_finite(c) and abs(c) <= MAX_COORDINATE for c in light["position"]):
        yield "position", f"must be finite and within +-{MAX_COORDINATE:g}, got {light['position']!r}"
    if light["type"] == "directional":
        d = light["direction"]
        if not all(_finite(c) for c in d) or not 0 < math.hypot(*d) < math.inf:
            yield "direction", f"must be a finite non-zero vector, got {d!r}"
    if light["type"] == "spot":
        yield from _transform_problems(light["to_world"], "to_world")
        cut, beam = light["cutoff_angle"], light["beam_width"]
        if not _finite(cut) or not 0 < cut <= 90:
            yield "cutoff_angle", f"must be in (0, 90] degrees, got {cut!r}"
        elif not _finite(beam) or not 0 <= beam <= cut:
            yield "beam_width", f"must be in [0, cutoff_angle = {cut}] degrees, got {beam!r}"


# Scene units: the canonical scenes span a few tens of units; beyond these bounds single-precision
# renderers lose the geometry and the writers' products overflow to inf
MAX_COORDINATE = 1e6
MIN_RADIUS = 1e-6
MAX_CONDITION = 1e8  # of a transform's 3x3 part: beyond it the frame is degenerate in float32


def _transform_problems(m, field):
    """A to_world is an affine map that can be inverted: finite, last row 0 0 0 1, and a 3x3 part
    that is not (nearly) singular (writers and probes invert it: a flattened rectangle or camera
    has no normal or view direction)."""
    bad = [(i, j, v) for i, row in enumerate(m) for j, v in enumerate(row) if not _finite(v) or abs(v) > MAX_COORDINATE]
    for i, j, v in bad:
        yield f"{field}[{i}][{j}]", f"must be a finite number within +-{MAX_COORDINATE:g}, got {v!r}"
    if bad:
        return
    a = np.asarray(m, dtype=np.float64)
    if not np.array_equal(a[3], [0.0, 0.0, 0.0, 1.0]):
        yield f"{field}[3]", f"must be [0, 0, 0, 1] (an affine transform), got {m[3]!r}"
    elif not np.linalg.cond(a[:3, :3]) <= MAX_CONDITION:  # nan for an all-zero part
        yield field, "is singular or nearly so (its 3x3 part flattens space): an object or camera needs a frame"


def transform_problem(m):
    """The first (field, message) of what keeps ``m`` (4x4 nested lists) from being a to_world, or
    None when it is one."""
    return next(_transform_problems(m, "to_world"), None)


def _shape_problems(shape, base_dir):
    if "to_world" in shape:
        yield from _transform_problems(shape["to_world"], "shape.to_world")
    if shape["type"] == "sphere":
        if not _finite(shape["radius"]) or not MIN_RADIUS <= shape["radius"] <= MAX_COORDINATE:
            yield "shape.radius", f"must be in [{MIN_RADIUS:g}, {MAX_COORDINATE:g}], got {shape['radius']!r}"
        if not all(_finite(c) and abs(c) <= MAX_COORDINATE for c in shape["center"]):
            yield "shape.center", f"must be finite and within +-{MAX_COORDINATE:g}, got {shape['center']!r}"
    if shape["type"] == "mesh":
        if "file" in shape:
            yield from _mesh_file_problems(shape, base_dir)
        else:
            yield from _mesh_data_problems(shape["vertices"], shape["faces"])
        if "uvs" in shape:
            yield from _uv_problems(shape)


def _texture_problems(obj, base_dir):
    """A textured BSDF's file (exporters/textures.py) and the texture coordinates it needs: a mesh
    with inline ``uvs``, one finite (u, v) per vertex."""
    yield from textures.problems(obj["bsdf"]["reflectance_texture"], base_dir)
    shape = obj["shape"]
    if shape["type"] != "mesh" or "uvs" not in shape:
        yield "shape.uvs", (f"a textured BSDF needs texture coordinates: a mesh with inline uvs (this "
                            f"{shape['type']} has none)")


def _uv_problems(shape):
    uvs = shape["uvs"]
    if "vertices" not in shape:
        yield "shape.uvs", "texture coordinates go with inline vertices (a mesh file's own u, v are not read)"
    elif len(uvs) != len(shape["vertices"]):
        yield "shape.uvs", f"{len(uvs)} texture coordinates for {len(shape.get('vertices', []))} vertices (one per vertex)"
    elif not all(_finite(c) and abs(c) <= MAX_COORDINATE for uv in uvs for c in uv):
        yield "shape.uvs", f"texture coordinates must be finite and within +-{MAX_COORDINATE:g}"


def _mesh_data_problems(vertices, faces, file=None):
    """Problems of mesh data, inline (fields shape.faces, shape.vertices) or read from ``file``
    (field shape.file)."""
    def field(sub):
        return ("shape.file", f"{file!r}: ") if file else (f"shape.{sub}", "")
    if not len(faces) or not len(vertices):
        f, what = field("faces")
        yield f, what + "mesh has no faces (missing mesh data)"
        return
    n = len(vertices)
    if any(i < 0 or i >= n for f in faces for i in f):
        f, what = field("faces")
        yield f, what + f"face index out of range (mesh has {n} vertices)"
    if not all(_finite(c) and abs(c) <= MAX_COORDINATE for v in vertices for c in v):
        f, what = field("vertices")
        yield f, what + f"vertices must be finite and within +-{MAX_COORDINATE:g}"


def _mesh_file_problems(shape, base_dir):
    """A mesh file is a relative path inside the scene's folder (the folder of its JSON file),
    and is read here, so that a file that is not a mesh fails this scene at validation."""
    raw = shape["file"]
    rel = Path(raw)
    if not raw or rel.is_absolute() or raw.startswith(("/", "\\")) or ".." in rel.parts or "\\" in raw \
            or any(ord(c) < 32 for c in raw):
        yield "shape.file", (f"{raw!r}: a mesh file must be a relative path inside the scene's folder "
                             "(no absolute path, no '..', no backslash or control character)")
        return
    base = Path(base_dir or ".").resolve()
    path = (base / rel).resolve()
    if base not in path.parents:
        yield "shape.file", f"{raw!r} resolves to {path}, outside the scene's folder {base} (a link?)"
        return
    if not path.is_file():
        yield "shape.file", f"mesh file not found: {path}"
        return
    if path.suffix.lower() not in (".ply", ".obj"):
        yield "shape.file", f"{raw!r}: a mesh file is .ply or .obj"
        return
    try:
        vertices, faces = mesh_io.load_mesh({"file": str(path)})
    except Exception as exc:  # noqa: BLE001 - any parser error is this scene's problem, named
        yield "shape.file", f"{raw!r} is not a readable {path.suffix[1:].upper()} mesh: {type(exc).__name__}: {exc}"
        return
    yield from _mesh_data_problems(vertices, faces, raw)


def bsdf_problems(bsdf):
    kind = bsdf["type"]
    if kind == "coated_diffuse":
        for key in ("int_ior", "ext_ior"):
            v = bsdf.get(key, ir.AIR_IOR)
            if not _finite(v) or not 0 < v <= dispersion.MAX_IOR:
                yield key, f"must be a finite IOR in (0, {dispersion.MAX_IOR:g}], got {v!r}"
    if kind in ("diffuse", "coated_diffuse"):
        problems = list(spectra.check(bsdf["reflectance"], "reflectance"))
        yield from problems
        if not problems:
            wl = spectra.cie_1931_cmfs()[0]
            values = spectra.evaluate(bsdf["reflectance"], wl)
            if values.max() > 1.0:
                i = int(values.argmax())
                yield "reflectance", (f"a diffuse reflectance above 1 creates energy: {values[i]:.4g} at "
                                      f"{wl[i]:g} nm (360-830 nm)")
            elif bsdf.get("fluorescence") is not None and bsdf.get("reflectance_texture") is not None:
                yield "reflectance_texture", ("a fluorescent diffuse takes one reflectance spectrum: a texture "
                                              "and a fluorescence matrix together are not modelled")
            elif bsdf.get("fluorescence") is not None:
                rho = bsdf["reflectance"]
                yield from fluorescence.problems(bsdf["fluorescence"], lambda wl: spectra.evaluate(rho, wl))
    if kind == "conductor":
        if "material" in bsdf and ("eta" in bsdf or "k" in bsdf):
            # inline data that exporters/inline_data.py left beside the name is incomplete: say so
            # rather than render the named table and ignore it
            missing = "k" if "eta" in bsdf else "eta"
            yield missing, f"a conductor's inline data needs both eta and k beside material {bsdf['material']!r}"
            return
        if "material" in bsdf and bsdf["material"] not in spectra.NAMED_CONDUCTORS:
            yield "material", (f"unknown conductor {bsdf['material']!r} "
                               f"(known: {', '.join(spectra.NAMED_CONDUCTORS)})")
        for key in ("eta", "k"):
            if key in bsdf:
                problems = list(spectra.check(bsdf[key], key))
                yield from problems
                top = _spectrum_max(bsdf[key]) if not problems else None
                if top is not None and top > MAX_CONDUCTOR_INDEX:
                    yield key, (f"reaches {top:.4g}, above {MAX_CONDUCTOR_INDEX:g}: no real conductor has such an "
                                f"index (shipped metals: eta < 7, k < 9 over 300-900 nm)")
        film = bsdf.get("thin_film")
        if film is not None:
            d = film["thickness"]
            if not _finite(d) or d < 0:
                yield "thin_film.thickness", f"must be a finite thickness >= 0 nm, got {d!r}"
            for key in ("ior", "ext_ior"):
                v = film.get(key, 1.0)
                if not _finite(v) or not 0 < v <= dispersion.MAX_IOR:
                    yield f"thin_film.{key}", f"must be a finite IOR in (0, {dispersion.MAX_IOR:g}], got {v!r}"
            if _finite(d) and d > MAX_FILM_NM:
                yield "thin_film.thickness", f"must be at most {MAX_FILM_NM:g} nm (a thin film), got {d!r}"
    if kind == "dielectric":
        yield from dispersion.problems(bsdf.get("int_ior"), "int_ior")  # a number or an IOR model
        v = bsdf.get("ext_ior", ir.AIR_IOR)
        if not _finite(v) or not 0 < v <= dispersion.MAX_IOR:
            yield "ext_ior", f"must be a finite IOR in (0, {dispersion.MAX_IOR:g}], got {v!r}"
    rough = bsdf.get("roughness")
    if rough is not None:
        a = rough["alpha"]
        if not _finite(a) or a < 0:
            yield "roughness.alpha", f"must be a finite number >= 0, got {a!r}"


# Physical bounds (documented in docs/scene-format.md): every real material is far inside them
MAX_CONDUCTOR_INDEX = 1000.0  # eta and k of a conductor (infrared tables of metals reach k ~ 100)
MAX_FILM_NM = 1e6  # a thin film's thickness (1 mm)


def _spectrum_max(spec):
    """The largest value of a checked spectrum given by numbers (constant or sampled), else None."""
    if spec.get("type") == "constant":
        return float(spec["value"])
    values = spec.get("values")
    return float(max(values)) if isinstance(values, list) and values else None


def check(scene, own_records=False):
    """Raise SceneError listing every problem of ``scene`` (an IR dict); return it otherwise.
    ``own_records``: the scene was just made by an exporter of this project (its ``warnings`` are
    its own records, not capped; see LIST_LIMITS).
    A scene in the self-contained form (inline tables) is first turned into the internal IR, in
    place (exporters/inline_data.py ``apply``)."""
    name = scene.get("name", "?") if isinstance(scene, dict) else "?"
    if names.scene_problem(name) is not None:
        name = "?"  # the problem is reported below; a bad name never labels anything
    if not isinstance(scene, dict):
        raise SceneError(name, [("scene", "(root)", "a scene must be a JSON object")])
    if scene.get("format") != ir.FORMAT or scene.get("version") != ir.VERSION:
        raise SceneError(name, [("scene", "version", f"expected format {ir.FORMAT!r} version {ir.VERSION}, "
                                 f"got {scene.get('format')!r} version {scene.get('version')!r}")])
    try:
        problems = list(_size_problems({k: v for k, v in scene.items() if not k.startswith("_")}, own_records))
        if problems:
            raise SceneError(name, problems)
        inline_data.apply(scene)  # a self-contained file's tables: dropped when the project's, else they win
        data = {k: v for k, v in scene.items() if not k.startswith("_")}
        problems = list(_schema_problems(data))
        if problems:
            raise SceneError(name, problems)
        problems = list(_name_problems(scene)) + list(_value_problems(scene))
    except RecursionError:
        problems = [("scene", "(root)", "nested too deeply to be a scene")]
    if problems:
        raise SceneError(name, problems)
    return scene
