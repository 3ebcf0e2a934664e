"""Names and free text are data (issue 18's findings, one test each): nothing is written outside
the outputs folder, no text escapes its comment in any export format, bounds are checked with the
field named, mesh files stay inside the scene's folder and are parsed at validation."""
import copy
import json
import xml.etree.ElementTree as ET

import pytest

import scene_fuzz
from conftest import metrics, run_batch, write_hand_made_metrics, write_scene
from spectral_bench.exporters import art_writer, ir_json, luxcore_writer, mitsuba_writer, names, pbrt_writer, rgb_scene, validate

INJECTION = "reflectance\n__attribute__((constructor)) static void pwn(void) { system(\"touch pwned\"); }\n//"


def _obj(scene, name):
    return next(o for o in scene["objects"] if o["name"] == name)


def _problems(scene, tmp_path):
    path = ir_json.write(scene, tmp_path / "in" / "scene.json")
    with pytest.raises(validate.SceneError) as info:
        ir_json.load(path)
    return [(o, f) for o, f, _ in info.value.problems], str(info.value)


@pytest.mark.parametrize("bad", ["../../../../escaped/light", "..", ".", "a/b", "a\\b", "light\nx", "-x", "", "x" * 65,
                                 "CON", "environment", "Key Light"])
def test_an_object_name_that_is_not_a_name_is_refused_naming_scene_object_field(golden, tmp_path, bad):
    sc = copy.deepcopy(golden["ggx_copper_50"])
    _obj(sc, "light")["name"] = bad
    found, text = _problems(sc, tmp_path)
    assert ("objects[2]", "name") in found, found
    assert "ggx_copper_50" in text and "name" in text


@pytest.mark.parametrize("bad", ["..", ".", "../up", "metrics.json", "report.html", "sweeps", "nul", "a\nb", "é"])
def test_a_scene_name_that_would_name_a_path_or_an_output_is_refused(golden, tmp_path, bad):
    sc = copy.deepcopy(golden["ggx_copper_50"])
    sc["name"] = bad
    found, _ = _problems(sc, tmp_path)
    assert ("scene", "name") in found, found


def test_a_trailing_newline_does_not_slip_through_the_schema_pattern(golden, tmp_path):
    """jsonschema applies "pattern" with re.search, where "$" matches before a final newline."""
    sc = copy.deepcopy(golden["ggx_copper_50"])
    sc["case"] = "reflectance\n"
    found, _ = _problems(sc, tmp_path)
    assert ("scene", "case") in found


def test_names_differing_only_in_case_are_refused(golden, tmp_path):
    sc = copy.deepcopy(golden["ggx_copper_50"])
    _obj(sc, "light")["name"] = "FLOOR"
    found, text = _problems(sc, tmp_path)
    assert ("FLOOR", "name") in found and "ignoring case" in text


@pytest.mark.parametrize("field, value", [("width", 100000), ("height", 0), ("spp", 10 ** 12), ("spp", -5),
                                          ("max_depth", -5), ("max_depth", 0), ("max_depth", 5000)])
def test_render_bounds_are_checked_at_validation_with_the_field(golden, tmp_path, field, value):
    sc = copy.deepcopy(golden["ggx_copper_50"])
    sc["render"][field] = value
    found, _ = _problems(sc, tmp_path)
    assert ("render", field) in found, found


def test_a_huge_image_is_refused_before_anything_renders(golden, tmp_path):
    sc = copy.deepcopy(golden["ggx_copper_50"])
    sc["render"]["width"] = sc["render"]["height"] = 16384
    found, text = _problems(sc, tmp_path)
    assert ("render", "width") in found and "8192 x 8192" in text


@pytest.mark.parametrize("file, why", [("/etc/hostname", "relative"), ("../outside.ply", "relative"),
                                       ("sub/../../outside.ply", "relative"), ("link.ply", "outside"),
                                       ("not_a_mesh.ply", "not a readable"), ("scene.json", ".ply or .obj"),
                                       ("empty.obj", "no faces"), ("missing.ply", "not found")])
