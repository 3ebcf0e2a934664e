"""Ordinary .blend files whose values Blender allows load scene by scene (issue 40, items 2 and 3),
through the runner (batch/run.py) on a .blend made with real bpy (tests/blend_builder.py):

- a scene of 70 objects without a material (70 conversion warnings) and one of 70 lights load:
  the list caps are named per list (exporters/validate.py LIST_LIMITS), sized for real scenes, and
  never apply to the exporter's own warnings; a list over its cap is refused naming the list and
  its limit;
- an area light of size 0 (or of zero scale) emits nothing and an object scaled to 0 shows
  nothing: each is dropped with a warning naming object and field; a mesh flattened by a zero scale
  along one axis keeps its geometry (vertices in world space); a light of negative power and a
  Blackbody node below 800 K are converted with a warning;
- an environment texture whose file is missing (or is a folder) fails its own scene, naming scene,
  world and field; every other scene of the file exports.
"""
import json
import subprocess
import sys

import pytest

from conftest import ROOT, metrics, run_batch

QUAD = {"mesh": "quad"}


def make_blend(folder, specs, timeout=300):
    """A .blend of ``specs`` (tests/blend_builder.py), made by one bpy child."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "spec.json").write_text(json.dumps(specs))
    path = folder / "scenes.blend"
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "blend_builder.py"), str(folder / "spec.json"), str(path)],
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0 and path.is_file(), proc.stdout[-2000:] + proc.stderr[-3000:]
    return path


def point(name, **settings):
    return {"name": name, "type": "POINT", "settings": {"energy": 10.0, "shadow_soft_size": 0.0, **settings}}


def area(name, scale=(1, 1, 1), **settings):
    return {"name": name, "type": "AREA", "scale": scale, "settings": {"energy": 50.0, **settings}}


def plain(name, objects=(), lights=(), world=None):
    """A scene: a floor, ``objects``, ``lights`` (a point light by default); each object's name is
    prefixed with the scene's (Blender's object names are the file's)."""
    items = [{"name": "floor", **QUAD}, *objects], list(lights) or [point("key")]
    return {"name": name, "objects": [dict(o, name=f"{name}_{o['name']}") for o in items[0]],
            "lights": [dict(o, name=f"{name}_{o['name']}") for o in items[1]], "world": world}


@pytest.fixture(scope="module")
def blend(tmp_path_factory):
    folder = tmp_path_factory.mktemp("blend_values")
    (folder / "a_folder.exr").mkdir()
    specs = [
        plain("good"),
        plain("many_objects", objects=[{"name": f"pebble_{i:02d}", **QUAD, "scale": (0.05, 0.05, 0.05)}
                                       for i in range(70)]),
        plain("many_lights", lights=[point(f"lamp_{i:02d}", energy=1.0) for i in range(70)]),
        plain("area_size_0", lights=[area("panel", size=0.0), point("key")]),
        plain("disk_size_y_0", lights=[area("oval", shape="ELLIPSE", size=1.0, size_y=0.0), point("key")]),
        plain("area_scaled_0", lights=[area("panel", scale=(0, 0, 0), size=1.0), point("key")]),
        plain("area_flattened", lights=[area("panel", scale=(2, 1, 0), size=1.0), point("key")]),
        plain("object_scaled_0", objects=[{"name": "gone", "mesh": "cube", "scale": (0, 0, 0)},
                                          {"name": "ball", "mesh": "cube", "sphere": True, "scale": (0, 0, 0)}]),
        plain("object_flattened", objects=[{"name": "flat", "mesh": "cube", "scale": (1, 1, 0)}]),
        plain("degenerate_mesh", objects=[{"name": "sliver", "mesh": "degenerate"}]),
        plain("negative_light", lights=[point("dark", energy=-100.0), point("key")],
              objects=[{"name": "sink", **QUAD, "material": {"kind": "principled", "emission": -2.0}}]),
        plain("cold_world", world={"strength": 1.0, "blackbody": 0.0}),
        plain("dark_world", world={"strength": -1.0}),
        plain("missing_sky", world={"strength": 1.0, "image": str(folder / "no_such_sky.exr")}),
        plain("folder_sky", world={"strength": 1.0, "image": str(folder / "a_folder.exr")}),
    ]
    path = make_blend(folder, specs)
    out = folder / "out"
    proc = run_batch("-i", path, "--export-only", "--format", "json", "--format", "mitsuba", "-o", out, timeout=600)
    return {"proc": proc, "out": out, "names": [s["name"] for s in specs], "folder": folder, "path": path}


