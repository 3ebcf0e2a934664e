"""Validation of an IR scene: JSON Schema for shape, then value checks.

Every problem names the scene, the object (or camera / render / environment) and the field,
so a user can find it in Blender or in the JSON file.
"""
import json
import math
from functools import lru_cache
from pathlib import Path

import jsonschema

from . import dispersion, fluorescence, ir, spectra

SCHEMA_PATH = Path(__file__).resolve().parent / "schema" / "scene.schema.json"


class SceneError(ValueError):
    """One or more problems in a scene; ``problems`` is a list of (object, field, message)."""

    def __init__(self, scene, problems):
        self.scene = scene
        self.problems = list(problems)
        lines = [f"scene {scene!r}, object {obj!r}, field {field!r}: {msg}" for obj, field, msg in self.problems]
        super().__init__("; ".join(lines) if len(lines) < 2 else "\n  " + "\n  ".join(lines))


@lru_cache(maxsize=1)
def schema():
    return json.loads(SCHEMA_PATH.read_text())


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


def _schema_problems(data):
    validator = jsonschema.Draft202012Validator(schema())
    errors = [leaf for err in validator.iter_errors(data) for leaf in _within_its_type(err)]
    for err in sorted(errors, key=lambda e: list(e.absolute_path)):
        path = list(err.absolute_path)
        obj = "scene"
        if len(path) >= 2 and path[0] == "objects" and isinstance(path[1], int):
            objs = data.get("objects", [])
            name = objs[path[1]].get("name") if isinstance(objs[path[1]], dict) else None
            obj = name or f"objects[{path[1]}]"
            path = path[2:]
        elif path and path[0] in ("camera", "render", "environment"):
            obj = path[0]
            path = path[1:]
        field = ".".join(str(p) for p in path) or "(root)"
        msg = err.message
        if err.validator == "oneOf":
            msg = "does not match any allowed form: " + "; ".join(sorted({c.message for c in err.context})[:4])
        yield obj, field, msg


def _value_problems(scene):
    r = scene["render"]
    for key in ("spp", "width", "height"):
        if r[key] < 1:
            yield "render", key, f"must be >= 1, got {r[key]}"
    cam = scene["camera"]
    cam_name = cam.get("name", "camera")
    if not _finite(cam["fov"]) or not 0 < cam["fov"] < 180:
        yield cam_name, "fov", f"must be in (0, 180) degrees, got {cam['fov']!r}"
    for i, row in enumerate(cam["to_world"]):
        for j, v in enumerate(row):
            if not _finite(v):
                yield cam_name, f"to_world[{i}][{j}]", f"must be finite, got {v!r}"
    pol = cam.get("polarizer")
    if pol is not None and not _finite(pol["angle"]):
        yield cam_name, "polarizer.angle", f"must be a finite angle in degrees, got {pol['angle']!r}"
    env = scene.get("environment")
    if env:
        for field, msg in spectra.check(env["radiance"], "radiance"):
            yield "environment", field, msg
    names = set()
    for obj in scene["objects"]:
        name = obj["name"]
        if name in names:
            yield name, "name", "is used by two objects"
        names.add(name)
        yield from ((name, f, m) for f, m in _shape_problems(obj["shape"], scene.get("_base_dir")))
        bsdf = obj.get("bsdf")
        if bsdf:
            yield from ((name, "bsdf." + f, m) for f, m in bsdf_problems(bsdf))
        em = obj.get("emitter")
        if em:
            key = "irradiance" if em.get("type") == "collimated" else "radiance"
            yield from ((name, "emitter." + f, m) for f, m in spectra.check(em[key], key))
            if em.get("type") == "collimated" and obj["shape"]["type"] != "rectangle":
                yield name, "emitter.type", "a collimated emitter must be a rectangle (it emits along its normal)"
        if not bsdf and not em:
            yield name, "bsdf", "object has neither a BSDF nor an emitter annotation"


