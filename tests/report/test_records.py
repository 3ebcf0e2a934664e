"""metrics.json as a contract (issue 24, item 3) and --junit (item 6).

- The schema (schemas/metrics.schema.json) is a valid draft 2020-12 schema, every property in it
  has a description, and the files the runner writes validate against it (also checked for every
  metrics.json the whole test suite writes: tests/conftest.py validate_every_metrics_json).
- A version-1 file (written by the code before schema_version, kept in tests/data/metrics_v1/)
  is read, upgraded and validates; a corrupt one is named; a run folder moved elsewhere still
  resolves its files (paths are relative to it).
- --junit writes JUnit XML that a JUnit parser (junitparser) reads: one test case per job, hostile
  reasons and names included.
"""
import json
import shutil
import subprocess
from pathlib import Path

import junitparser
import pytest

from conftest import ROOT, run_batch, runner_metrics_files, write_hand_made_metrics

DATA = Path(__file__).resolve().parents[1] / "data" / "metrics_v1"


def _records():
    from spectral_bench.batch import records
    return records


# -- the schema ------------------------------------------------------------------------------------
def _undescribed(node, where="#"):
    """Every property (and $defs entry) of a schema without a description."""
    out = []
    if isinstance(node, dict):
        for key in ("properties", "$defs"):
            for name, sub in (node.get(key) or {}).items():
                if isinstance(sub, dict) and not sub.get("description"):
                    out.append(f"{where}/{key}/{name}")
        for key, sub in node.items():
            out += _undescribed(sub, f"{where}/{key}")
    elif isinstance(node, list):
        for k, sub in enumerate(node):
            out += _undescribed(sub, f"{where}/{k}")
    return out