def exported(blend, scene):
    return json.loads((blend["out"] / scene / "json" / f"{scene}.json").read_text())


def warned(scene_ir):
    """{(object, field): its warnings' messages, one a line}."""
    out = {}
    for w in scene_ir.get("warnings", []):
        out[(w["object"], w["field"])] = out.get((w["object"], w["field"]), "") + w["message"] + "\n"
    return out


@pytest.mark.slow
def test_each_scene_of_the_file_is_exported_or_fails_alone_by_name(blend):
    proc = blend["proc"]
    assert proc.returncode == 1, proc.stderr[-3000:]  # two scenes failed, named; the rest exported
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    runs = {r["scene"]: r for r in metrics(blend["out"])["runs"]}
    assert set(runs) == set(blend["names"]), sorted(runs)
    failed = {name for name, r in runs.items() if r["status"] == "failed"}
    assert failed == {"missing_sky", "folder_sky"}, {n: runs[n]["reason"] for n in failed}
    for name in set(blend["names"]) - failed:
        assert (blend["out"] / name / "mitsuba" / "scene.xml").is_file(), name


@pytest.mark.slow
@pytest.mark.parametrize("scene, file, why", [
    ("missing_sky", "no_such_sky.exr", "': 'no_such_sky.exr': no such file ({path})"),
    ("folder_sky", "a_folder.exr", "': {path!r} is a folder, not a regular file: not opened")])  # refused before Blender reads it
def test_an_environment_image_without_pixels_names_scene_world_and_field(blend, scene, file, why):
    reason = {r["scene"]: r for r in metrics(blend["out"])["runs"]}[scene]["reason"]
    assert (f"scene {scene!r}, object 'world[{scene}_world]', field 'node_tree.nodes[Environment Texture].image': "
            f"image '{scene}_sky" + why.format(path=str(blend["folder"] / file))) in reason, reason


@pytest.mark.slow
def test_seventy_objects_without_material_and_seventy_lights_load(blend):
    objects = exported(blend, "many_objects")
    assert len(objects["objects"]) == 71 and len(objects["warnings"]) >= 70
    lights = exported(blend, "many_lights")
    assert len(lights["lights"]) == 70 and len(lights["warnings"]) >= 70


@pytest.mark.slow
def test_zero_area_lights_are_dropped_saying_they_emit_nothing(blend):
    for scene, obj, field, what in (("area_size_0", "panel", "data.size", "size 0"),
                                    ("disk_size_y_0", "oval", "data.size_y", "size_y 0"),
                                    ("area_scaled_0", "panel", "scale", "scale (0, 0, 0)")):
        sc = exported(blend, scene)
        assert [o["name"] for o in sc["objects"]] == [f"{scene}_floor"], (scene, sc["objects"])
        assert f"{what}: an area light of zero area emits nothing (in Blender too): not exported\n" in \
            warned(sc)[(f"{scene}_{obj}", field)]


@pytest.mark.slow
def test_an_area_light_flattened_along_its_normal_keeps_its_area_and_direction(blend):
    sc = exported(blend, "area_flattened")
    panel = next(o for o in sc["objects"] if o["name"] == "area_flattened_panel")
    m = panel["shape"]["to_world"]
    assert [row[:3] for row in m[:3]] == [[1.0, 0.0, 0.0], [0.0, -0.5, 0.0], [0.0, 0.0, -1.0]], m  # 2 x 1 m, emits down
    # L = P / (pi A), A = 2 m^2 (2 x 1 scale of a 1 m square): cie_d65 scaled to 50 / (2 pi)
    assert "z axis is scaled to 0: taken as its unit normal" in warned(sc)[("area_flattened_panel", "scale")]
    assert "radiance L = P / (pi A) = 50 / (pi 2) = 7.95775" in warned(sc)[("area_flattened_panel", "data.color")]


