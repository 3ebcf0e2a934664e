"""Bad input gets a clear error naming scene, object and field; the batch goes on."""
import copy
import json

import pytest

from conftest import metrics, run_batch, write_scene
from spectral_bench.exporters import ir_json, validate


def _obj(scene, name):
    return next(o for o in scene["objects"] if o["name"] == name)


def broken(golden, how):
    sc = copy.deepcopy(golden["ggx_copper_50"] if how not in ("ior", "sellmeier", "glass") else golden["ggx_glass"])
    if how == "roughness":
        _obj(sc, "copper_plate_50")["bsdf"]["roughness"]["alpha"] = -0.2
        return sc, "copper_plate_50", "bsdf.roughness.alpha"
    if how == "ior":
        _obj(sc, "glass_sphere")["bsdf"]["int_ior"] = 0.0
        return sc, "glass_sphere", "bsdf.int_ior"
    if how == "sellmeier":  # a resonance at 500 nm, inside the renderers' range: n is infinite there
        _obj(sc, "glass_sphere")["bsdf"]["int_ior"] = {"type": "sellmeier", "B": [1.0, 0.2], "C": [0.25, 0.02]}
        return sc, "glass_sphere", "bsdf.int_ior"
    if how == "glass":
        _obj(sc, "glass_sphere")["bsdf"]["int_ior"] = {"type": "named", "name": "BK7"}
        return sc, "glass_sphere", "bsdf.int_ior.name"
    if how == "nan":
        _obj(sc, "floor")["bsdf"]["reflectance"]["value"] = float("nan")
        return sc, "floor", "bsdf.reflectance.value"
    if how == "named":
        _obj(sc, "light")["emitter"]["radiance"]["name"] = "cie_d66"
        return sc, "light", "emitter.radiance.name"
    if how == "mesh":
        _obj(sc, "floor")["shape"] = {"type": "mesh", "file": "missing_floor.ply"}
        return sc, "floor", "shape.file"
    if how == "reflectance":
        _obj(sc, "floor")["bsdf"]["reflectance"] = {"type": "sampled", "wavelengths": [400, 700], "values": [0.5, 1.2]}
        return sc, "floor", "bsdf.reflectance"
    raise ValueError(how)


@pytest.mark.parametrize("how", ["roughness", "ior", "sellmeier", "glass", "nan", "named", "mesh", "reflectance"])
def test_value_errors_name_scene_object_field(golden, tmp_path, how):
    sc, obj, field = broken(golden, how)
    path = ir_json.write(sc, tmp_path / "bad.json")
    with pytest.raises(validate.SceneError) as info:
        ir_json.load(path)
    err = info.value
    assert (obj, field) in [(o, f) for o, f, _ in err.problems], err.problems
    assert sc["name"] in str(err) and obj in str(err) and field in str(err)


def test_wrong_version_is_named(golden, tmp_path):
    sc = copy.deepcopy(golden["ggx_glass"])
    sc["version"] = 99
    with pytest.raises(validate.SceneError) as info:
        ir_json.load(ir_json.write(sc, tmp_path / "v.json"))
    assert "version" in str(info.value) and "99" in str(info.value)


def test_wrong_shape_is_named(golden, tmp_path):
    sc = copy.deepcopy(golden["ggx_glass"])
    del _obj(sc, "glass_sphere")["shape"]["radius"]
    sc["render"]["spp"] = "many"
    with pytest.raises(validate.SceneError) as info:
        ir_json.load(ir_json.write(sc, tmp_path / "s.json"))
    fields = {(o, f) for o, f, _ in info.value.problems}
    assert ("render", "spp") in fields
    assert any(o == "glass_sphere" and f.startswith("shape") for o, f in fields), fields


def test_not_json_at_all(tmp_path):
    p = tmp_path / "junk.json"
    p.write_text("{ not json")
    with pytest.raises(validate.SceneError, match="junk"):
        ir_json.load(p)


@pytest.fixture(scope="module")
def mixed_run(golden, tmp_path_factory):
    """One Mitsuba run (a run costs about 2 s of CPU whatever it renders) of five inputs: two bad
    scenes around a good one, then two good scenes of one name ("twin", from two folders); the two
    tests below check it: (inputs, out, the finished process)."""
    tmp_path = tmp_path_factory.mktemp("mixed")
    good = write_scene(tmp_path, golden["ggx_glass"])
    bad_paths = []
    for how in ("roughness", "named"):
        sc, _, _ = broken(golden, how)
        sc["name"] = f"bad_{how}"
        bad_paths.append(ir_json.write(sc, tmp_path / f"bad_{how}.json"))
    a = write_scene(tmp_path / "a", golden["ggx_copper_50"], name="twin")
    b = write_scene(tmp_path / "b", golden["ggx_copper_60"], name="twin")
    out = tmp_path / "out"
    proc = run_batch("-r", "mitsuba", "-i", bad_paths[0], good, bad_paths[1], a, b, "--scale", 0.125, "--spp", 16,
                     "--no-flip", "-o", out)
    return {"twin_a": a, "twin_b": b}, out, proc


@pytest.mark.slow
def test_batch_goes_on_after_bad_scenes_and_exit_status_says_so(mixed_run):
    _, out, proc = mixed_run
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"] if r["scene"] != "twin"}
    assert sorted(runs) == ["bad_named", "bad_roughness", "ggx_glass"], runs
    assert runs["ggx_glass"]["status"] == "ok", runs["ggx_glass"]
    for how, field in (("roughness", "bsdf.roughness.alpha"), ("named", "emitter.radiance.name")):
        r = runs[f"bad_{how}"]
        assert r["status"] == "failed" and field in r["reason"], r
    assert (out / "ggx_glass" / "results" / "mitsuba" / "render.exr").is_file()


def test_existing_results_are_never_overwritten(golden, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.json").write_text(json.dumps({"runs": ["earlier"]}))
    proc = run_batch("-i", write_scene(tmp_path, golden["ggx_glass"]), "--export-only", "-o", out)
    assert proc.returncode == 2 and "already holds results" in proc.stderr
    assert json.loads((out / "metrics.json").read_text()) == {"runs": ["earlier"]}


@pytest.mark.slow
def test_two_inputs_with_one_scene_name_keep_apart(mixed_run):
    """Outputs are written per scene name: the second scene of a name fails with the reason, the
    first renders, nothing is mixed."""
    inputs, out, proc = mixed_run
    a = inputs["twin_a"]
    runs = [r for r in metrics(out)["runs"] if r["scene"] == "twin"]
    assert len(runs) == 2, runs
    # the first (no reference, no probe for a plate on a floor) renders; the second is refused
    by_status = {r["status"]: r for r in runs}
    assert sorted(by_status) == ["failed", "unjudged"], runs
    assert "already comes from" in by_status["failed"]["reason"] and str(a) in by_status["failed"]["reason"]
    assert (out / "twin" / "results" / "mitsuba" / "render.exr").is_file()
    assert proc.returncode == 1
