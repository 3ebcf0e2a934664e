"""Scene files are self-contained (exporters/inline_data.py, docs/scene-format.md): every named
spectrum, conductor and glass carries its data; the loader reads both forms to the same scene,
the same Mitsuba export, the same render and the same reference fingerprint; edited inline data
wins over the name."""
import copy
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

from conftest import ALL_SCENES, GOLDEN, render
from spectral_bench.batch.verdict import references
from spectral_bench.exporters import dispersion, inline_data, ir_json, mitsuba_writer, spectra, validate


def walk(node, path=""):
    """(path, dict) of every dict in parsed JSON."""
    if isinstance(node, dict):
        yield path, node
        for k, v in node.items():
            yield from walk(v, f"{path}.{k}")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from walk(v, f"{path}[{i}]")


def missing_data(raw):
    """Paths of named things in a parsed scene file that lack their data."""
    out = []
    for path, d in walk(raw):
        if d.get("type") == "named" and path.endswith("int_ior"):
            if not {"model", "B", "C"} <= d.keys():
                out.append(path)
        elif d.get("type") == "named" and not {"wavelengths", "values"} <= d.keys():
            out.append(path)
        if d.get("type") == "conductor" and "material" in d and not {"eta", "k"} <= d.keys():
            out.append(path)
    return out


def mitsuba_files(scene, folder):
    """{relative path: bytes} of the Mitsuba export of ``scene``."""
    mitsuba_writer.write(scene, folder)
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def write_named(scene, path):
    return ir_json.write(scene, path, self_contained=False)


def named_form(raw):
    """The parsed self-contained file with the data beside every name removed (the old form)."""
    raw = copy.deepcopy(raw)
    for path, d in walk(raw):
        if d.get("type") == "named" and path.endswith("int_ior"):
            for key in ("model", "B", "C"):
                d.pop(key)
        elif d.get("type") == "named":
            del d["wavelengths"], d["values"]
        if d.get("type") == "conductor" and "material" in d:
            del d["eta"], d["k"]
    return raw


def load_named(name, tmp_path):
    """Golden ``name`` written in the named form (its data stripped from the file) and loaded."""
    path = tmp_path / "named" / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(named_form(json.loads((GOLDEN / f"{name}.json").read_text()))))
    return ir_json.load(path)


@pytest.mark.parametrize("name", ALL_SCENES)
def test_golden_files_carry_the_data_behind_every_name(name):
    raw = json.loads((GOLDEN / f"{name}.json").read_text())
    assert missing_data(raw) == []


def test_the_check_finds_a_name_without_its_data():
    """The walk above is not vacuous: the named form of the files fails it."""
    raw = json.loads((GOLDEN / "dispersion_prism.json").read_text())
    assert missing_data(raw) == [] and len(missing_data(named_form(raw))) == 2  # the beam's D65, the prism's N-BK7
    copper = named_form(json.loads((GOLDEN / "ggx_copper_50.json").read_text()))
    assert ".objects[0].bsdf" in missing_data(copper)


@pytest.mark.parametrize("name", ALL_SCENES)
def test_both_forms_load_to_one_scene_export_and_fingerprint(name, tmp_path):
    """The self-contained file and the named one: the same IR, byte-identical Mitsuba exports, the
    same reference fingerprint (no reference becomes stale)."""
    full = ir_json.load(GOLDEN / f"{name}.json")
    named = load_named(name, tmp_path)
    for sc in (full, named):
        sc.pop("_base_dir")
    assert full == named
    assert mitsuba_files(full, tmp_path / "a") == mitsuba_files(named, tmp_path / "b")
    assert references.fingerprint(full) == references.fingerprint(named)


@pytest.mark.slow  # over about 1 s of CPU (1.2-2.6 s measured with ART and pbrt built, 2026-12-06: benchmarks/TESTS.md)
def test_every_reference_stays_current_with_the_self_contained_goldens():
    stale = []
    for name in ALL_SCENES:
        found = references.search(name, scene=ir_json.load(GOLDEN / f"{name}.json"))
        if found.ref is None or found.problems:
            stale.append((name, found.problems))
    assert stale == []


@pytest.mark.parametrize("name", ["macbeth_chart_D65", "ggx_copper_50"])
def test_a_self_contained_scene_renders_identically_to_the_named_one(name, tmp_path):
    """A real Mitsuba render (32 x 32, 4 spp, the same seed) of each form: identical pixels."""
    full = ir_json.load(GOLDEN / f"{name}.json")
    named = load_named(name, tmp_path)
    assert "values" in (GOLDEN / f"{name}.json").read_text()
    _, names_a, img_a = render(full, tmp_path / "a", 4, size=(32, 32))
    _, names_b, img_b = render(named, tmp_path / "b", 4, size=(32, 32))
    assert names_a == names_b and img_a.shape == (32, 32, len(names_a))
    assert np.isfinite(img_a).all() and img_a.mean() > 0
    assert np.array_equal(img_a, img_b)


# -- inline data wins over the name ----------------------------------------------------------------
def edited(name, edit):
    """Load golden ``name`` after ``edit`` changed its parsed self-contained JSON."""
    raw = json.loads((GOLDEN / f"{name}.json").read_text())
    edit(raw)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"{name}.json"
        path.write_text(json.dumps(raw))
        return ir_json.load(path)


def light(scene):
    return next(o for o in scene["objects"] if o.get("emitter"))["emitter"]