@pytest.mark.slow
def test_objects_scaled_to_zero_are_dropped_and_a_flattened_one_keeps_its_geometry(blend):
    sc = exported(blend, "object_scaled_0")
    assert [o["name"] for o in sc["objects"]] == ["object_scaled_0_floor"]
    w = warned(sc)
    assert "scale (0, 0, 0): every face (12) has zero area in the world" in w[("object_scaled_0_gone", "scale")], w
    assert "scale (0, 0, 0): a sphere of radius 0" in w[("object_scaled_0_ball", "scale")], w
    flat = next(o for o in exported(blend, "object_flattened")["objects"] if o["name"] == "object_flattened_flat")
    assert flat["shape"]["to_world"] == [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    assert {tuple(v) for v in flat["shape"]["vertices"]} == {(x, y, 0.5) for x in (-1.0, 1.0) for y in (-1.0, 1.0)}
    assert len(flat["shape"]["faces"]) == 4  # the top and bottom quads; the sides have no area left
    sc = exported(blend, "degenerate_mesh")  # faces of collinear or repeated vertices: nothing to render
    assert [o["name"] for o in sc["objects"]] == ["degenerate_mesh_floor"]
    assert warned(sc)[("degenerate_mesh_sliver", "data")].startswith("every face (2) has zero area in the world"), warned(sc)


@pytest.mark.slow
def test_negative_light_and_world_and_cold_blackbody_are_converted_with_a_warning(blend):
    sc = exported(blend, "negative_light")
    assert [light["name"] for light in sc["lights"]] == ["negative_light_key"]
    assert warned(sc)[("negative_light_dark", "data.energy")].startswith("negative power -100: Blender subtracts light")
    sink = next(o for o in sc["objects"] if o["name"] == "negative_light_sink")
    assert sink["emitter"] is None and "negative strength -2: Blender subtracts light" in \
        warned(sc)[("negative_light_sink", "material[negative_light_negative_light_sink_mat].node_tree.nodes[Principled BSDF]."
                                           "inputs[Emission Strength]")]
    sc = exported(blend, "cold_world")
    assert sc["environment"]["radiance"] == {"type": "blackbody", "temperature": 800.0,
                                             "scale": sc["environment"]["radiance"]["scale"]}
    assert "temperature 0 K: Cycles' Blackbody node gives the colour of 800 K" in \
        warned(sc)[("world[cold_world_world]", "node_tree.nodes[Background].Color")]
    sc = exported(blend, "dark_world")
    assert sc["environment"] is None and "negative strength -1: Blender subtracts light" in \
        warned(sc)[("world[dark_world_world]", "node_tree.nodes[Background].Strength")]


def test_list_caps_are_named_per_list_in_the_error(tmp_path, golden):
    """A scene file over a cap is refused naming the list and its limit (before anything looks at
    its items); the caps are far above what a real scene holds."""
    from spectral_bench.exporters import validate
    assert validate.LIST_LIMITS["objects"] >= 10_000 and validate.LIST_LIMITS["lights"] >= 1000
    sc = dict(golden["ggx_copper_50"])
    sc = {k: v for k, v in sc.items() if not k.startswith("_")}
    light = {"type": "point", "position": [0.0, 0.0, 5.0], "intensity": {"type": "constant", "value": 1.0}}
    n = validate.LIST_LIMITS["lights"] + 1
    sc["lights"] = [dict(light, name=f"l{i}") for i in range(n)]
    path = tmp_path / "lamps.json"
    path.write_text(json.dumps(sc))
    proc = run_batch("--list", "-i", path)
    assert proc.returncode == 2
    assert (f"field 'lights': holds {n} items, more than {n - 1}: the limit for a scene's lights "
            "(exporters/validate.py LIST_LIMITS") in proc.stdout, proc.stdout[-2000:]


def test_the_documented_caps_are_the_table():
    """docs/scene-format.md section 5 states each cap of exporters/validate.py LIST_LIMITS with its field."""
    from spectral_bench.exporters import validate
    assert {"objects", "lights", "warnings"} <= set(validate.LIST_LIMITS)  # each list a Blender scene fills, named
    text = " ".join((ROOT / "docs" / "scene-format.md").read_text().split())
    for field, limit in validate.LIST_LIMITS.items():
        if not field.endswith("[]"):
            assert f"{limit} (`{field}`)" in text or f"`{field}`" in text and str(limit) in text, (field, limit)
    assert f"{validate.MAX_OTHER_LIST} (any other list" in text
