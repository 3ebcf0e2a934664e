"""The IR's delta lights (point, spot, directional) and warnings, without bpy: validation names
the light and field, every writer either renders a light or says it cannot, and neither the
warnings nor a light's name change a reference's fingerprint."""
import copy
import json

import pytest

from conftest import GOLDEN
from spectral_bench.batch.verdict import references
from spectral_bench.exporters import art_writer, ir, ir_json, mitsuba_writer, rgb_reduction, rgb_scene, validate

D65 = {"type": "named", "name": "cie_d65", "scale": 2.0}
LIGHTS = [
    {"name": "bulb", "type": "point", "position": [0.0, 0.0, 2.0], "intensity": D65},
    {"name": "cone", "type": "spot", "to_world": [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 2], [0, 0, 0, 1]],
     "intensity": D65, "cutoff_angle": 30.0, "beam_width": 20.0},
    {"name": "sun", "type": "directional", "direction": [0.0, 0.5, -0.866], "irradiance": {"type": "constant", "value": 3.0}},
]


@pytest.fixture
def scene():
    sc = ir_json.load(GOLDEN / "ggx_copper_50.json")
    sc.pop("_base_dir")
    sc["lights"] = copy.deepcopy(LIGHTS)
    sc["warnings"] = [{"object": "lamp", "field": "data.color", "message": "converted"}]
    return sc


def problems(sc):
    with pytest.raises(validate.SceneError) as info:
        validate.check(sc)
    return {(o, f) for o, f, _ in info.value.problems}


def test_a_scene_with_delta_lights_and_warnings_is_valid_and_round_trips(scene, tmp_path):
    validate.check(copy.deepcopy(scene))
    back = ir_json.load(ir_json.write(scene, tmp_path / "s.json"))
    back.pop("_base_dir")
    assert back["lights"] == scene["lights"] and back["warnings"] == scene["warnings"]
    assert "spectral" in ir.derived_needs(scene)


@pytest.mark.parametrize("edit, field", [
    (lambda s: s["lights"][1].update(cutoff_angle=120.0), ("cone", "cutoff_angle")),
    (lambda s: s["lights"][1].update(beam_width=40.0), ("cone", "beam_width")),
    (lambda s: s["lights"][2].update(direction=[0.0, 0.0, 0.0]), ("sun", "direction")),
    (lambda s: s["lights"][0].update(position=[0.0, 1e9, 0.0]), ("bulb", "position")),
    (lambda s: s["lights"][0].update(intensity={"type": "constant", "value": -1.0}), ("bulb", "intensity.value")),
    (lambda s: s["lights"][0].update(name=s["objects"][0]["name"].upper()), (None, "name")),
    (lambda s: s["lights"][2].update(irradiance=None), ("sun", "irradiance")),
    (lambda s: s["lights"][0].update(kind="x"), ("bulb", "(root)")),
])
def test_a_bad_light_is_refused_naming_the_light_and_field(scene, edit, field):
    edit(scene)
    found = problems(scene)
    if field[0] is None:  # a name taken by an object: named by the name itself
        assert any(f == "name" for _, f in found), found
    else:
        assert field in found, found


def test_every_writer_renders_each_light_or_names_it(scene, tmp_path):
    xml = mitsuba_writer.write(scene, tmp_path / "mitsuba").read_text()
    for kind in ("point", "spot", "directional"):
        assert f'<emitter type="{kind}"' in xml
    assert 'name="cutoff_angle" value="30.0"' in xml and 'name="beam_width" value="20.0"' in xml
    assert {(o, f) for o, f, _ in art_writer.unsupported(scene)} >= {("bulb", "type"), ("cone", "type"), ("sun", "type")}
    # an RGB renderer without delta lights names each; one with them approximates only the spot's falloff
    assert {(o, f) for o, f, _, _ in rgb_scene.problems(scene, {"ggx"})} >= {("bulb", "type"), ("cone", "type"), ("sun", "type")}
    found = rgb_scene.problems(scene, {"ggx"}, frozenset({"point", "spot", "directional"}))
    assert [(o, f, a is not None) for o, f, _, a in found if o in ("bulb", "cone", "sun")] == [("cone", "beam_width", True)]
    rgb = rgb_scene.build(scene, {"ggx"}, approximate=True, light_types=frozenset({"point", "spot", "directional"}))
    assert [lt["type"] for lt in rgb["lights"]] == ["point", "spot", "directional"]
    flat, _ = rgb_reduction.emission_rgb({"type": "constant", "value": 1.0})
    assert rgb["lights"][2]["irradiance"] == pytest.approx(3.0 * flat)
    assert rgb["lights"][1]["to_world"] == LIGHTS[1]["to_world"] and rgb["lights"][0]["position"] == [0.0, 0.0, 2.0]


