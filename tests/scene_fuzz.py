"""Hostile scenes for property-based tests (tests/hostile/test_fuzz_scenes.py) and the long fuzzing run
(benchmarks/fuzz_scenes.py).

Two sources of scenes:
- ``schema_scenes()``: anything exporters/schema/scene.schema.json admits (hypothesis-jsonschema),
  names and free text included;
- ``mutated_scenes()``: a golden scene with some of its values replaced by hostile ones (path
  walks, newlines and comment terminators of every export format, control characters, reserved
  names, huge and non-finite numbers, wrong types, nesting), names and mesh files most often.

``check(text, root)`` pushes one scene (the JSON text of an IR file) through load -> validate ->
every writer inside ``root`` and returns what happened: "invalid" (a SceneError naming scene,
object and field) or "exported" (every export parsed and stayed in its folder). Anything else
raises AssertionError (or the unexpected exception), which is what a fuzzer reports.
"""
import functools
import hashlib
import json
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from hypothesis import strategies as st

from spectral_bench.exporters import art_writer, ir_json, luxcore_writer, mitsuba_writer, names, pbrt_writer, rgb_scene, validate

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "golden"

HOSTILE_TEXT = [
    "..", ".", "", " ", "../../../../escaped/light", "../x", "/tmp/absolute", "a/b", "a\\b", "C:\\x",
    "light\n__attribute__((constructor)) static void pwn(void) { system(\"touch pwned\"); }\n//",
    "x\nscene.lights.injected.type = \"sky2\"", " --> <emitter type=\"point\"/> <!-- ", "--", "a--b", "*/ int x; /*",
    "end\\", "\x00", "a\rb", "tab\there", "\u2028", "metrics.json", "report.html", "sweeps", "CON", "nul.txt", "Würfel",
    "Key Light", "x" * 65, "x" * 5000, "$spp", "${seed}", "%s%n", "'\"", "<svg onload=alert(1)>", "-leading", ".hidden",
    "environment", "camera",
]
HOSTILE_NUMBERS = [0, -1, -5, 1, 2 ** 31, 10 ** 12, 100000, 16385, 1e308, -1e308, 1e-320, float("nan"), float("inf"),
                   -float("inf"), 0.5, True, None]
VALID_NAMES = st.from_regex(r"\A[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}\Z")
NAME_PATHS = [("name",), ("case",), ("camera", "name")]


@functools.lru_cache(maxsize=1)
def _golden_texts():
    return {p.stem: p.read_text() for p in sorted((GOLDEN / "ir").glob("*.json"))}


def golden_scenes():
    return {name: json.loads(text) for name, text in _golden_texts().items()}


