"""A spectral job in the report (issue 33 item 3), on a real spectral render (tests/spectral_fixture.py:
the example renderer's spectral route on four Lambertian patches, one with a planted +15 % over
480-500 nm): the band data the page decodes is the preview EXR's half floats exactly; the band
record is read defensively; the summary and JUnit name the planted patch's worst band inside the
planted range; and in headless Chromium, opening the section loads the bands, moving the slider
redraws the canvas with that band's values (sRGB of the half float) and each region has its plot
with one point per band, the planted bands marked."""
import html as html_text
import json
import re
import zlib
from pathlib import Path

import numpy as np
import pytest

from spectral_fixture import PLANT, PATCHES, spectral_run
from installed import CHROMIUM, chromium


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from spectral_bench.batch.report import html
    out = tmp_path_factory.mktemp("spectra") / "out"
    out.mkdir()
    job = spectral_run(out)
    html.write(out)
    return out, job


def _decode_data_js(path):
    """(w, h, {layer: {channel: H x W float32}}) of a view.js-style data file, decoded as
    templates/viewer.js does (x-user-defined bytes, string escapes, zlib, binary16 split bytes)."""
    raw = path.read_bytes()
    head = re.match(rb'spectralBench\.data\(document\.currentScript, \{"w": (\d+), "h": (\d+), "layers": \{', raw)
    w, h = int(head.group(1)), int(head.group(2))
    layers = {}
    for m in re.finditer(rb'"([^"]+)": \{"channels": (\[[^\]]*\]), "data": "((?:[^"\\]|\\.)*)"\}', raw[head.end():], re.S):
        data = re.sub(rb"\\(.)", lambda e: {b"n": b"\n", b"r": b"\r"}.get(e.group(1), e.group(1)), m.group(3))
        b = np.frombuffer(zlib.decompress(data), dtype=np.uint8)
        half = b[: b.size // 2].astype(np.uint16) | (b[b.size // 2:].astype(np.uint16) << 8)
        planes = half.view(np.float16).astype(np.float32).reshape(-1, h, w)
        layers[m.group(1).decode()] = dict(zip(json.loads(m.group(2)), planes))
    return w, h, layers


@pytest.mark.slow
def test_band_data_is_the_previews_half_floats(run):
    from spectral_bench.batch import spectral_exr
    out, job = run
    img = spectral_exr.read(job / "spectral_preview.exr")
    w, h, layers = _decode_data_js(job / "spectral_preview.js")
    cube = img.stokes[0]
    assert (h, w) == cube.shape[:2] and list(layers) == ["bands"] and len(layers["bands"]) == cube.shape[2] == 94
    for i in range(cube.shape[2]):
        np.testing.assert_array_equal(layers["bands"][str(i)], cube[..., i].astype(np.float32))  # the EXR is half: exact


def test_record_is_read_defensively():
    from spectral_bench.batch.report import spectra
    good = {"centres_nm": [500.0, 510.0, 520.0], "threshold": 0.01,
            "regions": [{"region": "a", "measured": [1.0, 2.0, 3.0], "se": [0.1, 0.1, 0.1], "expected": [1.0, 1.0, 3.0],
                         "pass": False},
                        {"region": "short", "measured": [1.0], "expected": [1.0]}, "not a dict"]}
    rec = spectra.record({"bands": good})
    assert [r["region"] for r in rec["regions"]] == ["a"]  # the region whose arrays do not fit is left out
    assert rec["edges"] == [(495.0, 505.0), (505.0, 515.0), (515.0, 525.0)]  # no edges_nm: midway, outer half a spacing
    assert rec["regions"][0]["z"][1] == pytest.approx(10.0) and rec["regions"][0]["failing"] == [1]
    assert spectra.worst_lines({"bands": good}) == ["a 505-515 nm: 100 % high, z 10"]  # 3 significant digits (issue 40: not "1e+02 %")
    for bad in (None, "x", {"centres_nm": [500]}, {"centres_nm": [510, 500]}, {"centres_nm": ["a", "b"]},
                {"centres_nm": [500, float("nan")]}):
        assert spectra.record({"bands": bad}) is None and spectra.worst_lines({"bands": bad}) == []
    p = spectra.plot(rec, rec["regions"][0])
    assert len(p["points"]) == 3 and [q["fail"] for q in p["points"]] == [False, True, False] and len(p["failing"]) == 1


@pytest.mark.slow
def test_summary_and_junit_name_the_planted_band(run):
    from spectral_bench.batch import records
    from spectral_bench.batch.report import junit, summary
    out, _ = run
    runs = records.read(out, strict=False)["runs"]
    text = summary.spectra_table(runs)
    lines = [l for l in text.splitlines() if l.startswith("| patches")]
    assert len(lines) == 1, text  # only the planted patch fails
    m = re.search(r"planted (\d+)-(\d+) nm: ([0-9.]+) % (high|low), z ([0-9.e+-]+)", lines[0])
    assert m, lines[0]
    lo, hi = float(m.group(1)), float(m.group(2))
    assert PLANT[0] <= lo and hi <= PLANT[1] and m.group(4) == "high" and float(m.group(5)) > 4, lines[0]
    case = junit.testcase(runs[0])
    assert case.find("properties/property[@name='worst bands']").get("value") in lines[0]


# opens the spectra section, waits for its data, moves the slider to band __A__ then __B__ and
# reads the band canvas at the pixels __XY__ after each; counts each plot's points
SLIDE = """
var d=document.querySelector('details.spectra');
var before={scripts: document.querySelectorAll('script[src$="spectral_preview.js"], script[src$="spectral_plots.js"]').length, plots: d.querySelector('.plots').childElementCount};
d.open=true;
(function wait(){ if(!d.dataset.ready){ setTimeout(wait, 50); return; }
  var s=d.querySelector('input.band'), c=d.querySelector('canvas.band-canvas'), got={};
  [__A__, __B__].forEach(function(k){ s.value=String(k); s.dispatchEvent(new Event('input'));
    got['band'+k]={px: __XY__.map(function(p){ return Array.from(c.getContext('2d').getImageData(p[0], p[1], 1, 1).data); }), nm: d.querySelector('.band-nm').textContent,
                   band: d.dataset.band}; });
  got.before=before; got.max=s.max; got.size=[c.width, c.height];
  got.plots=Array.from(d.querySelectorAll('.plots svg')).map(function(svg){ return {label: svg.getAttribute('aria-label'),
    cls: svg.getAttribute('class'), points: svg.querySelectorAll('circle').length, red: svg.querySelectorAll('circle.f').length,
    bars: svg.querySelectorAll('line.eb').length, expected: svg.querySelector('polyline.exp').getAttribute('points').trim().split(/\\s+/).length}; });
  document.body.dataset.result=JSON.stringify(got); })();
"""


def srgb(x):
    """The sRGB encoding (IEC 61966-2-1) of x in [0, 1], in 8-bit steps (not rounded)."""
    v = min(max(x, 0.0), 1.0)
    return 255 * (12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055)


@pytest.mark.slow
@pytest.mark.skipif(not CHROMIUM, reason="no chromium: the page not checked in a browser (scripts/setup.sh installs it as root)")
def test_slider_shows_the_bands_data_and_plots_have_every_band(run):
    from spectral_bench.batch import spectral_exr
    out, job = run
    cube = spectral_exr.read(job / "spectral_preview.exr").stokes[0]
    xy = [((x0 + x1) // 2, (y0 + y1) // 2) for _, (x0, y0, x1, y1) in PATCHES.values()]  # each patch's centre
    wls = spectral_exr.read(job / "spectral_preview.exr").wavelengths_nm
    a, b = (int(np.searchsorted(wls, nm)) for nm in (440.0, 650.0))  # blue patch bright, red dark; then the other way
    page = (out / "report.html").read_text()
    script = SLIDE.replace("__A__", str(a)).replace("__B__", str(b)).replace("__XY__", json.dumps(xy))
    probe = out / "probe_spectra.html"
    probe.write_text(page.replace("</body>", "<script>window.addEventListener('load', function(){" + script + "});</script></body>"))
    dom = chromium("--dump-dom", probe.as_uri())
    m = re.search(r'data-result="([^"]*)"', dom)
    assert m, "the spectra section never got its data"
    got = json.loads(html_text.unescape(m.group(1)))
    assert got["before"] == {"scripts": 0, "plots": 0}  # nothing of the section loads before it is opened
    assert got["size"] == [cube.shape[1], cube.shape[0]] and got["max"] == str(cube.shape[2] - 1)
    for k in (a, b):
        for (x, y), px in zip(xy, got[f"band{k}"]["px"]):
            # grey: the band's half float, sRGB-encoded (to the 8-bit step, as the viewer's table rounds)
            assert px[0] == px[1] == px[2] and px[3] == 255 and abs(px[0] - srgb(float(cube[y, x, k]))) <= 1.01, (k, x, y, px, cube[y, x, k])
        assert got[f"band{k}"]["band"] == str(k)
    red, blue = list(PATCHES).index("red"), list(PATCHES).index("blue")
    assert got[f"band{a}"]["px"][blue][0] > got[f"band{a}"]["px"][red][0] + 50  # 440 nm: the blue patch bright
    assert got[f"band{b}"]["px"][red][0] > got[f"band{b}"]["px"][blue][0] + 50  # 650 nm: the red patch bright
    assert got[f"band{a}"]["nm"] == "440-445 nm" and got[f"band{b}"]["nm"] == "650-655 nm"
    assert sorted(p["label"] for p in got["plots"]) == sorted(PATCHES)
    for p in got["plots"]:
        assert p["points"] == p["bars"] == p["expected"] == 94, p
        assert ("FAIL" in p["cls"]) == (p["label"] == "planted") and (p["red"] > 0) == (p["label"] == "planted"), p
    planted = next(p for p in got["plots"] if p["label"] == "planted")
    assert planted["red"] <= (PLANT[1] - PLANT[0]) / 5  # only bands inside the planted range are marked


@pytest.mark.slow
def test_hostile_band_record_is_text_and_links_nothing_outside(run, tmp_path):
    """Anyone's metrics.json: a region label of markup, a preview path out of the folder, arrays of
    the wrong kind. The page shows the labels as text, links no preview outside the job's folder
    and keeps every other region's plot; a preview that is no spectral EXR leaves the plots."""
    import shutil
    from spectral_bench.batch.report import html
    out, _ = run
    copy = tmp_path / "out"
    shutil.copytree(out, copy)
    data = json.loads((copy / "metrics.json").read_text())
    rec = data["runs"][0]["bands"]
    rec["regions"][3]["region"] = "<img src=x onerror=alert(1)>"  # the failing one: its worst band is on the page
    job_dir = lambda o: o / "patches" / "results" / "toy_spectral"  # noqa: E731
    rec["regions"][1]["measured"] = "not a list"
    rec["regions"][2]["se"] = [None] * len(rec["centres_nm"])
    for preview, linked in (("../../../etc/passwd", False), ("render.exr", False), ("spectral_preview.exr", True)):
        rec["preview"] = preview
        (copy / "metrics.json").write_text(json.dumps(data))
        page = html.render(copy)
        plots = json.loads(re.fullmatch(r"spectralBench\.markup\(document\.currentScript, (.*)\);\n",
                                        (job_dir(copy) / html.PLOTS_JS).read_text(), re.S).group(1))
        for text in (page, plots):
            assert "<img src=x" not in text
        assert "&lt;img src=x onerror=alert(1)&gt;" in plots and "&lt;img src=x onerror=alert(1)&gt;" in page
        assert plots.count("<svg class='spectrum") == len(PATCHES) - 1  # the region with no measured list is left out
        assert ("spectral_preview.js' data-plots" in page) == linked and "passwd" not in page, preview


@pytest.mark.slow
def test_a_regenerated_report_rewrites_the_data_files_its_page_loads(run, tmp_path):
    """The run folder copied with its times (a report made again elsewhere, later): its view.js and
    spectral_preview.js are newer than their EXRs, but one holds a foreign script and the render
    EXR was replaced (given an older time) since the other was written. Writing the report again
    writes both from the EXRs as they are: a data file is a script the page runs."""
    import os
    import shutil
    from spectral_bench.batch import exr
    from spectral_bench.batch.report import html
    out = tmp_path / "copy"
    shutil.copytree(run[0], out)  # copy2: the times travel with the files
    job = out / Path(*run[1].relative_to(run[0]).parts)
    (job / "spectral_preview.js").write_text('alert("not from this run");\n')
    names, img, se = exr.read_image_and_stderr(job / "render.exr")
    exr.write(job / "render.exr", img[..., :3] * 2.0 + 0.25)
    old = (job / "view.js").stat().st_mtime - 3600
    os.utime(job / "render.exr", (old, old))
    assert (job / "view.js").stat().st_mtime > (job / "render.exr").stat().st_mtime
    assert (job / "spectral_preview.js").stat().st_mtime > (job / "spectral_preview.exr").stat().st_mtime
    html.write(out)
    assert b"not from this run" not in (job / "spectral_preview.js").read_bytes()
    cube = spectral_exr_cube(job / "spectral_preview.exr")
    w, h, layers = _decode_data_js(job / "spectral_preview.js")
    for i in range(cube.shape[2]):
        np.testing.assert_array_equal(layers["bands"][str(i)], cube[..., i])
    w, h, layers = _decode_data_js(job / "view.js")
    now = exr.read_rgb(job / "render.exr")
    for k, c in enumerate("RGB"):
        np.testing.assert_allclose(layers["render"][c], now[..., k], rtol=1e-3, atol=1e-6)


def spectral_exr_cube(path):
    from spectral_bench.batch import spectral_exr
    return spectral_exr.read(path).stokes[0].astype(np.float32)


@pytest.mark.slow
def test_the_data_files_written_as_a_job_finishes_are_the_pages(run, tmp_path):
    """The runner writes a render's data files as its job finishes (batch/jobs/runner.py
    ``page_data``: html.data_files, only the files, issue 45 item 1); the page written at the end
    keeps them, and they hold the render's channels as the page reads them."""
    import shutil
    from spectral_bench.batch import exr, records
    from spectral_bench.batch.report import html
    out = tmp_path / "copy"
    shutil.copytree(run[0], out)
    job = out / Path(*run[1].relative_to(run[0]).parts)
    (job / "view.js").unlink()
    entry = records.read(out)["runs"][0]
    _, names, _ = html.data_files(out, entry)
    assert names and (job / "view.js").is_file()
    stamp = (job / "view.js").stat()
    html.write(out)
    again = (job / "view.js").stat()
    assert (again.st_ino, again.st_mtime_ns) == (stamp.st_ino, stamp.st_mtime_ns)  # kept, not written again
    w, h, layers = _decode_data_js(job / "view.js")
    img = exr.read_rgb(job / "render.exr")
    for k, c in enumerate("RGB"):
        np.testing.assert_allclose(layers["render"][c], img[..., k], rtol=1e-3, atol=1e-6)  # binary16
