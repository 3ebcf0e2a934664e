"""scenes.blend -> IR -> JSON -> IR, against the golden files; Blender-side errors.

Each test that edits the Blender data runs in a child process (bpy has one global state)."""
import json

import pytest

from conftest import ALL_SCENES, GOLDEN, REFLECTANCE, bpy_script
from spectral_bench.exporters import inline_data, ir_json

pytestmark = pytest.mark.slow  # every test here costs over ~1 s of CPU, its children and module fixtures counted (benchmarks/TESTS.md)


@pytest.fixture(scope="module")
def extracted():
    return bpy_script("print(json.dumps({n: (ir_json.dumps(r) if isinstance(r, dict) else str(r)) for n, r in results.items()}))")


def test_scenes_blend_has_every_case(extracted):
    assert sorted(extracted) == ALL_SCENES
    cases = {n: json.loads(extracted[n])["case"] for n in ALL_SCENES}
    assert {n for n, c in cases.items() if c == "reflectance"} == set(REFLECTANCE)
    assert cases["macbeth_chart_D65"] == "spectral_accuracy" and cases["polarizing_spheres"] == "polarization"


def test_polarization_annotations_reach_the_ir(extracted):
    plane = json.loads(extracted["polarizing_plane_90"])
    assert plane["camera"]["polarizer"] == {"angle": 90.0}
    assert "polarization" in plane["needs"] and "spectral" in plane["needs"]
    spheres = json.loads(extracted["polarizing_spheres"])
    assert spheres["render"]["output"] == "stokes" and spheres["needs"] == ["polarization"]
    chart = json.loads(extracted["macbeth_chart_D50"])
    assert chart["environment"]["radiance"] == {"type": "named", "name": "cie_d50", "scale": 1.0}
    assert sum(1 for o in chart["objects"] if o["name"].startswith("patch_")) == 24


@pytest.mark.parametrize("name", ALL_SCENES)
def test_extraction_matches_golden_file(extracted, name):
    """A change to scenes.blend must show up as a reviewable diff of golden/ir/ (regenerate
    with scripts/update_golden.py). Golden files are written as every scene file is: in the
    self-contained form (exporters/inline_data.py)."""
    assert ir_json.dumps(inline_data.embed(json.loads(extracted[name]))) == (GOLDEN / f"{name}.json").read_text()


@pytest.mark.parametrize("name", ALL_SCENES)
def test_ir_json_ir_is_lossless(extracted, name, tmp_path):
    scene = json.loads(extracted[name])
    back = ir_json.load(ir_json.write(scene, tmp_path / f"{name}.json"))
    back.pop("_base_dir")
    assert back == scene
    assert ir_json.dumps(back) == extracted[name]


def test_copper_geometry_follows_the_thesis(extracted):
    sc = json.loads(extracted["ggx_copper_70"])
    plate = next(o for o in sc["objects"] if o["name"] == "copper_plate_70")
    m = plate["shape"]["to_world"]
    # rotated 70 degrees about x: the normal (third column) is (0, -sin 70, cos 70)
    assert [m[0][2], m[1][2], m[2][2]] == pytest.approx([0.0, -0.939693, 0.34202], abs=1e-6)
    light = next(o for o in sc["objects"] if o["emitter"])
    lm = light["shape"]["to_world"]
    assert lm[2][2] == pytest.approx(-1.0) and lm[2][3] == pytest.approx(1.5)  # faces down at z = 1.5
    assert light["emitter"]["radiance"] == {"type": "named", "name": "cie_d65", "scale": 4.0}
    assert sc["camera"]["fov"] == pytest.approx(34.0221, abs=1e-4)  # Mitsuba's default 50 mm camera


@pytest.fixture(scope="module")
def edited():
    """The Blender-side edits of the tests below, made in one bpy child in this order (scenes.blend
    read once, not once per test): a mesh object and an empty mesh in ggx_glass; then ggx_copper_60
    with a negative roughness alone, then also with the material kind NONE on its floor (the first
    edit is part of the second; that material, grey_0.5, is shared with ggx_glass, so that edit
    comes last). Each step's result is its test's input."""
    return bpy_script("""
        def problems(sc):
            try:
                extract_blender.extract_scene(sc)
                return None
            except validate.SceneError as e:
                return {"problems": e.problems, "text": str(e)}
        out = {}
        sc = bpy.data.scenes["ggx_glass"]
        mesh = bpy.data.meshes.new("tri")
        mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)], [], [(0, 1, 3, 2)])
        obj = bpy.data.objects.new("quad", mesh)
        obj.location = (0, 0, -2)
        mesh.materials.append(bpy.data.materials["grey_0.5"])
        sc.collection.objects.link(obj)
        ir = extract_blender.extract_scene(sc)
        quad = next(o for o in ir["objects"] if o["name"] == "quad")
        empty = bpy.data.objects.new("empty_mesh", bpy.data.meshes.new("nothing"))
        empty.data.materials.append(bpy.data.materials["grey_0.5"])
        sc.collection.objects.link(empty)
        err = problems(sc)
        out["mesh"] = {"quad": quad, "err": err and err["problems"]}
        sc = bpy.data.scenes["ggx_copper_60"]
        sc.objects["copper_plate_60"].active_material.spectral_bench.alpha = -0.5
        out["negative_roughness"] = problems(sc)
        sc.objects["floor"].active_material.spectral_bench.kind = "NONE"
        out["errors"] = problems(sc)
        print(json.dumps(out))
    """)


def test_blender_side_errors_name_scene_object_field(edited):
    out = edited["errors"]
    fields = {(o, f) for o, f, _ in out["problems"]}
    # the floor's material without an annotation is converted from its nodes (a warning), not refused
    assert fields == {("copper_plate_60", "bsdf.roughness.alpha")}
    assert "ggx_copper_60" in out["text"]


def test_negative_roughness_from_blender_is_rejected_with_its_field(edited):
    out = edited["negative_roughness"]
    assert ["copper_plate_60", "bsdf.roughness.alpha", "must be a finite number >= 0, got -0.5"] in out["problems"]


def test_mesh_objects_export_with_their_triangles_and_a_missing_mesh_is_named(edited):
    out = edited["mesh"]
    assert out["quad"]["shape"]["type"] == "mesh"
    assert len(out["quad"]["shape"]["faces"]) == 2 and len(out["quad"]["shape"]["vertices"]) == 4
    assert out["quad"]["shape"]["to_world"][2][3] == -2.0
    assert ["empty_mesh", "data", "mesh has no faces (missing mesh)"] in out["err"]