def _paths(node, prefix=()):
    """Every path into a JSON tree (containers and leaves)."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _set(tree, path, value):
    if not path:
        return value
    node = tree
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return tree


def hostile_values():
    json_leaf = st.one_of(st.none(), st.booleans(), st.integers(-2 ** 40, 2 ** 40),
                          st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20))
    nested = st.recursive(json_leaf, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                              st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                          max_leaves=12)
    return st.one_of(st.sampled_from(HOSTILE_TEXT), st.sampled_from(HOSTILE_NUMBERS), st.text(max_size=80), nested)


@st.composite
def mutated_scenes(draw):
    """A golden scene with 1-3 values replaced; names and mesh files are chosen most often."""
    texts = _golden_texts()
    scene = json.loads(texts[draw(st.sampled_from(sorted(texts)))])
    for _ in range(draw(st.integers(1, 3))):
        objects = scene.get("objects") if isinstance(scene.get("objects"), list) else []
        name_paths = NAME_PATHS + [("objects", i, "name") for i in range(len(objects))]
        if draw(st.booleans()):
            path = draw(st.sampled_from(name_paths))
            value = draw(st.one_of(st.sampled_from(HOSTILE_TEXT), st.text(max_size=70), VALID_NAMES))
        elif draw(st.integers(0, 9)) == 0 and isinstance(scene.get("objects"), list) and scene["objects"]:
            i = draw(st.integers(0, len(scene["objects"]) - 1))
            path = ("objects", i, "shape")
            value = {"type": "mesh", "file": draw(st.sampled_from(HOSTILE_TEXT + ["mesh.ply", "mesh.obj", "scene.json"]))}
        else:
            paths = list(_paths(scene))
            path = draw(st.sampled_from(paths[1:]))
            value = draw(hostile_values())
        try:
            scene = _set(scene, path, value)
        except (KeyError, IndexError, TypeError):  # an earlier replacement removed the path
            pass
    return scene


def schema_scenes():
    """The schema's scenes, the strategy built when first drawn from (st.deferred): building it
    (hypothesis-jsonschema's from_schema) takes about 0.5 s, which every pytest-xdist worker paid
    while collecting tests/hostile/test_fuzz_scenes.py, where it is an argument of @given."""
    def build():
        from hypothesis_jsonschema import from_schema
        return from_schema(validate.schema())
    return st.deferred(build)


def scene_text(scene):
    return json.dumps(scene, allow_nan=True)


# -- checking one scene -------------------------------------------------------------------------
def snapshot(root):
    """{relative path: sha256 or 'dir'} of everything under ``root`` (links not followed)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[os.path.relpath(os.path.join(dirpath, d), root)] = "dir"
        for f in filenames:
            p = os.path.join(dirpath, f)
            out[os.path.relpath(p, root)] = hashlib.sha256(Path(p).read_bytes()).hexdigest() if not os.path.islink(p) else "link"
    return out


def _inside(path, folder):
    path, folder = Path(path).resolve(), Path(folder).resolve()
    return path == folder or folder in path.parents


def _tree_inside(folder):
    for dirpath, dirnames, filenames in os.walk(folder):
        for f in dirnames + filenames:
            p = Path(dirpath) / f
            assert not p.is_symlink(), f"an export wrote a link: {p}"
            assert _inside(p, folder), p


_ART_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_ART_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')


def art_vocabulary():
    """Identifiers the ART writer emits: those of every golden .arm and of the writer's source."""
    words = set(_ART_IDENT.findall((ROOT / "exporters" / "art_writer.py").read_text()))
    for p in (GOLDEN / "art").glob("*/scene.arm"):
        words |= set(_ART_IDENT.findall(_art_code(p.read_text())))
    return words


_NUMBER = re.compile(r"(?<![A-Za-z0-9_])[0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?")


def _art_code(text):
    """The .arm text without its // comments, string literals and numbers."""
    lines = []
    for line in text.splitlines():
        line = _ART_STRING.sub('""', line)
        lines.append(_NUMBER.sub("0", line.split("//", 1)[0]))
    return "\n".join(lines)


def check_art(path, vocabulary):
    text = Path(path).read_text()
    for line in text.splitlines():
        if "//" in line:
            comment = line.split("//", 1)[1]
            assert re.fullmatch(r"[ A-Za-z0-9_.,:;()\[\]+=%/'?*-]*", comment) and not comment.endswith("\\"), line
    for s in _ART_STRING.findall(text):
        assert re.fullmatch(r'"meshes/[A-Za-z0-9_][A-Za-z0-9_.-]*\.ply"', s), f"unexpected string in .arm: {s}"
        assert _inside(Path(path).parent / s.strip('"'), Path(path).parent)
    unknown = {w for w in _ART_IDENT.findall(_art_code(text))
               if w not in vocabulary and not re.fullmatch(r"obj\d+(?:_points)?", w)}
    assert not unknown, f"identifiers outside the ART writer's grammar: {sorted(unknown)[:10]}"


XML_TAGS = {"scene", "default", "integrator", "integer", "float", "string", "boolean", "spectrum", "rgb", "point", "vector",
            "sensor", "sampler", "film", "rfilter", "emitter", "shape", "bsdf", "transform", "matrix", "lookat", "ref"}


def check_mitsuba(path, scene):
    folder = Path(path).parent
    root = ET.parse(path).getroot()  # raises on anything an injected comment terminator broke
    tags = {el.tag for el in root.iter() if isinstance(el.tag, str)}
    assert tags <= XML_TAGS, f"unexpected elements {tags - XML_TAGS}"
    shapes = [el for el in root if el.tag == "shape"]
    assert len(shapes) == len(scene["objects"]), "a shape was injected or lost"
    emitters = len([el for el in root.iter("emitter")])
    expected = sum(1 for o in scene["objects"] if o.get("emitter")) + (1 if scene.get("environment") else 0)
    assert emitters == expected, f"{emitters} emitters for {expected} in the IR"
    for el in root.iter():
        value = el.get("filename") or (el.get("value") if el.get("name") in ("filename", "reradiation") else None)
        if value is not None:
            assert _inside(folder / value, folder) and (folder / value).is_file(), value


PBRT_DIRECTIVES = {"Transform", "Translate", "Camera", "Sampler", "Integrator", "PixelFilter", "Film", "WorldBegin",
                   "LightSource", "AreaLightSource", "AttributeBegin", "AttributeEnd", "Material", "Shape"}
_PBRT_TOKEN = re.compile(r'\s*(?:("[^"\n]*")|([\[\]])|([-+0-9.eE]+)|([A-Z][A-Za-z]*)|(true|false))')


def check_pbrt(path, scene):
    """scene.pbrt: comments of the safe characters only; outside them only the pbrt writer's
    directives, quoted strings, numbers and brackets; one shape per object written and one light per
    emitter, environment and delta light written; every file it names inside the folder."""
    folder = Path(path).parent
    left_out = {o for o, f, _m in pbrt_writer.unsupported(scene)}
    code = []
    for line in Path(path).read_text().splitlines():
        if line.lstrip().startswith("#"):
            assert re.fullmatch(r"\s*# [ A-Za-z0-9_.,:;()\[\]+=%/'?*-]*", line), line
            continue
        code.append(line)
    text, pos, directives, strings = "\n".join(code), 0, [], []
    while pos < len(text):
        m = _PBRT_TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            if text[pos:].strip() == "":
                break
            raise AssertionError(f"outside the pbrt writer's grammar: {text[pos:pos + 60]!r}")
        if m.group(4):
            assert m.group(4) in PBRT_DIRECTIVES, f"unexpected directive {m.group(4)}"
            directives.append(m.group(4))
        if m.group(1):
            strings.append(m.group(1).strip('"'))
        pos = m.end()
    written = [o for o in scene["objects"] if o["name"] not in left_out]
    # a one-sided rectangle is written with its black closed backing (one more Shape), as the
    # writer's approximations list says; nothing else adds a shape
    backed = {o for o, f, _m in pbrt_writer.approximations(scene) if f == "bsdf.type"}
    backings = sum(1 for o in written if o["name"] in backed and o["shape"]["type"] == "rectangle")
    assert directives.count("Shape") == len(written) + backings, "a shape was injected or lost"
    lights = sum(1 for o in written if o.get("emitter")) + (1 if scene.get("environment") else 0)
    lights += sum(1 for light in scene.get("lights", []) if light["name"] not in left_out)
    assert directives.count("LightSource") + directives.count("AreaLightSource") == lights
    for value in strings:
        if value.startswith("meshes/"):
            assert _inside(folder / value, folder) and (folder / value).is_file(), value


def check_luxcore(cfg, rgb):
    scn = Path(cfg).parent / "scene.scn"
    objects = set()
    for line in scn.read_text().splitlines() + Path(cfg).read_text().splitlines():
        if line.startswith("#"):
            assert re.fullmatch(r"# [ A-Za-z0-9_.,:;()\[\]+=%/'?*-]*", line), line
            continue
        m = re.fullmatch(r"([a-z][A-Za-z0-9_.]*) = (.*)", line)
        assert m, f"not an SDL property line: {line!r}"
        key = m.group(1)
        o = re.match(r"scene\.(?:objects|shapes|materials)\.([A-Za-z0-9_]+)\.", key)
        if o:
            assert re.fullmatch(r"obj\d+(?:_black|_front)?", o.group(1)), key
            if key.startswith("scene.objects."):
                objects.add(o.group(1))
    assert len(objects) == len(rgb["objects"])


def check(text, root):
    """Push one IR file's text through load -> validate -> writers inside ``root``; returns
    "invalid" or "exported"."""
    return check_detailed(text, root)[0]


def check_detailed(text, root):
    """check(), returning (outcome, the fields refused: [(object, field)] or [])."""
    root = Path(root)
    src = root / "in" / "scene.json"
    src.parent.mkdir(parents=True, exist_ok=True)
    src.write_text(text)
    out = root / "out"
    before = snapshot(root)
    try:
        scene = ir_json.load(src)
    except validate.SceneError as err:
        assert err.problems, "a SceneError without problems"
        for problem in err.problems:
            assert len(problem) == 3 and all(isinstance(p, str) and p for p in problem), problem
        assert "scene " in str(err) and str(src) in str(err), str(err)[:200]  # names the file and the scene
        assert snapshot(root) == before, "a scene that failed validation wrote files"
        return "invalid", [(o, f) for o, f, _ in err.problems]
    name = names.file_stem(scene["name"])
    path = mitsuba_writer.write(scene, out / name / "mitsuba")
    check_mitsuba(path, scene)
    arm, _missing = art_writer.write(scene, out / name / "art")
    check_art(arm, art_vocabulary_cached())
    for o, f, m in pbrt_writer.unsupported(scene):  # what pbrt-v4 cannot express: named object, field, why
        assert all(isinstance(x, str) and x for x in (o, f, m)), (o, f, m)
    check_pbrt(pbrt_writer.write(scene, out / name / "pbrt"), scene)
    json_path = ir_json.write(scene, out / name / "json" / f"{name}.json")
    back = ir_json.load(json_path)  # the self-contained file reads back to the same scene
    assert {k: v for k, v in back.items() if not k.startswith("_")} == {k: v for k, v in scene.items() if not k.startswith("_")}
    try:
        rgb = rgb_scene.build(scene, ("ggx", "beckmann"), approximate=True)
    except ValueError as exc:  # what even an approximation cannot express: "object.field: why" (unsupported)
        assert re.match(r"[^:]+\.[^:]+: ", str(exc)), repr(exc)
    else:
        cfg = luxcore_writer.write(rgb, out / name / "luxcore")
        check_luxcore(cfg, rgb)
    after = snapshot(root)
    changed = {p for p in set(before) | set(after) if before.get(p) != after.get(p)}
    outside = {p for p in changed if not (p == "out" or p.startswith("out" + os.sep))}
    assert not outside, f"written outside OUT: {sorted(outside)[:5]}"
    _tree_inside(out)
    return "exported", []


_VOCAB = {}


def art_vocabulary_cached():
    if "v" not in _VOCAB:
        _VOCAB["v"] = art_vocabulary()
    return _VOCAB["v"]


# -- ordinary .blend files (issue 40) -------------------------------------------------------------
# Scenes as a Blender user makes them, with the values Blender allows: lights of every type with
# sizes, scales and powers of 0 (and negative, huge, tiny), objects scaled to 0 or flattened, faces
# of zero area, meshes without faces, materials linked to image textures, environment maps whose file
# is missing, a folder or empty, Blackbody nodes at 0 K. tests/blend_builder.py turns a list of them
# into one .blend (one bpy child per file, not per scene); ``check_blend`` runs batch/run.py on it.
SCALES = [(1, 1, 1), (0, 0, 0), (1, 1, 0), (0, 1, 1), (1e-9, 1e-9, 1e-9), (-1, 1, 1), (2, 0.5, 1)]
POWERS = [0.0, 10.0, -5.0, 1e30, 1e-30]
SIZES = [0.0, 1e-9, 0.5, 1e4]
IMAGES = ["missing", "folder", "empty", "packed"]  # paths: see image_path
TEMPERATURES = [None, 0.0, -100.0, 5000.0]


def _light(kind):
    settings = {"energy": st.sampled_from(POWERS)}
    if kind == "AREA":
        settings.update(shape=st.sampled_from(["SQUARE", "RECTANGLE", "DISK", "ELLIPSE"]), size=st.sampled_from(SIZES),
                        size_y=st.sampled_from(SIZES))
    elif kind == "SPOT":
        settings.update(spot_size=st.sampled_from([0.0175, 1.0, 3.14159]), spot_blend=st.sampled_from([0.0, 1.0]),
                        shadow_soft_size=st.sampled_from([0.0, 0.5]))
    elif kind == "SUN":
        settings.update(angle=st.sampled_from([0.0, 0.1]))
    else:
        settings.update(shadow_soft_size=st.sampled_from([0.0, 0.5]))
    return st.fixed_dictionaries({"type": st.just(kind), "settings": st.fixed_dictionaries(settings),
                                  "scale": st.sampled_from(SCALES), "blackbody": st.sampled_from(TEMPERATURES)})


def _material():
    return st.one_of(st.none(), st.fixed_dictionaries({"kind": st.just("principled"),
                                                       "emission": st.sampled_from([-1.0, 0.0, 5.0])}),
                     st.fixed_dictionaries({"kind": st.just("image"), "path": st.sampled_from(IMAGES)}),
                     st.just({"kind": "mix"}))


def _object():
    return st.fixed_dictionaries({"mesh": st.sampled_from(["quad", "cube", "degenerate", "no_faces"]),
                                  "scale": st.sampled_from(SCALES), "sphere": st.booleans(), "material": _material()})


def _world():
    return st.one_of(st.none(), st.fixed_dictionaries({
        "strength": st.sampled_from([-1.0, 0.0, 1.0, 1e30]), "colour": st.sampled_from([(0.2, 0.3, 0.4), (0, 0, 0)]),
        "image": st.one_of(st.none(), st.sampled_from(IMAGES)), "blackbody": st.sampled_from(TEMPERATURES)}))


@st.composite
def blend_scenes(draw, n=4):
    """A list of ``n`` scenes for tests/blend_builder.py, named case0... (objects caseK_oJ, lights
    caseK_lJ: Blender's object names are the file's); image paths are tokens (IMAGES)."""
    scenes = []
    for k in range(n):
        lights = draw(st.lists(st.sampled_from(["POINT", "SPOT", "SUN", "AREA"]).flatmap(_light), max_size=3))
        objects = draw(st.lists(_object(), min_size=1, max_size=3))
        scenes.append({"name": f"case{k}", "world": draw(_world()),
                       "objects": [dict(o, name=f"case{k}_o{j}") for j, o in enumerate(objects)],
                       "lights": [dict(light, name=f"case{k}_l{j}") for j, light in enumerate(lights)]})
    return scenes


def image_path(token, root):
    """The path an image token stands for: a file that does not exist, a folder, nothing, packed."""
    return {"missing": str(Path(root) / "no_such_image.exr"), "folder": str(Path(root)), "empty": "",
            "packed": "packed"}[token]


def _with_paths(specs, root):
    out = json.loads(json.dumps(specs))
    for sc in out:
        for o in sc["objects"]:
            if o.get("material") and o["material"]["kind"] == "image":
                o["material"]["path"] = image_path(o["material"]["path"], root)
        if sc.get("world") and sc["world"].get("image"):
            sc["world"]["image"] = image_path(sc["world"]["image"], root)
    return out


SCENE_PROBLEM = re.compile(r"scene '([^']+)', object '([^']*)', field '([^']*)': ")


def check_blend(specs, root, timeout=180):
    """Build one .blend of ``specs`` (a bpy child) and export it with batch/run.py (a child, under
    ``timeout``: a hang fails); returns {scene: status}. Asserts: an exit status of 0-3, no
    traceback, every scene of the file recorded under its own name (one bad scene fails alone),
    every failure naming scene, object and field (none a fault of the exporter), every exported
    JSON loading back."""
    return check_blends([specs], root, timeout)[0]


def check_blends(files, root, timeout=180):
    """``check_blend`` for many files at the cost of two child start-ups: every .blend built by one
    bpy child (tests/blend_builder.py takes many pairs), all exported by one batch/run.py (one -i
    each, under ``timeout`` per file). The scenes of file I are renamed ``fI_<name>`` (a run's
    scene names are unique: outputs are written per scene name), each file's paths (IMAGES) in its
    own folder ROOT/fI. Returns [{scene name as in ``files``: status}], one per file; asserts for
    every file and scene what ``check_blend`` asserts."""
    import subprocess
    import sys
    root = Path(root)
    files = [[dict(sc, name=sc["name"] if len(files) == 1 else f"f{i}_{sc['name']}") for sc in specs]
             for i, specs in enumerate(files)]
    pairs = []
    for i, specs in enumerate(files):
        folder = root if len(files) == 1 else root / f"f{i}"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "spec.json").write_text(json.dumps(_with_paths(specs, folder)))
        pairs += [str(folder / "spec.json"), str(folder / "fuzz.blend")]
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "blend_builder.py"), *pairs],
                          capture_output=True, text=True, timeout=timeout * len(files))
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = root / "out"
    proc = subprocess.run([sys.executable, str(ROOT / "batch" / "run.py"), *sum((["-i", b] for b in pairs[1::2]), []),
                           "--export-only", "--format", "json", "--format", "mitsuba", "-o", str(out)],
                          capture_output=True, text=True, timeout=timeout * len(files), cwd=ROOT)
    assert proc.returncode in (0, 1, 2, 3), (proc.returncode, proc.stderr[-3000:])
    assert "Traceback" not in proc.stderr + proc.stdout, proc.stderr[-3000:]
    runs = json.loads((out / "metrics.json").read_text())["runs"]
    statuses = {}
    for r in runs:
        statuses.setdefault(r["scene"], set()).add(r["status"])
        if r["status"] == "failed":
            m = SCENE_PROBLEM.search(r["reason"] or "")
            assert m and m.group(1) == r["scene"] and m.group(3) not in ("", "(file)"), r["reason"]
            assert "a fault of the exporter" not in r["reason"], r["reason"]
    assert set(statuses) == {s["name"] for specs in files for s in specs}, (sorted(statuses), proc.stderr[-2000:])
    for name, status in statuses.items():
        if "failed" not in status:
            ir_json.load(out / name / "json" / f"{name}.json")  # what was exported loads back
    verdict = {name: "failed" if "failed" in s else "exported" for name, s in statuses.items()}
    return [{(sc["name"] if len(files) == 1 else sc["name"].split("_", 1)[1]): verdict[sc["name"]] for sc in specs}
            for specs in files]
