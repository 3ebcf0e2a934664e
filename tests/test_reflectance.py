"""The reflectance case end to end: every scene renders at low resolution through the real
batch command and agrees with its reference within the reference's noise; a wrong material
(gold for copper) fails the same test."""
import copy

import pytest

from conftest import REFLECTANCE, metrics, run_batch
from spectral_bench.batch import backends, exr
from spectral_bench.batch.verdict import compare, references

SCALE, SPP = 0.125, 256


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reflectance") / "out"
    # alpha 0.001: five scenes judged at once keep the chance of a false alarm near 0.5 % per run
    # (renders are seeded, so a run repeats; benchmarks/CALIBRATION.md has the measured rates)
    proc = run_batch("-r", "mitsuba", "-c", "reflectance", "--scale", SCALE, "--spp", SPP, "--alpha", 0.001, "-o", out)
    return proc, out, {r["scene"]: r for r in metrics(out)["runs"]}


def test_references_exist_with_provenance_and_noise():
    for name in REFLECTANCE:
        ref = references.load(name)
        assert ref is not None, f"references/{name}.exr missing: run batch/make_references.py"
        p = ref.provenance
        for key in ("backend", "mode", "spp", "passes", "resolution", "time_s", "date", "versions", "fingerprint"):
            assert key in p, (name, key)
        assert p["passes"] >= 4 and ref.stderr.shape == ref.mean.shape and (ref.stderr > 0).mean() > 0.5


def test_every_reflectance_scene_agrees_with_its_reference(batch_run):
    proc, out, runs = batch_run
    assert sorted(runs) == REFLECTANCE
    for name, run in runs.items():
        assert run["status"] == "ok", (name, run["reason"], run.get("test"))
        assert run["test"]["pass"] and run["resolution"] == [64, 64] and run["spp"] == SPP
        assert run["metrics"]["flip"] is not None and 0 <= run["metrics"]["flip"] < 1
        assert run["sanity"]["nan"] == 0 and run["sanity"]["inf"] == 0
        for f in ("render.exr", "reference.exr", "diff_abs.exr", "diff_rel.exr", "flip.exr", "diff.png"):
            assert (out / name / "results" / "mitsuba" / f).is_file(), (name, f)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "5 ok" in (out / "summary.md").read_text()


def _render_variant(golden, name, tmp_path, change):
    sc = copy.deepcopy(golden[name])
    change(sc)
    sc["render"]["width"] = sc["render"]["height"] = int(512 * SCALE)
    backend = backends.get("mitsuba")
    mode, _ = backend.mode_for(sc)
    xml = backend.export(sc, tmp_path / "m")
    backend.render(xml, mode, SPP, tmp_path / "r.exr")
    test = exr.read_rgb(tmp_path / "r.exr")
    ref = references.load(name)
    mean, vom, s2 = compare.reference_at(ref.mean, ref.stderr, ref.spp, test.shape)
    return compare.z_test(test, mean, vom, s2, SPP)


def _set_conductor(metal):
    def change(sc):
        for obj in sc["objects"]:
            if (obj.get("bsdf") or {}).get("type") == "conductor":
                obj["bsdf"]["material"] = metal
    return change


@pytest.mark.parametrize("name", ["ggx_copper_50", "ggx_copper_80"])
def test_gold_instead_of_copper_fails(golden, tmp_path, name):
    assert _render_variant(golden, name, tmp_path / "cu", _set_conductor("Cu")).passed
    zt = _render_variant(golden, name, tmp_path / "au", _set_conductor("Au"))
    assert not zt.passed and zt.z_max > 10, zt