def test_an_edited_spectrum_table_wins_and_the_name_is_a_label():
    def halve_below_500(raw):
        spec = light(raw)["radiance"]
        spec["values"] = [v * (0.5 if w < 500 else 1.0) for w, v in zip(spec["wavelengths"], spec["values"])]
    sc = edited("ggx_copper_50", halve_below_500)
    spec = light(sc)["radiance"]
    assert spec["type"] == "sampled"  # the table replaced the name
    own_wl, own_values = inline_data.named_spectrum_table("cie_d65")
    wl = np.array([400.0, 450.0, 560.0, 700.0])
    expected = 4.0 * np.interp(wl, own_wl, own_values) * np.where(wl < 500, 0.5, 1.0)  # scale 4 * the edited table
    np.testing.assert_allclose(spectra.evaluate(spec, wl), expected, rtol=1e-12)
    original = ir_json.load(GOLDEN / "ggx_copper_50.json")
    assert references.fingerprint(sc) != references.fingerprint(original)  # its reference is stale for it
    with tempfile.TemporaryDirectory() as d:
        assert mitsuba_files(sc, Path(d) / "a") != mitsuba_files(original, Path(d) / "b")


def test_a_table_equal_to_the_project_s_within_rounding_is_the_named_spectrum():
    def round_to_float32(raw):
        spec = light(raw)["radiance"]
        spec["values"] = [float(np.float32(v)) for v in spec["values"]]  # as a float32 tool re-saves it
    sc = edited("ggx_copper_50", round_to_float32)
    assert light(sc)["radiance"]["type"] == "sampled"  # float32 is far more than RTOL away: the file wins
    sc = edited("ggx_copper_50", lambda raw: light(raw)["radiance"].update(
        values=[v * (1 + 1e-12) for v in light(raw)["radiance"]["values"]]))
    assert light(sc)["radiance"] == {"type": "named", "name": "cie_d65", "scale": 4.0}


def test_an_unknown_name_with_its_table_is_accepted():
    sc = edited("ggx_copper_50", lambda raw: light(raw)["radiance"].update(name="my_lamp"))
    assert light(sc)["radiance"]["type"] == "sampled"


def test_edited_conductor_tables_replace_the_material():
    def scale_k(raw):
        raw["objects"][0]["bsdf"]["k"]["values"] = [2 * v for v in raw["objects"][0]["bsdf"]["k"]["values"]]
    sc = edited("ggx_copper_50", scale_k)
    bsdf = sc["objects"][0]["bsdf"]
    assert "material" not in bsdf and bsdf["eta"] == spectra.named_conductor("Cu")[0]
    assert bsdf["k"]["values"] == [2 * v for v in spectra.named_conductor("Cu")[1]["values"]]
    with tempfile.TemporaryDirectory() as d:
        xml = (Path(mitsuba_writer.write(sc, Path(d) / "m"))).read_text()
    assert 'name="material"' not in xml


def test_edited_glass_coefficients_replace_the_named_glass():
    def edit(raw):
        prism = next(o for o in raw["objects"] if o["name"] == "prism")
        prism["bsdf"]["int_ior"]["B"][0] = 1.1
    sc = edited("dispersion_prism", edit)
    ior = next(o for o in sc["objects"] if o["name"] == "prism")["bsdf"]["int_ior"]
    assert ior == {"type": "sellmeier", "B": [1.1] + dispersion.NAMED_GLASSES["N-BK7"]["B"][1:],
                   "C": dispersion.NAMED_GLASSES["N-BK7"]["C"]}


@pytest.mark.parametrize("edit, obj, field", [
    (lambda raw: light(raw)["radiance"]["values"].pop(), "light", "emitter.radiance"),
    (lambda raw: light(raw)["radiance"]["values"].__setitem__(3, "x"), "light", "emitter.radiance"),
    (lambda raw: light(raw)["radiance"].pop("wavelengths"), "light", "emitter.radiance"),
    (lambda raw: light(raw)["radiance"]["values"].__setitem__(3, -1.0), "light", "emitter.radiance.values[3]"),
])
def test_malformed_inline_data_is_refused_by_object_and_field(edit, obj, field):
    with pytest.raises(validate.SceneError) as err:
        edited("ggx_copper_50", edit)
    assert any(o == obj and f.startswith(field) for o, f, _ in err.value.problems), err.value.problems


def test_a_conductor_with_half_its_inline_data_is_refused_not_rendered_as_the_name():
    with pytest.raises(validate.SceneError) as err:
        edited("ggx_copper_50", lambda raw: raw["objects"][0]["bsdf"].pop("k"))
    assert [(o, f) for o, f, _ in err.value.problems] == [("copper_plate_50", "bsdf.k")]


def test_malformed_inline_glass_coefficients_are_refused_by_field():
    def edit(raw):
        next(o for o in raw["objects"] if o["name"] == "prism")["bsdf"]["int_ior"]["C"] = [0.1, 0.2]
    with pytest.raises(validate.SceneError) as err:
        edited("dispersion_prism", edit)
    assert any(o == "prism" and f.startswith("bsdf.int_ior") for o, f, _ in err.value.problems), err.value.problems


def test_named_form_is_still_written_on_request(tmp_path):
    sc = ir_json.load(GOLDEN / "ggx_copper_50.json")
    text = write_named(sc, tmp_path / "n.json").read_text()
    assert json.loads(text)["objects"][0]["bsdf"] == {"material": "Cu", "roughness": {"alpha": 0.2, "distribution": "ggx"},
                                                      "type": "conductor"}
    assert copy.deepcopy(inline_data.embed(sc)) == json.loads((GOLDEN / "ggx_copper_50.json").read_text())
