"""The reflectance case end to end at the product's default settings (full resolution, each
scene's own sample count, two passes, alpha 0.01): every scene renders through the real batch
command and agrees with its reference on its own noise; a wrong material (gold for copper) fails
the same test."""
import copy

import pytest

from conftest import REFLECTANCE, metrics, noise_test, render_with_noise, run_batch
from spectral_bench.batch.verdict import references


@pytest.fixture(scope="module")
def batch_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reflectance") / "out"
    proc = run_batch("-r", "mitsuba", "-c", "reflectance", "--no-flip", "-o", out)
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
        assert run["status"] in ("ok", "known"), (name, run["reason"], run.get("test"))
        assert run["test"]["pass"] and run["test"]["noise"] == "own" and run["passes"] == 2
        assert run["resolution"] == [512, 512] and run["spp"] == run["spp"] > 0
        assert run["sanity"]["nan"] == 0 and run["sanity"]["inf"] == 0
        for f in ("render.exr", "reference.exr", "diff_abs.exr", "diff_rel.exr", "zscore.exr", "diff.png"):
            assert (out / name / "results" / "mitsuba" / f).is_file(), (name, f)
    assert proc.returncode == 0, proc.stderr[-2000:]


def _render_variant(golden, name, tmp_path, change):
    sc = copy.deepcopy(golden[name])
    change(sc)
    spp = sc["render"]["spp"]
    _, _, img, se = render_with_noise(sc, tmp_path, spp)
    return noise_test(name, img, se, spp)


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