def _shape_problems(shape, base_dir):
    for key in ("to_world",):
        for i, row in enumerate(shape.get(key, [])):
            for j, v in enumerate(row):
                if not _finite(v):
                    yield f"shape.{key}[{i}][{j}]", f"must be finite, got {v!r}"
    if shape["type"] == "sphere":
        if not _finite(shape["radius"]) or shape["radius"] <= 0:
            yield "shape.radius", f"must be > 0, got {shape['radius']!r}"
        if not all(_finite(c) for c in shape["center"]):
            yield "shape.center", f"must be finite, got {shape['center']!r}"
    if shape["type"] == "mesh":
        if "file" in shape:
            path = Path(shape["file"])
            if not path.is_absolute() and base_dir:
                path = Path(base_dir) / path
            if not path.is_file():
                yield "shape.file", f"mesh file not found: {path}"
        else:
            if not shape["faces"] or not shape["vertices"]:
                yield "shape.faces", "mesh has no faces (missing mesh data)"
            n = len(shape["vertices"])
            if any(i >= n for f in shape["faces"] for i in f):
                yield "shape.faces", f"face index out of range (mesh has {n} vertices)"
            if not all(_finite(c) for v in shape["vertices"] for c in v):
                yield "shape.vertices", "must be finite"


def bsdf_problems(bsdf):
    kind = bsdf["type"]
    if kind == "diffuse":
        problems = list(spectra.check(bsdf["reflectance"], "reflectance"))
        yield from problems
        if not problems:
            wl = spectra.cie_1931_cmfs()[0]
            values = spectra.evaluate(bsdf["reflectance"], wl)
            if values.max() > 1.0:
                i = int(values.argmax())
                yield "reflectance", (f"a diffuse reflectance above 1 creates energy: {values[i]:.4g} at "
                                      f"{wl[i]:g} nm (360-830 nm)")
            elif bsdf.get("fluorescence") is not None:
                rho = bsdf["reflectance"]
                yield from fluorescence.problems(bsdf["fluorescence"], lambda wl: spectra.evaluate(rho, wl))
    if kind == "conductor":
        if "material" in bsdf and bsdf["material"] not in spectra.NAMED_CONDUCTORS:
            yield "material", (f"unknown conductor {bsdf['material']!r} "
                               f"(known: {', '.join(spectra.NAMED_CONDUCTORS)})")
        for key in ("eta", "k"):
            if key in bsdf:
                yield from spectra.check(bsdf[key], key)
        film = bsdf.get("thin_film")
        if film is not None:
            d = film["thickness"]
            if not _finite(d) or d < 0:
                yield "thin_film.thickness", f"must be a finite thickness >= 0 nm, got {d!r}"
            for key in ("ior", "ext_ior"):
                v = film.get(key, 1.0)
                if not _finite(v) or v <= 0:
                    yield f"thin_film.{key}", f"must be a finite IOR > 0, got {v!r}"
    if kind == "dielectric":
        yield from dispersion.problems(bsdf.get("int_ior"), "int_ior")  # a number or an IOR model
        v = bsdf.get("ext_ior", ir.AIR_IOR)
        if not _finite(v) or v <= 0:
            yield "ext_ior", f"must be a finite IOR > 0, got {v!r}"
    rough = bsdf.get("roughness")
    if rough is not None:
        a = rough["alpha"]
        if not _finite(a) or a < 0:
            yield "roughness.alpha", f"must be a finite number >= 0, got {a!r}"


def check(scene):
    """Raise SceneError listing every problem of ``scene`` (an IR dict); return it otherwise."""
    name = scene.get("name", "?") if isinstance(scene, dict) else "?"
    if not isinstance(scene, dict):
        raise SceneError(name, [("scene", "(root)", "a scene must be a JSON object")])
    if scene.get("format") != ir.FORMAT or scene.get("version") != ir.VERSION:
        raise SceneError(name, [("scene", "version", f"expected format {ir.FORMAT!r} version {ir.VERSION}, "
                                 f"got {scene.get('format')!r} version {scene.get('version')!r}")])
    data = {k: v for k, v in scene.items() if not k.startswith("_")}
    problems = list(_schema_problems(data))
    if problems:
        raise SceneError(name, problems)
    problems = list(_value_problems(scene))
    if problems:
        raise SceneError(name, problems)
    return scene
