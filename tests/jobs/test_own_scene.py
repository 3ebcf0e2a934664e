"""A new scenario (thesis 3.4.3): a scene written by hand as docs/scenes.md's "Add your own scene"
shows (examples/scenes/), listed, given a reference and judged; and every output says what judged
a render, so a scene no probe fits, judged against a reference its own renderer made, reads as a
regression check ("checked against itself: detects change, not error"), never as a plain ok."""
import json
from xml.etree import ElementTree as ET

import pytest

from conftest import ROOT, metrics, run_batch

EXAMPLES = ROOT / "examples" / "scenes"
SELF = "checked against itself: detects change, not error"


def test_the_minimal_example_loads_as_written():
    """The example leaves out ``needs`` (derived on load, as docs/scene-format.md says)."""
    from spectral_bench.exporters import ir_json
    raw = json.loads((EXAMPLES / "red_sphere.json").read_text())
    assert "needs" not in raw
    scene = ir_json.load(EXAMPLES / "red_sphere.json")
    assert scene["needs"] == ["spectral"]  # a ColorChecker reflectance and D65 are spectra


def test_list_shows_load_errors_and_exits_2(tmp_path, run_batch_here):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "spectral-bench-scene", "version": 1, "name": "bad", "case": "custom"}))
    proc = run_batch_here("--list", "-r", "mitsuba", "-i", bad, EXAMPLES / "red_sphere.json")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stdout.splitlines()
    assert "red_sphere\tcustom\tmitsuba" in lines
    err = [l for l in lines if l.startswith("bad\tERROR\t")]
    assert len(err) == 1 and "field '(root)'" in err[0] and "'render' is a required property" in err[0], lines
    assert "1 scene(s) could not be loaded" in proc.stderr
    ok = run_batch_here("--list", "-r", "mitsuba", "-i", EXAMPLES / "red_sphere.json")
    assert ok.returncode == 0 and ok.stdout.splitlines() == ["red_sphere\tcustom\tmitsuba"]


@pytest.fixture(scope="module")
def judged(tmp_path_factory):
    """References for both example scenes made as docs/scenes.md says (at 256 spp instead of the
    default, into a folder of their own), then one run judging both with them."""
    tmp = tmp_path_factory.mktemp("own")
    refs, out = tmp / "refs", tmp / "out"
    scenes = [EXAMPLES / "red_sphere.json", EXAMPLES / "two_spheres.json"]
    import subprocess
    import sys
    made = subprocess.run([sys.executable, str(ROOT / "batch" / "make_references.py"), "-i", *map(str, scenes),
                           "--spp", "256", "--out", str(refs)], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert made.returncode == 0, made.stderr[-3000:]
    proc = run_batch("-i", *scenes, "--references", refs, "-r", "mitsuba", "-o", out, "--junit", tmp / "junit.xml")
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = metrics(out)
    return {"out": out, "stdout": proc.stdout, "junit": tmp / "junit.xml",
            "runs": {r["scene"]: r for r in data.entries("runs")}}


@pytest.mark.slow
def test_a_scene_a_probe_fits_is_judged_by_it(judged):
    from spectral_bench.batch.report import results
    run = judged["runs"]["red_sphere"]
    assert run["status"] == "ok" and run["reference"]["backend"] == "mitsuba"
    assert results.probes_measured(run) == (1, 1)  # the lone Lambertian sphere: rho L
    assert not results.checked_against_itself(run)
    # the run's power: it would have seen a 1 % radiance error (the probe and the reference)
    assert run["detectable"]["scale"] < 0.01, run["detectable"]


@pytest.mark.slow
def test_a_probe_less_scene_against_its_own_renderers_reference_says_so_everywhere(judged):
    from spectral_bench.batch.report import results
    run = judged["runs"]["two_spheres"]
    assert run["status"] == "ok" and results.probes_measured(run) == (0, 0)
    assert results.checked_against_itself(run) and SELF in results.judged_by(run)
    assert run["detectable"]["scale"] < 0.01, run["detectable"]  # it does detect change
    # summary.md (also printed): the status cell, the probes column and the footnote
    summary = (judged["out"] / "summary.md").read_text()
    row = next(l for l in summary.splitlines() if l.startswith("| ok (checked against itself) | two_spheres |"))
    assert row.split("|")[-3].strip() == "none"
    red = next(l for l in summary.splitlines() if "| red_sphere |" in l)
    assert red.startswith("| ok | red_sphere |") and red.split("|")[-3].strip() == "1/1 pass"
    assert "*checked against itself*" in summary and "*checked against itself*" in judged["stdout"]
    # report.html: the summary table and the viewer's "judged by" line naming who made the reference
    html = (judged["out"] / "report.html").read_text()
    assert html.count("(checked against itself)") >= 1 and SELF in html
    assert "judged by: 1 probe (1 passed); reference by mitsuba llvm_ad_spectral, 256 spp" in html
    # JUnit: a property on each test case
    props = {c.get("classname"): {p.get("name"): p.get("value") for p in c.iter("property")}
             for c in ET.parse(judged["junit"]).getroot().iter("testcase")}
    assert SELF in props["two_spheres"]["judged by"]
    assert SELF not in props["red_sphere"]["judged by"] and "1 probe (1 passed)" in props["red_sphere"]["judged by"]