def test_mesh_files_stay_in_the_scene_folder_and_are_parsed_at_validation(golden, tmp_path, file, why):
    sc = copy.deepcopy(golden["ggx_copper_50"])
    _obj(sc, "floor")["shape"] = {"type": "mesh", "file": file}
    folder = tmp_path / "in"
    folder.mkdir()
    (tmp_path / "outside.ply").write_text("not read")
    (folder / "not_a_mesh.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
    (folder / "empty.obj").write_text("# nothing\n")
    (folder / "link.ply").symlink_to(tmp_path / "outside.ply")
    found, text = _problems(sc, tmp_path)
    assert ("floor", "shape.file") in found, found
    assert why in text, text


def test_writers_refuse_a_path_name_even_when_validation_was_skipped(golden, tmp_path):
    """Writers never trust that validation ran: a name reaches a file name only through
    names.file_stem."""
    sc = copy.deepcopy(golden["dispersion_prism"])
    _obj(sc, "prism")["name"] = "../../../../escaped/prism"
    before = scene_fuzz.snapshot(tmp_path)
    for write in (lambda: mitsuba_writer.write(sc, tmp_path / "out" / "m"), lambda: art_writer.write(sc, tmp_path / "out" / "a"),
                  lambda: pbrt_writer.write(sc, tmp_path / "out" / "p")):
        with pytest.raises(ValueError, match="refusing"):
            write()
    assert not any(p.startswith("escaped") or "escaped" in p for p in set(scene_fuzz.snapshot(tmp_path)) - set(before))
    assert not (tmp_path.parent / "escaped").exists()


def test_free_text_cannot_leave_its_comment_in_any_format(golden, tmp_path):
    """Writers called on an unvalidated IR whose case and object names carry newlines and comment
    terminators: the .arm stays within the writer's grammar, the XML parses to the same elements,
    the SDL has only property lines."""
    sc = copy.deepcopy(golden["ggx_copper_50"])
    sc["case"] = INJECTION + " --> <emitter type=\"point\"/> <!-- "
    _obj(sc, "light")["name"] = "light"  # file names stay valid; the comments carry the text
    sc["description"] = "*/ --> \n# scene.lights.x.type = \"sky2\""
    arm, _ = art_writer.write(sc, tmp_path / "art")
    scene_fuzz.check_art(arm, scene_fuzz.art_vocabulary())
    assert "system" not in arm.read_text().split("{", 1)[1].split("//")[0]
    xml = mitsuba_writer.write(sc, tmp_path / "mitsuba")
    scene_fuzz.check_mitsuba(xml, sc)
    comment = next(c for c in ET.parse(xml, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))).getroot()
                   .iter() if c.tag is ET.Comment)
    assert "-->" not in comment.text and "\n" not in comment.text
    pbrt = pbrt_writer.write(sc, tmp_path / "pbrt")  # pbrt's comments end only at a newline
    code = [line for line in pbrt.read_text().splitlines() if not line.lstrip().startswith("#")]
    assert code == [line for line in pbrt_writer.write(golden["ggx_copper_50"], tmp_path / "pbrt_clean").read_text()
                    .splitlines() if not line.lstrip().startswith("#")]
    rgb = rgb_scene.build(sc, ("ggx", "beckmann"), approximate=True)
    rgb["objects"][0]["name"] = "floor\nscene.lights.injected.type = \"sky2\""
    cfg = luxcore_writer.write(rgb, tmp_path / "luxcore")
    scene_fuzz.check_luxcore(cfg, rgb)
    assert "injected" not in (cfg.parent / "scene.scn").read_text().replace("# floor?scene.lights.injected", "")


@pytest.mark.slow
def test_a_hostile_scene_among_good_ones_fails_alone_and_nothing_leaves_out(golden, tmp_path):
    """The issue's report: an object named ../../../../<folder>/light wrote outside OUT, a case
    with a newline injected code into the .arm. Now the bad scene fails naming its field, the good
    one is exported in every format, and only OUT changes."""
    good = write_scene(tmp_path / "in", golden["ggx_copper_50_isolated"])
    bad_sc = copy.deepcopy(golden["ggx_copper_50"])
    bad_sc["name"] = "hostile"
    _obj(bad_sc, "light")["name"] = f"../../../../{tmp_path.name}/escaped/light"
    bad_sc["case"] = INJECTION
    bad = tmp_path / "in" / "hostile.json"
    bad.write_text(json.dumps(bad_sc))
    before = scene_fuzz.snapshot(tmp_path)
    out = tmp_path / "OUT"
    proc = run_batch("-i", good, bad, "--export-only", "--format", "mitsuba", "--format", "art", "--format", "json",
                     "--format", "luxcore", "--format", "pbrt", "-o", out, timeout=600)
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = metrics(out)["runs"]
    by_scene = {}
    for r in runs:
        by_scene.setdefault(r["scene"], []).append(r)
    good_status = {r["backend"]: r["status"] for r in by_scene["ggx_copper_50_isolated"]}
    assert good_status == {"mitsuba": "ok", "art": "unsupported", "json": "ok", "luxcore": "ok", "pbrt": "ok"}, good_status
    failed = [r for r in runs if r["status"] == "failed"]
    assert failed and all("objects[" in r["reason"] and "name" in r["reason"] for r in failed)
    assert any("case" in r["reason"] for r in failed)
    after = scene_fuzz.snapshot(tmp_path)
    changed = {p for p in set(before) | set(after) if before.get(p) != after.get(p)}
    assert changed and all(p == "OUT" or p.startswith("OUT/") for p in changed), sorted(changed)[:5]
    assert not (tmp_path / "escaped").exists()


