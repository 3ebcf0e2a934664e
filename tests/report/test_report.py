"""The static HTML report, opened in headless Chromium (no server): images and charts load,
and switching views works."""
import re

import pytest

from conftest import metrics, run_batch
from installed import dump_dom, needs_chromium

pytestmark = [pytest.mark.slow,  # over ~1 s of CPU: a batch run and Chromium (benchmarks/TESTS.md)
              needs_chromium]


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "out"
    run_batch("-r", "mitsuba", "-s", "polarizing_plane_0", "-s", "ggx_copper_80", "--scale", 0.125,
              "--sweep", "--ladder", "4,16", "-o", out)
    return out


@pytest.mark.slow
def test_report_images_and_charts_load(report):
    """The charts load and every viewer decodes its float data (view.js and the scene's
    reference_WxH.js: script files, so file:// works)."""
    page = (report / "report.html").read_text()
    force = ("<script>window.addEventListener('load', function(){document.querySelectorAll('.viewer').forEach("
             "function(b){spectralBench.viewer(b.id).start();});});</script>")
    copy = report / "all.html"
    copy.write_text(page.replace("</body>", force + "</body>"))
    dom = dump_dom(copy.as_uri())
    images = int(re.search(r'data-images="(\d+)"', dom).group(1))
    loaded = int(re.search(r'data-loaded="(\d+)"', dom).group(1))
    runs = metrics(report)["runs"]
    assert images == loaded == 2 and dom.count("class=\"chart\"") == 2
    boxes = re.findall(r'<div class="viewer" id="([^"]+)"[^>]*>', dom)
    assert len(boxes) == len(runs) == 2
    assert all('data-ready="1"' in b for b in re.findall(r'<div class="viewer"[^>]*>', dom)), dom[:3000]
    for run in runs:
        assert run["scene"] in dom


@pytest.mark.slow
def test_switching_views(report):
    dom = dump_dom((report / "report.html").as_uri() + "#view=ggx_copper_80--mitsuba-box:difference")
    box = re.search(r'<div class="viewer" id="ggx_copper_80--mitsuba-box" data-active="([^"]+)"', dom)
    assert box and box.group(1) == "difference"
    tabs = re.findall(r'<button data-view="([^"]+)"[^>]*class="active"', dom[dom.index('id="ggx_copper_80--mitsuba-box"'):])
    assert tabs[:1] == ["difference"], tabs


def test_clicking_a_tab_and_the_sliders(report, tmp_path):
    """The page's own buttons and sliders act on their viewer (a copy of the page clicks the
    difference tab of the second viewer and moves its exposure slider once loaded)."""
    page = (report / "report.html").read_text()
    click = ("<script>window.addEventListener('load', function(){var box=document.querySelectorAll('.viewer')[1];"
             "box.querySelector(\".tabs button[data-view='difference']\").click();"
             "var s=box.querySelector('input[type=range]'); s.value='2'; s.dispatchEvent(new Event('input'));"
             "document.body.dataset.ev=spectralBench.viewer(box.id).ev;});</script>")
    copy = report / "clicked.html"
    copy.write_text(page.replace("</body>", click + "</body>"))
    dom = dump_dom(copy.as_uri())
    boxes = re.findall(r'<div class="viewer" id="([^"]+)" data-active="([^"]+)"', dom)
    assert [a for _, a in boxes] == ["render", "difference"], boxes
    assert 'data-ev="2"' in dom
    second = dom[dom.index(f'id="{boxes[1][0]}"'):]
    assert re.search(r'<span class="ev">2</span>', second)