def test_the_schema_is_valid_and_every_property_is_described():
    import jsonschema
    records = _records()
    schema = json.loads(records.SCHEMA_FILE.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["properties"]["schema_version"]["const"] == records.SCHEMA_VERSION == 2
    assert not _undescribed(schema), _undescribed(schema)
    # every field a run record is built with, and the contract's fields of the other helpers, are described
    run = schema["$defs"]["run"]["properties"]
    built = records.run_record("s", {"case": "c"}, "mitsuba", mode="m", spp=4, resolution=[8, 8], job="0" * 20)
    assert set(built) <= set(run) and {"detectable", "baseline", "pass_times", "retried", "versions",
                                       "approximated", "reference", "reference_problems", "sanity", "test"} <= set(run)


def test_the_schema_refuses_what_the_contract_forbids():
    """Absolute or escaping paths of files inside the run folder, unknown fields of a run record,
    a missing version: each is named by its field."""
    records = _records()
    data = records.read(DATA / "copper").resolved()  # every path absolute, as the code before issue 24 kept them
    assert any(p.startswith("runs/0/image:") for p in records.validate(data)), records.validate(data)
    bad = json.loads(json.dumps(records.read(DATA / "copper")))
    bad["runs"][0]["image"] = "../elsewhere/render.exr"
    bad["runs"][0]["surprise"] = 1
    del bad["schema_version"]
    problems = records.validate(bad)
    assert any(p.startswith("runs/0/image:") for p in problems)
    assert any(p.startswith("runs/0:") and "surprise" in p for p in problems)
    assert any(p.startswith("(top level):") and "schema_version" in p for p in problems), problems


# -- reading: version 1, corrupt files ---------------------------------------------------------------
@pytest.mark.parametrize("name", ["copper", "studies"])
def test_a_version_1_file_is_read_upgraded_and_validates(name, tmp_path):
    """tests/data/metrics_v1: metrics.json written by the code before issue 24 (``batch/run.py -s
    ggx_copper_50 --scale 0.125 --spp 4 -r mitsuba``; and a run with probes, --sweep and --stability,
    trimmed), with absolute reference and image paths."""
    records = _records()
    original = json.loads((DATA / name / "metrics.json").read_text())
    assert "schema_version" not in original
    run = records.read(DATA / name / "metrics.json")
    assert run.read_version == 1 and run["schema_version"] == 2 and run["tool"] == {"version": None, "commit": None}
    assert records.validate(run) == []
    assert run.file == DATA / name / "metrics.json" and run.folder == DATA / name
    # paths are now relative to the run folder, and resolve to the files the old file named
    for old, new in zip(original["runs"], run["runs"]):
        if "reference" in old:
            assert not Path(new["reference"]["path"]).is_absolute()
            assert run.path(new["reference"]["path"]) == Path(old["reference"]["path"])
        assert new["image"] == old["image"] and run.path(new["image"]) == DATA / name / old["image"]
    for k, (old, new) in enumerate(zip(original.get("jobs", []), run.get("jobs", []))):
        # inside the run folder where it was written (/tmp/rec/v1rich): moved along with the file
        assert Path(old["image_path"]).is_absolute() and new["image_path"] == old["image"]
        assert run.resolved()["jobs"][k]["image_path"] == str(DATA / name / old["image"])
    assert name != "studies" or len(original["jobs"]) == 4
    # everything else is as it was
    strip = lambda d: {k: v for k, v in d.items() if k not in ("reference", "image", "reference_problems")}  # noqa: E731
    assert [strip(r) for r in run["runs"]] == [strip(r) for r in original["runs"]]
    assert run["options"] == original["options"] and run["started"] == original["started"]


@pytest.mark.parametrize("content, words", [
    (b"{\"runs\": [", "is not a readable metrics.json"),
    (b"\xff\xfe not utf-8", "is not a readable metrics.json"),
    (b"[1, 2]", "an object expected, got list"),
    (b"{\"schema_version\": \"two\", \"runs\": []}", "schema_version 'two' is not a version"),
    (b"{\"schema_version\": 99, \"runs\": []}", "written by a newer spectral_bench"),
])
def test_a_corrupt_file_is_named(tmp_path, content, words):
    records = _records()
    folder = tmp_path / "run"
    folder.mkdir()
    write_hand_made_metrics(folder, "")
    (folder / "metrics.json").write_bytes(content)
    with pytest.raises(records.RecordError) as err:
        records.read(folder)
    assert str(folder / "metrics.json") in str(err.value) and words in str(err.value), err.value
    if b"schema_version" in content:  # the report and the panel show what they can of it, saying what they passed over
        run = records.read(folder, strict=False)
        assert run["runs"] == [] and words in run.problems[0]
    with pytest.raises(records.RecordError):
        records.read(tmp_path / "missing")


def test_a_corrupt_file_cannot_be_resumed_and_is_named(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    write_hand_made_metrics(out, '{"schema_version": 7, "options": {}, "runs": []}')
    proc = run_batch("--resume", out)
    assert proc.returncode == 2 and str(out / "metrics.json") in proc.stderr and "newer spectral_bench" in proc.stderr, \
        proc.stderr[-2000:]


def test_the_noise_test_line():
    """One wording for summary.md, report.html and the panel (batch/records.py noise_test_text)."""
    text = _records().noise_test_text
    assert text({"p_min": 0.731, "threshold": 0.00334, "z_max": 0.344, "pass": True}) == \
        "pass: p_min 0.731 (threshold 0.00334), z_max 0.34"
    assert text({"p_min": 1e-9, "threshold": 0.00334, "z_max": 8.1, "pass": False, "reason": "x"}) == \
        "FAIL: p_min 1e-09 (threshold 0.00334), z_max 8.10"
    assert text({"pass": None, "reason": "one pass:\n no noise"}) == "not judged: one pass: no noise"
    assert text({"pass": False, "reason": "render channels lack R"}) == "FAIL: render channels lack R"
    assert text(None) == "" and text([1]) == "" and text({"pass": "yes", "p_min": "a"}) == "not judged"
    from spectral_bench.batch.report import summary
    row = {"scene": "s", "backend": "b", "status": "failed", "reason": "",
           "test": {"p_min": 1e-9, "threshold": 0.00334, "z_max": 8.1, "pass": False}}
    assert "| FAIL: p_min 1e-09 (threshold 0.00334), z_max 8.10 |" in summary.table([row])


# -- what the runner writes -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A real run: a rendered, judged scene (ok), ART (skipped where no artist is installed) and a
    scene that does not exist (failed on each backend); with --junit (about 10 s)."""
    base = tmp_path_factory.mktemp("records")
    out, xml = base / "out", base / "junit.xml"
    proc = run_batch("-r", "mitsuba", "-r", "art", "-s", "ggx_copper_50", "-s", "no_such_scene", "--scale", 0.125,
                     "--spp", 4, "-o", out, "--junit", xml)
    assert proc.returncode == 1 and (out / "metrics.json").is_file(), proc.stderr[-3000:]
    return out, xml, proc


@pytest.mark.slow
def test_the_runner_writes_the_contract(run, tmp_path):
    """schema_version, the tool's version and commit, paths relative to the run folder; the folder
    moved elsewhere still names its files."""
    import tomllib
    records = _records()
    out, _xml, _proc = run
    data = json.loads((out / "metrics.json").read_text())
    assert data["schema_version"] == records.SCHEMA_VERSION and records.validate(data) == []
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    git = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    assert data["tool"] == {"version": manifest["version"], "commit": git.stdout.strip() if git.returncode == 0 else None}
    copper = next(r for r in data["runs"] if r["backend"] == "mitsuba" and r["scene"] == "ggx_copper_50")
    assert copper["status"] == "ok" and copper["image"] == "ggx_copper_50/results/mitsuba/render.exr"
    assert copper["reference"]["path"] == Path(
        __import__("os").path.relpath(ROOT / "references" / "ggx_copper_50.exr", out)).as_posix()
    assert runner_metrics_files(out.parent)[0] == [out / "metrics.json"]
    moved = tmp_path / "elsewhere" / "moved"
    shutil.copytree(out, moved)
    again = records.read(moved).resolved()
    image = Path(next(r for r in again["runs"] if r["scene"] == "ggx_copper_50" and r["backend"] == "mitsuba")["image"])
    assert image == moved / "ggx_copper_50" / "results" / "mitsuba" / "render.exr" and image.is_file()


@pytest.mark.slow
def test_junit_xml_from_the_runner(run):
    out, xml, _proc = run
    data = _records().read(out)
    suites = list(junitparser.JUnitXml.fromfile(str(xml)))
    assert len(suites) == 1
    cases = {(c.classname, c.name): c for c in suites[0]}
    assert len(cases) == len(data["runs"]) == suites[0].tests
    for r in data["runs"]:
        case = cases[(r["scene"], f"{r['backend']}/{r['mode']}" if r["mode"] else r["backend"])]
        if r["status"] == "failed":
            assert not case.is_passed and case.result[0].message == r["reason"]
        elif r["status"] in ("skipped", "unsupported", "unjudged"):
            assert case.is_skipped and case.result[0].message == f"{r['status']}: {r['reason']}"
        else:
            assert case.is_passed and case.time == pytest.approx(r["time_s"], abs=1e-3)
    assert suites[0].failures == sum(r["status"] == "failed" for r in data["runs"]) == 2


# -- --junit against hostile input --------------------------------------------------------------------
HOSTILE = "a<b>&\"c' ]]> \x00\x1b[31m\ud800 end\u2028 \U0001F600"


def _case_properties(case):
    props = case.child(junitparser.Properties)
    return {p.name: p.value for p in props} if props is not None else {}


def test_junit_xml_names_every_status(tmp_path):
    """Every status, as the parser reads it back; names and reasons hostile (markup, CDATA end,
    NUL and escape characters, a lone surrogate, a line separator, an emoji)."""
    from spectral_bench.batch.report import junit
    records = _records()
    runs = []
    for k, status in enumerate(["ok", "failed", "known", "fixed", "unjudged", "skipped", "unsupported", "brand_new"]):
        runs.append(records.run_record(f"scene{k}{HOSTILE}", {"case": "c"}, f"back{HOSTILE}", mode=f"m{k}", spp=4,
                                       resolution=[8, 8], status=status, reason=f"why {status} {HOSTILE}",
                                       time_s=1.5 + k, known=["dev-a", "dev<b>"] if status == "known" else [],
                                       fixed=["dev-c"] if status == "fixed" else [],
                                       test={"pass": status != "failed", "p_min": 0.5, "threshold": 0.01, "z_max": 1.0}))
    runs.append("not a record")
    path = junit.write(tmp_path / "junit.xml", runs, name=f"suite {HOSTILE}")
    xml = junitparser.JUnitXml.fromfile(str(path))
    suite = next(iter(xml))
    cases = list(suite)
    assert len(cases) == 8 and suite.tests == 8 and suite.failures == 2 and suite.skipped == 3
    clean = junit._text(HOSTILE)
    assert "\ufffd" in clean and "\x00" not in clean and "]]>" in clean and "<b>" in clean
    for case, r in zip(cases, runs):
        props = _case_properties(case)
        assert case.classname == junit._text(r["scene"]) and case.name == junit._text(f"{r['backend']}/{r['mode']}")
        assert case.time == pytest.approx(r["time_s"]) and props["status"] == r["status"]
        reason = junit._text(r["reason"])
        if r["status"] in ("failed", "brand_new"):
            assert isinstance(case.result[0], junitparser.Failure) and case.result[0].message.endswith(reason)
        elif r["status"] in ("unjudged", "skipped", "unsupported"):
            assert case.is_skipped and case.result[0].message == f"{r['status']}: {reason}"
        else:
            assert case.is_passed
    assert _case_properties(cases[2])["known"] == "dev-a, dev<b>"
    assert _case_properties(cases[3])["fixed"] == "dev-c"
    assert _case_properties(cases[0])["noise test"] == "pass: p_min 0.5 (threshold 0.01), z_max 1.00"


def test_junit_to_a_missing_folder_is_a_usage_error(tmp_path):
    proc = run_batch("-s", "ggx_copper_50", "-r", "mitsuba", "-o", tmp_path / "out", "--junit", tmp_path / "no" / "j.xml")
    assert proc.returncode == 2 and "--junit" in proc.stderr and str(tmp_path / "no") in proc.stderr, proc.stderr[-2000:]
    assert not (tmp_path / "out" / "metrics.json").exists()


# -- per-block arrays beside the image (issue 31: metrics.json <= 500 kB) --------------------------
def _run_with_block_arrays(n=3000):
    records = _records()
    rng = __import__("numpy").random.default_rng(7)
    stat = {"z": 3.5, "pass": True, "measured": rng.random(n).tolist(), "se": (rng.random(n) * 1e-3).tolist(),
            "dof": [831.0] * n, "ids": list(range(n)), "few": [0.1, 0.2, 0.3], "mixed": [1, 2.5] * 40}
    alt = dict(stat, expected=rng.random(n).tolist())
    run = records.run_record("ggx_copper_80_isolated", {"case": "reflectance"}, "mitsuba", mode="m", spp=4,
                             resolution=[8, 8], job="0" * 20)
    run["probes"] = [{"name": "ggx blocks", "pass": True, "stat": stat, "alternatives": {"mitsuba3": alt}},
                     {"name": "other", "pass": True}]
    return run


def test_long_block_arrays_are_stored_beside_the_image_and_read_back_exactly(tmp_path):
    """Lists of more than 64 floats (or ints) in a probe's stat and alternatives go into one .npz
    beside the run's image; the file keeps short and mixed lists; read() returns the very lists
    (float64 exactly); writing again reuses the file (named by its content)."""
    records = _records()
    out = tmp_path / "out"
    image = out / "ggx_copper_80_isolated" / "results" / "mitsuba" / "render.exr"
    image.parent.mkdir(parents=True)
    run = _run_with_block_arrays()
    run["image"] = str(image)
    want = dict(json.loads(json.dumps(run)), image="ggx_copper_80_isolated/results/mitsuba/render.exr")
    records.write(out, "2026-12-02T00:00:00", {}, [run])
    text = (out / "metrics.json").read_text()
    written = json.loads(text)
    assert not records.validate(written), records.validate(written)
    stat = written["runs"][0]["probes"][0]["stat"]
    for key in ("measured", "se", "dof", "ids"):
        assert set(stat[key]) == {"array_file", "key"}, stat[key]
    assert stat["few"] == [0.1, 0.2, 0.3] and stat["mixed"] == [1, 2.5] * 40 and stat["z"] == 3.5
    files = sorted(image.parent.glob("probe_arrays-*.npz"))
    assert len(files) == 1 and stat["measured"]["array_file"] == files[0].relative_to(out).as_posix()
    assert len(text) < 20_000 < files[0].stat().st_size  # the numbers moved, not dropped
    back = records.read(out)
    assert back["runs"] == [want] and not back.problems
    assert type(back["runs"][0]["probes"][0]["stat"]["ids"][0]) is int
    records.write(out, "2026-12-02T00:00:00", {}, [back["runs"][0]])  # a resumed run writes it again
    assert sorted(image.parent.glob("probe_arrays-*.npz")) == files and records.read(out)["runs"] == [want]
    moved = tmp_path / "moved"
    shutil.move(out, moved)  # the folder moves with its arrays
    assert records.read(moved)["runs"] == [want]


def test_a_record_written_again_is_the_same_text_as_the_whole_document(tmp_path):
    """records.write keeps each run record's text between writes (the runner writes the file after
    every job, issue 45 item 1): after each of a run's writes the file is json.dumps of the whole
    document, as written without keeping anything; a record changed in place, a new one, one
    removed, and a deleted array file (written again) all show."""
    records = _records()
    out = tmp_path / "out"
    runs = []
    for i in range(4):
        image = out / f"s{i}" / "results" / "mitsuba" / "render.exr"
        image.parent.mkdir(parents=True)
        run = _run_with_block_arrays(100 + i)
        run.update(image=str(image), scene=f"s{i}")
        runs.append(run)

    def written_as_a_whole(now):
        data = records.document(out, "2026-12-02T00:00:00", {"o": 1}, now, [{"job": "x", "kind": "sweep", "scene": "s0", "backend": "mitsuba", "status": "rendered"}])
        records._store_arrays(data, out)
        assert (out / "metrics.json").read_text() == json.dumps(data, indent=1) + "\n"

    for n in range(len(runs) + 1):
        records.write(out, "2026-12-02T00:00:00", {"o": 1}, runs[:n], [{"job": "x", "kind": "sweep", "scene": "s0", "backend": "mitsuba", "status": "rendered"}])
        written_as_a_whole(runs[:n])
    runs[1]["status"] = "failed"  # changed in place after it was written
    runs[2]["probes"][0]["stat"]["measured"][0] = 0.5
    npz = next((out / "s3" / "results" / "mitsuba").glob("probe_arrays-*.npz"))
    npz.unlink()
    records.write(out, "2026-12-02T00:00:00", {"o": 1}, runs, [{"job": "x", "kind": "sweep", "scene": "s0", "backend": "mitsuba", "status": "rendered"}])
    written_as_a_whole(runs)
    assert npz.is_file() and records.read(out)["runs"][3]["probes"][0]["stat"]["measured"] == runs[3]["probes"][0]["stat"]["measured"]
    records.write(out, "2026-12-02T00:00:00", {"o": 1}, runs[2:], [{"job": "x", "kind": "sweep", "scene": "s0", "backend": "mitsuba", "status": "rendered"}])  # fewer, and no other section first
    written_as_a_whole(runs[2:])
    assert records.read(out)["runs"][0]["probes"][0]["stat"]["measured"][0] == 0.5


@pytest.mark.parametrize("damage", ["missing", "outside", "not npz", "no such key"])
def test_a_block_array_that_cannot_be_read_is_named(tmp_path, damage):
    """Strict (resume, compare): RecordError naming metrics.json, the scene and the array file;
    lenient (report, panel): the array reads as None and the problem is listed. A reference out of
    the run folder is never opened."""
    records = _records()
    out = tmp_path / "out"
    image = out / "s" / "render.exr"
    image.parent.mkdir(parents=True)
    run = _run_with_block_arrays(100)
    run["image"] = str(image)
    records.write(out, "2026-12-02T00:00:00", {}, [run])
    data = json.loads((out / "metrics.json").read_text())
    ref = data["runs"][0]["probes"][0]["stat"]["measured"]
    npz = out / ref["array_file"]
    if damage == "missing":
        npz.unlink()
    elif damage == "outside":
        secret = tmp_path / "elsewhere.npz"
        shutil.copy(npz, secret)
        ref["array_file"] = "../elsewhere.npz"
    elif damage == "not npz":
        npz.write_bytes(b"PK not a zip")
    else:
        ref["key"] = "a99"
    (out / "metrics.json").write_text(json.dumps(data))
    with pytest.raises(records.RecordError) as err:
        records.read(out)
    assert "metrics.json" in str(err.value) and "ggx_copper_80_isolated" in str(err.value), err.value
    assert (ref["array_file"] in str(err.value)), err.value
    lenient = records.read(out, strict=False)
    assert lenient["runs"][0]["probes"][0]["stat"]["measured"] is None and len(lenient.problems) == 1, lenient.problems
    se = lenient["runs"][0]["probes"][0]["stat"]["se"]
    assert se is None if damage in ("missing", "not npz") else len(se) == 100  # a broken file: every array in it
