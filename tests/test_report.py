"""The static HTML report, opened in headless Chromium (no server): images and charts load,
and switching views works."""
import re
import shutil
import subprocess

import pytest

from conftest import metrics, run_batch

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(not CHROMIUM, reason="no chromium: report not checked in a browser "
                                                      "(scripts/setup.sh installs it as root)")


def dump_dom(url):
    proc = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000",
                           "--dump-dom", url], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-1000:]
    return proc.stdout


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "out"
    run_batch("-r", "mitsuba", "-s", "polarizing_plane_0", "-s", "ggx_copper_80", "--scale", 0.125,
              "--sweep", "--ladder", "4,16", "-o", out)
    return out


@pytest.mark.slow
def test_report_images_and_charts_load(report):
    dom = dump_dom((report / "report.html").as_uri())
    images = int(re.search(r'data-images="(\d+)"', dom).group(1))
    loaded = int(re.search(r'data-loaded="(\d+)"', dom).group(1))
    runs = metrics(report)["runs"]
    assert images == loaded and images >= 2 * 5 + 2  # five views per scene plus two charts
    assert dom.count("class=\"chart\"") == 2
    for run in runs:
        assert run["scene"] in dom


@pytest.mark.slow
def test_switching_views(report):
    dom = dump_dom((report / "report.html").as_uri() + "#view=ggx_copper_80--mitsuba-box:difference")
    box = re.search(r'<div class="viewer" id="ggx_copper_80--mitsuba-box" data-active="([^"]+)"', dom)
    assert box and box.group(1) == "difference"
    tags = re.findall(r'<img class="view"[^>]*src="ggx_copper_80[^>]*>', dom)
    shown = [(re.search(r'data-view="([^"]+)"', t).group(1), "display: none" in t) for t in tags]
    visible = [v for v, hidden in shown if not hidden]
    assert visible == ["difference"], shown


def test_clicking_a_tab_and_the_sliders(report, tmp_path):
    """The page's own buttons and sliders act on their viewer (a copy of the page clicks the
    difference tab of the second viewer and moves its exposure slider once loaded)."""
    page = (report / "report.html").read_text()
    click = ("<script>window.addEventListener('load', function(){var box=document.querySelectorAll('.viewer')[1];"
             "box.querySelector(\".tabs button[data-view='difference']\").click();"
             "var s=box.querySelector('input[type=range]'); s.value='2'; s.dispatchEvent(new Event('input'));});</script>")
    copy = report / "clicked.html"
    copy.write_text(page.replace("</body>", click + "</body>"))
    dom = dump_dom(copy.as_uri())
    boxes = re.findall(r'<div class="viewer" id="([^"]+)" data-active="([^"]+)"', dom)
    assert [a for _, a in boxes] == ["render", "difference"], boxes
    second = dom[dom.index(f'id="{boxes[1][0]}"'):]
    tags = re.findall(r'<img class="view"[^>]*>', second)[:5]
    visible = [re.search(r'data-view="([^"]+)"', t).group(1) for t in tags if "display: none" not in t]
    assert visible == ["difference"] and all("brightness(4)" in t for t in tags), tags