@pytest.mark.slow
def test_blender_names_become_safe_ids_with_their_label(tmp_path):
    from conftest import bpy_script
    out = bpy_script("""
        sc = bpy.data.scenes["ggx_copper_50"]
        sc.name = "../my scene"
        bpy.data.objects["light"].name = "Key Light/../x"
        bpy.data.objects["floor"].name = "Würfel"
        ir = extract_blender.extract_scene(sc)
        print(json.dumps({"scene": [ir["name"], ir.get("label")],
                          "objects": [[o["name"], o.get("label")] for o in ir["objects"]]}))
    """)
    assert out["scene"] == ["my_scene", "../my scene"]
    assert ["Key_Light_.._x", "Key Light/../x"] in out["objects"]
    assert ["Wurfel", "Würfel"] in out["objects"]
    assert ["copper_plate_50", None] in out["objects"]
    for name, _label in out["objects"] + [out["scene"]]:
        assert names.problem(name) is None


def test_a_results_folder_from_elsewhere_cannot_point_the_panel_outside_it(tmp_path):
    """The Results panel reads any outputs folder (batch/run_folder.py): a metrics.json naming its
    scene '../..', or a render or chart outside the folder, gets no image path (nothing outside the
    folder is read, or written beside it as an RGB copy); a path is the record's, never one built
    from a scene or backend name."""
    from spectral_bench.batch import run_folder
    outside = tmp_path / "secret" / "results" / "mitsuba"
    outside.mkdir(parents=True)
    (outside / "render.exr").write_bytes(b"not ours")
    (tmp_path / "secret.png").write_bytes(b"not ours")
    out = tmp_path / "run"
    (out / "ok" / "results" / "mitsuba").mkdir(parents=True)
    (out / "ok" / "results" / "mitsuba" / "render.exr").write_bytes(b"ours")
    runs = [{"scene": "../secret", "backend": "mitsuba", "image": "../secret/results/mitsuba/render.exr"},
            {"scene": "ok", "backend": "../../secret/results/mitsuba", "image": "../secret/results/mitsuba/render.exr"},
            {"scene": "ok", "backend": "mitsuba", "image": "ok/results/mitsuba/render.exr"}]
    sweeps = [{"scene": "../secret", "chart": "../secret.png"}]
    write_hand_made_metrics(out, {"started": "now", "runs": runs, "sweeps": sweeps})
    assert run_folder.job(out, "../secret", "mitsuba").path("render") is None
    assert run_folder.job(out, "ok", "../../secret/results/mitsuba").path("render") is None
    assert run_folder.chart_path(out, "../secret") is None
    assert run_folder.job(out, "ok", "mitsuba").path("render") == out / "ok" / "results" / "mitsuba" / "render.exr"


@pytest.mark.parametrize("where", ["rectangle", "camera", "affine"])
def test_a_degenerate_transform_is_refused_at_validation(golden, tmp_path, where):
    """Found by the long fuzzing run: a rectangle whose to_world flattens it passed validation and
    crashed the RGB export (numpy: singular matrix)."""
    sc = copy.deepcopy(golden["ggx_copper_50"])
    if where == "rectangle":
        _obj(sc, "floor")["shape"]["to_world"][2] = [0.0, 0.0, 0.0, -1.0]
        expected = ("floor", "shape.to_world")
    elif where == "camera":
        sc["camera"]["to_world"] = [[0.0] * 4, [0.0] * 4, [0.0] * 4, [0.0, 0.0, 0.0, 1.0]]
        expected = (sc["camera"]["name"], "to_world")
    else:
        _obj(sc, "light")["shape"]["to_world"][3] = [0.0, 0.0, 1.0, 1.0]
        expected = ("light", "shape.to_world[3]")
    found, _ = _problems(sc, tmp_path)
    assert expected in found, found


@pytest.mark.parametrize("where, value, expected", [
    ("fov", 1e-320, ("glass_camera", "fov")),              # found by the long fuzzing run: ART's zoom became inf
    ("radius", 1e300, ("glass_sphere", "shape.radius")),
    ("center", 1e300, ("glass_sphere", "shape.center")),
    ("to_world", 1e300, ("glass_light", "shape.to_world[0][3]"))])
def test_numbers_that_overflow_a_writer_are_refused(golden, tmp_path, where, value, expected):
    sc = copy.deepcopy(golden["ggx_glass"])
    if where == "fov":
        sc["camera"]["fov"] = value
    elif where == "radius":
        _obj(sc, "glass_sphere")["shape"]["radius"] = value
    elif where == "center":
        _obj(sc, "glass_sphere")["shape"]["center"][0] = value
    else:
        _obj(sc, "glass_light")["shape"]["to_world"][0][3] = value
    found, _ = _problems(sc, tmp_path)
    assert expected in found, found
