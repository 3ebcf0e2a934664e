"""Scene files that are valid JSON and absurd (issue 30): a list of 1e5 or 1e6 entries, a conductor
with k = 1e308, a Sellmeier B of 1e300. Each is refused naming the object and the field, with a
reason a person can read (not the list repeated: it was 1.1 MB per job), and a list too long is
refused before anything looks at its items (1e6 entries took 28 s to validate)."""
import copy
import json

import pytest

from conftest import GOLDEN, metrics
from spectral_bench.exporters import dispersion, ir_json, validate


class Untouchable(list):
    """A list that claims ``n`` items and fails the test if anything reads one."""

    def __init__(self, n):
        super().__init__()
        self.n = n

    def __len__(self):
        return self.n

    def __iter__(self):
        raise AssertionError("an item of a list over its length limit was read")

    __getitem__ = __iter__


def prism(b=None, c=None, n=3):
    sc = ir_json.load(GOLDEN / "dispersion_prism.json")
    for obj in sc["objects"]:
        if isinstance(obj.get("bsdf"), dict) and isinstance(obj["bsdf"].get("int_ior"), dict):
            obj["bsdf"]["int_ior"] = {"type": "sellmeier", "B": b if b is not None else [1.0] * n,
                                      "C": c if c is not None else [0.01] * n}
    return sc


def copper(**k):
    """The raw file (its copper's eta and k inline beside the material's name, which they replace)."""
    sc = json.loads((GOLDEN / "ggx_copper_50.json").read_text())
    for obj in sc["objects"]:
        if isinstance(obj.get("bsdf"), dict) and "k" in obj["bsdf"]:
            obj["bsdf"]["k"] = k
            return sc, obj["name"]
    raise AssertionError("no conductor in ggx_copper_50")


def refused(scene):
    with pytest.raises(validate.SceneError) as err:
        validate.check(copy.deepcopy(scene) if not isinstance(scene, dict) else scene)
    return str(err.value)


def test_a_long_sellmeier_list_gives_a_short_reason():
    text = refused(prism(n=100_000))
    assert len(text) < 1000, len(text)
    assert "object 'prism', field 'bsdf.int_ior.B': holds 100000 items, more than 64" in text


@pytest.mark.parametrize("where", ["sellmeier", "spectrum", "mesh"])
def test_a_list_over_its_limit_is_refused_before_its_items_are_read(where):
    if where == "sellmeier":
        sc, field = prism(b=Untouchable(10 ** 6), c=[0.01] * 3), "bsdf.int_ior.B"
    elif where == "spectrum":
        sc, _ = copper(type="sampled", wavelengths=Untouchable(10 ** 6), values=Untouchable(10 ** 6))
        field = "bsdf.k.wavelengths"
    else:
        sc = ir_json.load(GOLDEN / "ggx_copper_50.json")
        sc["objects"][0]["shape"] = {"type": "mesh", "vertices": Untouchable(validate.MAX_MESH_ITEMS + 1), "faces": [[0, 1, 2]]}
        field = "shape.vertices"
    text = refused(sc)
    assert f"field '{field}': holds" in text and "more than" in text, text


@pytest.mark.parametrize("spec, words", [
    ({"type": "sampled", "wavelengths": [400.0, 500.0, 600.0], "values": [1.0, 1e308, 2.0]}, "reaches 1e+308, above 1000"),
    ({"type": "constant", "value": 1e308}, "reaches 1e+308, above 1000"),
])
def test_an_absurd_conductor_index_is_refused_naming_it(spec, words):
    sc, name = copper(**spec)
    text = refused(sc)
    assert f"object {name!r}, field 'bsdf.k': {words}" in text, text


@pytest.mark.parametrize("b, c, field, words", [
    ([1e300, 0.2, 1.0], [0.006, 0.02, 103.0], "bsdf.int_ior.B[0]", "must be within +-100"),
    ([1.0, 0.2, 1.0], [0.006, 0.02, 1e300], "bsdf.int_ior.C[2]", "must be in [0, 1e+06]"),
    ([99.0, 99.0, 1.0], [0.006, 0.02, 103.0], "bsdf.int_ior", "n(lambda) reaches"),  # each B in bounds, n about 14
])
def test_an_absurd_sellmeier_glass_is_refused_naming_it(b, c, field, words):
    text = refused(prism(b=b, c=c))
    assert f"object 'prism', field '{field}': {words}" in text, text


def test_every_shipped_scene_and_glass_is_inside_the_bounds():
    for path in sorted(GOLDEN.glob("*.json")):
        validate.check(ir_json.load(path))
    for name, coeffs in dispersion.NAMED_GLASSES.items():
        assert list(dispersion.problems(dict(coeffs, type="sellmeier"), name)) == []


def test_many_problems_are_listed_up_to_a_limit():
    err = validate.SceneError("s", [("o", f"f{i}", "x" * 5000) for i in range(100)])
    assert len(str(err)) < 20_000 and "... and 80 more problems" in str(err)
    assert len(err.problems) == 100 and all(len(m) <= validate.MAX_MESSAGE for _, _, m in err.problems)


def test_the_runner_records_the_short_reason_and_goes_on(tmp_path, run_batch_here):
    """Through batch/run.py: the scene fails alone with the short reason in metrics.json."""
    bad = prism(n=100_000)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({k: v for k, v in bad.items() if not k.startswith("_")}))
    proc = run_batch_here("-i", path, GOLDEN / "ggx_copper_50_isolated.json", "-r", "mitsuba", "--list")
    assert proc.returncode == 2, proc.stderr  # --list shows the load error (short) and exits 2; the other scene is listed
    (error,) = [line for line in proc.stdout.splitlines() if "\tERROR\t" in line]
    assert len(error) < 1000 and "bsdf.int_ior.B" in error, error[:2000]
    assert "ggx_copper_50_isolated\treflectance\tmitsuba" in proc.stdout.splitlines()
    out = tmp_path / "out"
    proc = run_batch_here("-i", path, "-r", "mitsuba", "--scale", 0.0625, "--spp", 4, "-o", out)
    runs = metrics(out)["runs"]
    assert [r["status"] for r in runs] == ["failed"] and len(runs[0]["reason"]) < 1000, runs[0]["reason"][:2000]
    assert "bsdf.int_ior.B" in runs[0]["reason"] and proc.returncode == 1
