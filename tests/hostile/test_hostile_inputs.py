"""One bad input fails alone (issue 18): whatever is wrong with one scene file (unreadable, not
UTF-8, not JSON, nested too deeply, not an object, a name that is no string or that would be a
path or one of the run's own files, a mesh that is no mesh) becomes that input's failure, naming
the file and the field; the other scenes run, metrics.json and summary.md are always written, and
nothing is written outside OUT."""
import copy
import json

import pytest

from conftest import GOLDEN, metrics, run_batch, write_scene
from spectral_bench.batch import scene_sources
from spectral_bench.exporters import ir_json, validate

GOOD = "ggx_copper_50_isolated"
TINY = ("--scale", 0.0625, "--spp", 4, "--passes", 2, "--no-flip")


def _golden(name=GOOD):
    return json.loads((GOLDEN / f"{name}.json").read_text())


def _with(**fields):
    sc = _golden()
    sc.update(fields)
    return json.dumps(sc)


# (file name, bytes or text, the field the failure names, the label it is reported under)
HOSTILE = {
    "not_utf8": ("not_utf8.json", b'{"name": "\xff\xfe"}', "not UTF-8", "not_utf8"),
    "deep_recursion": ("deep_recursion.json", "[" * 100000 + "]" * 100000, "nested too deeply", "deep_recursion"),
    "deep_bounded": ("deep_bounded.json", _with(extra=json.loads("[" * 40 + "]" * 40)), "nested too deeply", "deep_bounded"),
    "not_an_object": ("not_an_object.json", "[1, 2, 3]", "a scene must be a JSON object", "not_an_object"),
    "not_json": ("not_json.json", "{ nope", "not valid JSON", "not_json"),
    "name_not_a_string": ("name_not_a_string.json", _with(name=["a", "b"]), "name", "name_not_a_string"),
    "name_is_metrics": ("name_is_metrics.json", _with(name="metrics.json"), "name", "name_is_metrics"),
    "name_is_dotdot": ("name_is_dotdot.json", _with(name=".."), "name", "name_is_dotdot"),
    "name_is_a_path": ("name_is_a_path.json", _with(name="../../escaped"), "name", "name_is_a_path"),
    "hidden_stem": (".hidden.json", "{ nope", "not valid JSON", "input-1"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_hostile_scene_file_fails_alone_naming_file_and_field(tmp_path, run_batch_here, case):
    """Through batch/run.py's main() in this process (the same run as a child's; the real child of
    this kind: test_repeated_input_options_accumulate, test_a_blend_file_that_is_no_blend_fails_alone)."""
    fname, content, field, label = HOSTILE[case]
    bad = tmp_path / "in" / fname
    bad.parent.mkdir()
    bad.write_bytes(content if isinstance(content, bytes) else content.encode())
    out = tmp_path / "sandbox" / "out"
    out.parent.mkdir()
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    proc = run_batch_here("-i", bad, GOLDEN / f"{GOOD}.json", "--export-only", "--format", "json", "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = metrics(out)["runs"]
    by_scene = {r["scene"]: r for r in runs}
    assert by_scene[GOOD]["status"] == "ok", runs
    assert (out / GOOD / "json" / f"{GOOD}.json").is_file()
    failed = [r for r in runs if r["status"] == "failed"]
    assert [r["scene"] for r in failed] == [label], runs
    assert field in failed[0]["reason"] and str(bad) in failed[0]["reason"], failed[0]["reason"]
    assert (out / "summary.md").is_file() and (out / "report.html").is_file()
    # nothing appears outside OUT; inside it, only the good scene's folder and the run's own files
    after = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*") if out not in p.parents and p != out)
    assert after == before
    assert sorted(p.name for p in out.iterdir()) == sorted([".lock", GOOD, "metrics.json", "report.html", "summary.md"])


def test_ir_json_load_names_the_file_for_every_kind_of_problem(tmp_path):
    """ir_json.load raises a SceneError (never another exception) that names the file."""
    for name, (fname, content, field, _label) in HOSTILE.items():
        path = tmp_path / fname
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        try:
            ir_json.load(path)
        except validate.SceneError as exc:
            if name.startswith("name_") and name != "name_not_a_string":
                continue  # a well-formed name that cannot be an output folder is refused by scene_sources (or the schema)
            assert str(path) in str(exc) and field in str(exc), (name, str(exc))
        else:
            assert name.startswith("name_") and name != "name_not_a_string", name
    missing = tmp_path / "missing.json"
    with pytest.raises(validate.SceneError, match="cannot read"):
        ir_json.load(missing)
    with pytest.raises(validate.SceneError, match="cannot read"):
        ir_json.load(tmp_path)  # a folder, not a file


def test_scene_sources_never_return_an_unsafe_name(tmp_path):
    """Names of failed inputs are labels safe as folder names; hostile scene names are refused."""
    paths = []
    for k, name in enumerate(["..", "a/b", "metrics.json", "summary.md", ".lock", "x\ny", "ok_name"]):
        p = tmp_path / f"s{k}.json"
        p.write_text(_with(name=name))
        paths.append(p)
    results = scene_sources.load(paths + [tmp_path / "nothing_here.json"])
    assert len(results) == len(paths) + 1
    for name, _result in results:
        assert scene_sources.name_problem(name) is None, name
    assert [n for n, r in results if isinstance(r, dict)] == ["ok_name"]


def test_repeated_input_options_accumulate(golden, tmp_path):
    a = write_scene(tmp_path, golden["ggx_copper_50_isolated"])
    b = write_scene(tmp_path, golden["ggx_copper_60_isolated"])
    out = tmp_path / "o"
    proc = run_batch("-i", a, "-i", b, "--export-only", "--format", "json", "-o", out)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert sorted(r["scene"] for r in metrics(out)["runs"]) == ["ggx_copper_50_isolated", "ggx_copper_60_isolated"]


@pytest.mark.slow
def test_a_mesh_that_is_no_mesh_fails_its_scene_alone(tmp_path):
    """Planning (job ids read every mesh) or validation refuses the scene; the good one renders."""
    sc = _golden("dispersion_prism")
    for obj in sc["objects"]:
        if obj["shape"]["type"] == "mesh":
            obj["shape"] = {"type": "mesh", "file": "not_a_mesh.ply", "to_world": obj["shape"]["to_world"]}
    sc["name"] = "prism_with_a_broken_mesh"
    (tmp_path / "not_a_mesh.ply").write_text("this is not a PLY file\n")
    bad = tmp_path / "prism.json"
    bad.write_text(json.dumps(sc))
    out = tmp_path / "o"
    proc = run_batch("-i", bad, GOLDEN / f"{GOOD}.json", "-r", "mitsuba", *TINY, "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert runs[GOOD]["status"] in ("ok", "unjudged"), runs[GOOD]
    assert (out / GOOD / "results" / "mitsuba" / "render.exr").is_file()
    r = runs["prism_with_a_broken_mesh"]
    assert r["status"] == "failed" and r["reason"], r
    assert (out / "summary.md").is_file()


@pytest.mark.slow
def test_a_run_whose_every_scene_failed_writes_its_results_and_exits_1(tmp_path):
    bad1, bad2 = tmp_path / "a.json", tmp_path / "b.json"
    bad1.write_bytes(b"\xff")
    bad2.write_text(_with(name="metrics.json"))
    out = tmp_path / "o"
    proc = run_batch("-i", bad1, bad2, "-r", "mitsuba", *TINY, "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = metrics(out)["runs"]
    assert sorted(r["scene"] for r in runs) == ["a", "b"] and {r["status"] for r in runs} == {"failed"}
    assert "failed" in (out / "summary.md").read_text()


@pytest.mark.slow
def test_a_scene_named_like_the_runs_own_files_cannot_take_them_over(golden, tmp_path):
    """A scene named metrics.json used to crash the run (its folder took metrics.json's place)."""
    sc = copy.deepcopy(golden[GOOD])
    sc["name"] = "metrics.json"
    path = tmp_path / "evil.json"
    path.write_text(json.dumps({k: v for k, v in sc.items() if not k.startswith("_") and k != "needs"}))
    out = tmp_path / "o"
    proc = run_batch("-i", path, GOLDEN / f"{GOOD}.json", "-r", "mitsuba", *TINY, "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert (out / "metrics.json").is_file()
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert runs["evil"]["status"] == "failed" and "name" in runs["evil"]["reason"]
    assert runs[GOOD]["status"] in ("ok", "unjudged")
    assert proc.returncode == 1


@pytest.mark.slow  # over about 1 s of CPU (1.2-2.6 s measured with ART and pbrt built, 2026-12-06: benchmarks/TESTS.md)
def test_a_blend_file_that_is_no_blend_fails_alone(tmp_path):
    bad = tmp_path / "broken.blend"
    bad.write_bytes(b"BLENDER-v500 this is not a blend file")
    out = tmp_path / "o"
    proc = run_batch("-i", bad, GOLDEN / f"{GOOD}.json", "--export-only", "--format", "json", "-o", out)
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert runs[GOOD]["status"] == "ok"
    assert runs["broken"]["status"] == "failed" and str(bad) in runs["broken"]["reason"], runs["broken"]


@pytest.mark.slow
def test_a_scene_folder_that_cannot_be_written_fails_that_scene_naming_the_path(tmp_path):
    """OUT/<scene> taken by a file (as an unwritable scene folder would be): that scene's job fails
    naming the path, the other scene is judged."""
    out = tmp_path / "o"
    out.mkdir()
    (out / "ggx_copper_50_isolated").write_text("a file where the scene's folder goes")
    proc = run_batch("-i", GOLDEN / "ggx_copper_50_isolated.json", GOLDEN / "ggx_copper_60_isolated.json",
                     "-r", "mitsuba", "--scale", "0.0625", "--spp", "4", "-o", out)
    assert proc.returncode == 1, proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    assert runs["ggx_copper_60_isolated"]["status"] == "ok"
    bad = runs["ggx_copper_50_isolated"]
    assert bad["status"] == "failed" and str(out / "ggx_copper_50_isolated") in bad["reason"], bad["reason"]