def test_warnings_and_light_names_do_not_change_the_fingerprint(scene):
    base = references.fingerprint(scene)
    other = copy.deepcopy(scene)
    other["warnings"] = []
    other["lights"][0]["name"] = "renamed"
    other["lights"].reverse()
    assert references.fingerprint(other) == base
    other["lights"][0]["irradiance"] = {"type": "constant", "value": 3.5}
    assert references.fingerprint(other) != base


def test_a_scene_without_lights_or_warnings_is_written_as_before(golden):
    """The canonical scenes have no delta lights and no warnings, so their Mitsuba export (golden/,
    test_mitsuba_export.py) and JSON are what they were; the one exception is the furnaces' surface
    emission, which the extension has no spectral annotation for (issue 41): it comes from the
    Principled BSDF's Emission, converted to D65 and warned, and nothing else is."""
    for name, sc in golden.items():
        assert "lights" not in sc
        assert '"lights"' not in ir_json.dumps(sc)
        if name.startswith("furnace_") and not name.startswith("furnace_ggx_"):  # the GGX ones emit nothing
            assert [(w["object"], w["field"].rsplit(".", 1)[-1]) for w in sc["warnings"]] == [
                (f"{name}_sphere", "inputs[Emission Strength]")], sc["warnings"]
            assert "cie_d65" in sc["warnings"][0]["message"]
        else:
            assert "warnings" not in sc, name
    assert json.loads(ir_json.dumps(golden["ggx_copper_50"]))["objects"]


def test_a_scene_files_warnings_reach_the_log_escaped_and_metrics(scene, tmp_path):
    """A scene file's warnings (here hand-written, with a newline in a name that would forge a log
    line) are logged one line each, escaped, and land in metrics.json; --export-only renders nothing."""
    from conftest import metrics, run_batch
    scene["warnings"] = [{"object": "lamp\nERROR forged", "field": "data.color", "message": "converted"}]
    path = ir_json.write(scene, tmp_path / "lit.json")
    out = tmp_path / "out"
    proc = run_batch("-i", path, "-r", "mitsuba", "--export-only", "-o", out)
    log = proc.stdout + proc.stderr
    assert "conversion (ggx_copper_50): 'lamp\\nERROR forged'.data.color: converted" in log, log[-2000:]
    assert not any(line.startswith("ERROR forged") for line in log.splitlines())
    assert proc.returncode == 0, log[-2000:]
    runs = metrics(out)["runs"]
    assert runs and all(r["scene_warnings"] == scene["warnings"] for r in runs)
    assert json.loads((out / "ggx_copper_50" / "json" / "ggx_copper_50.json").read_text())["warnings"] == scene["warnings"]


def test_list_notes_a_scene_with_conversion_warnings(scene, tmp_path, run_batch_here):
    path = ir_json.write(scene, tmp_path / "lit.json")
    proc = run_batch_here("--list", "-r", "mitsuba", "-i", path)
    assert proc.returncode == 0 and proc.stdout.splitlines() == ["ggx_copper_50\treflectance\tmitsuba"]
    assert "note: ggx_copper_50: 1 conversion warning(s)" in proc.stderr
