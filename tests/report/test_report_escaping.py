"""report.html shows every value of metrics.json as text: markup in any field, even in the output
folder's name and in the folders images live in, neither creates an element nor runs a script.

A tiny real run gives a real metrics.json; every string in it (every leaf, wherever it is, plus an
unknown key added to every object) is replaced by a payload that carries its own number, so the
fields checked are the fields the runner writes, not a hand-kept list. The page is made by the real
code (summary.write, html.write) and loaded in headless Chromium: the title must be unchanged (each
payload's script sets it), no element may carry a payload's id, every src/href must be a relative
path to a file inside OUT (or an anchor of the page), and a payload that shows at all shows whole,
as text. Checked to fail on the f-string report this replaced (backend, mode, status, started and
stability values went out unescaped)."""
import copy
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import pytest

from conftest import run_batch, write_hand_made_metrics

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(not CHROMIUM, reason="no chromium: report not checked in a browser "
                                                      "(scripts/setup.sh installs it as root)")

# one payload per string: an element with an id, scripts that set the title (an inline one, one
# after closing a <script>, event handlers on elements and on a broken-out attribute), a javascript:
# URL, a comment opener and an entity that must stay literal text. [P<n>] tells which field it came from.
PAYLOAD = ("javascript:document.title='XSS{n}'//[P{n}]\"'><img src=x id=xss-{n} onerror=\"document.title='XSS{n}'\">"
           "</script><script id=xss-{n}s>document.title='XSS{n}'</script><svg id=xss-{n}v onload=document.title='XSS{n}'>"
           "' autofocus onfocus='document.title=\"XSS{n}\"' x='<!--</pre></textarea>&amp;<b>bold</b> end[P{n}]")
# a folder name (no slash): the output folder itself and the folders that hold images
DIR_PAYLOAD = "d{n} \"'><img src=x id=xss-{n} onerror=document.title='XSS{n}'>#?%&amp;[P{n}]"
MARK = re.compile(r"\[P(\d+)\]")


def dump_dom(path):
    proc = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=5000",
                           "--dump-dom", Path(path).as_uri()], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-1000:]
    return proc.stdout


class Page(HTMLParser):
    """Elements (tag, attrs), the title, and the visible text outside <pre> of a page."""

    def __init__(self, source):
        super().__init__(convert_charrefs=True)
        self.elements, self.title, self.text, self.scripts, self._in = [], "", [], [], []
        self.feed(source)

    def handle_starttag(self, tag, attrs):
        self.elements.append((tag, dict(attrs)))
        if tag in ("script", "style", "title", "pre"):
            self._in.append(tag)
            if tag == "script":
                self.scripts.append("")

    def handle_endtag(self, tag):
        if self._in and self._in[-1] == tag:
            self._in.pop()

    def handle_data(self, data):
        where = self._in[-1] if self._in else None
        if where == "title":
            self.title += data
        elif where == "script":
            self.scripts[-1] += data
        elif where is None:
            self.text.append(data)


def injected(page):
    """Elements or attributes that only a payload brings."""
    return [(t, a) for t, a in page.elements if (a.get("id") or "").startswith("xss")
            or {"onerror", "onload", "onfocus", "autofocus", "x"} & set(a)]


def hostile(data, out=None):
    """``data`` with every string replaced by a numbered payload and an unknown key added to every
    object; returns (the new data, {n: path of the leaf}). With ``out``, a string that names a file
    in ``out`` (an image, a chart) keeps naming it, through a copy of its top folder under a hostile
    name (the quoting and percent-encoding of src)."""
    paths = {}

    def new(path, template=PAYLOAD):
        n = len(paths)
        paths[n] = path
        return template.format(n=n)

    def walk(x, path):
        if isinstance(x, dict):
            obj = {k: walk(v, path + (k,)) for k, v in x.items()}
            obj[new(path + ("<key>",))] = new(path + ("<extra>",))
            return obj
        if isinstance(x, list):
            return [walk(v, path + (i,)) for i, v in enumerate(x)]
        if not isinstance(x, str):
            return x
        if out is not None and "/" in x and not x.startswith("/") and ".." not in x and (out / x).is_file():
            top, rest = x.split("/", 1)
            name = new(path, DIR_PAYLOAD)
            shutil.copytree(out / top, out / name)
            return f"{name}/{rest}"
        return new(path)

    return walk(data, ()), paths


def must_show(path, viewers):
    """Fields the page is meant to show as text (whether it does is checked, not just its escaping)."""
    if path == ("started",):
        return True
    if path[:1] == ("runs",) and len(path) == 3 and path[2] in ("scene", "backend", "mode", "status", "reason"):
        return True
    if path[:1] == ("runs",) and len(path) == 5 and path[2] == "reference_problems" and path[4] in ("file", "problem"):
        return True
    if path[:1] == ("stability",) and len(path) >= 3 and path[2] in ("sweep", "status", "problems", "backend"):
        return True
    if viewers and path[:1] == ("runs",) and len(path) == 5 and path[2] == "probes" and path[4] in ("name", "unit"):
        return True
    if viewers and path[:1] == ("runs",) and len(path) == 4 and path[2:] in (("test", "reason"), ("metrics", "<key>")):
        return True
    return False


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A real run: one scene, its sweep and the stability strips (about 35 s)."""
    out = tmp_path_factory.mktemp("escaping") / "run"
    proc = run_batch("-r", "mitsuba", "-s", "polarizing_plane_0", "--scale", 0.0625, "--sweep", "--ladder", 4,
                     "--stability", "-o", out)
    assert (out / "metrics.json").is_file(), proc.stdout[-2000:] + proc.stderr[-2000:]
    return out


def make_hostile_report(run, tmp_path, keep_images):
    from spectral_bench.batch.report import html, summary
    out = tmp_path / DIR_PAYLOAD.format(n="out")
    shutil.copytree(run, out)
    (out / "report.html").unlink()
    data = json.loads((out / "metrics.json").read_text())
    assert data["runs"] and data["sweeps"] and data["stability"] and any(r.get("probes") for r in data["runs"])
    for r in data["runs"]:  # the field the reference checks add (issue 18), whether this run had one or not
        r.setdefault("reference_problems", [{"file": "references/x.exr", "problem": "truncated"}])
    unjudged = copy.deepcopy(data["runs"][0])  # the other branch of the noise test's line: its reason
    unjudged["test"] = {"pass": None, "reason": "no reference"}
    data["runs"].append(unjudged)
    data, paths = hostile(data, out if keep_images else None)
    write_hand_made_metrics(out, data)
    summary.write(out, data["runs"], 1.0, data["sweeps"], data["stability"])
    with open(out / "summary.md", "a") as f:  # summary.md is read back by the page: a section of it, hostile
        f.write("\n## RGB renderers against the spectral references\n\n" + PAYLOAD.format(n=len(paths)) + "\n")
    paths[len(paths)] = ("summary.md",)
    return html.write(out), paths


@pytest.mark.slow
@pytest.mark.parametrize("keep_images", [False, True], ids=["every-string", "images-in-hostile-folders"])
def test_every_value_is_text(run, tmp_path, keep_images):
    report, paths = make_hostile_report(run, tmp_path, keep_images)
    out = report.parent
    source = report.read_text()

    # the source: no payload, nor any of its tags, survives unescaped
    for n in paths:
        assert PAYLOAD.format(n=n) not in source and DIR_PAYLOAD.format(n=n) not in source
        assert f"<img src=x id=xss-{n}" not in source and f"<b>bold</b> end[P{n}]" not in source
    assert not injected(Page(source))
    assert len(re.findall(r"</script", source, re.I)) == len(re.findall(r"<script", source, re.I))

    # the page as Chromium built it (scripts run, images loaded or failed)
    dom = dump_dom(report)
    page = Page(dom)
    assert page.title == f"Spectral benchmark: {out.name}", "a payload's script ran"
    assert not injected(page)
    assert all("XSS" not in s for s in page.scripts)
    ids = {a["id"] for _, a in page.elements if a.get("id")}
    for tag, attrs in page.elements:
        for attr in ("src", "href"):
            url = attrs.get(attr)
            if url is None:
                continue
            if url.startswith("#"):
                assert url[1:] in ids, (tag, url)
                continue
            assert not re.match(r"[a-z][a-z0-9+.-]*:", url, re.I) and not url.startswith("/"), (tag, url)
            target = (out / unquote(url)).resolve()
            assert target.is_file() and target.is_relative_to(out.resolve()), (tag, url)
        for attr, value in attrs.items():
            if attr.startswith("on"):
                assert "XSS" not in value and "[P" not in value, (tag, attr, value)

    # every payload that shows, shows whole, as text; the fields meant to be shown are
    text = "".join(page.text)
    shown = {int(m) for m in MARK.findall(text)}
    viewers = keep_images
    for n in shown:
        assert PAYLOAD.format(n=n) in text or DIR_PAYLOAD.format(n=n) in text, (paths[n], "shown in part: markup was interpreted")
    missing = [paths[n] for n in paths if must_show(paths[n], viewers) and n not in shown]
    assert not missing, missing
    if keep_images:  # the hostile folders' images and float data load (their src is quoted and percent-encoded)
        images = int(re.search(r'data-images="(\d+)"', dom).group(1))
        loaded = int(re.search(r'data-loaded="(\d+)"', dom).group(1))
        assert images >= 1 and loaded == images
        viewers = [a for t, a in page.elements if t == "div" and "viewer" in (a.get("class") or "")]
        assert len(viewers) == 2 and all(a.get("data-ready") in (None, "1") for a in viewers), viewers  # loaded when near the window
        for a in viewers:
            for attr in ("data-src", "data-ref"):
                if a.get(attr):
                    target = (out / unquote(a[attr])).resolve()
                    assert target.is_file() and target.is_relative_to(out.resolve()), (attr, a[attr])


def test_ids_urls_and_reference_problems(tmp_path):
    """Without a run: an image path outside OUT (absolute, ../) is not linked; an unsafe scene name
    gives a safe id; reference problems are shown, with the file, escaped."""
    from spectral_bench.batch import exr
    from spectral_bench.batch.report import html
    out = tmp_path / "out"
    outside = tmp_path / "outside"
    for folder in (out / "s" / "results" / "mitsuba", outside / "results" / "mitsuba"):
        exr.write(folder / "render.exr", np.ones((4, 4, 3), dtype=np.float32))
    runs = [{"scene": "s", "backend": "mitsuba", "status": "ok", "image": "s/results/mitsuba/render.exr",
             "reference_problems": [{"file": "references/<b>s</b>.exr", "problem": "truncated: 12 of 4096 bytes"}]},
            {"scene": "a'b", "backend": "mitsuba", "status": "failed", "image": "s/results/mitsuba/render.exr",
             "reason": "judged by probes alone: <i>no</i> usable reference"},
            {"scene": "up", "backend": "mitsuba", "status": "ok", "image": "../outside/results/mitsuba/render.exr"},
            {"scene": "abs", "backend": "mitsuba", "status": "ok", "image": str(outside / "results/mitsuba/render.exr")},
            {"scene": "js", "backend": "mitsuba", "status": "ok", "image": "javascript:alert(1)//x/render.exr"}]
    (out / "metrics.json").write_text(json.dumps({"started": "now", "runs": runs,
                                                  "sweeps": [{"chart": "../outside/results/mitsuba/render.png"}]}))
    source = html.write(out).read_text()
    srcs = re.findall(r"src='([^']*)'", source)
    assert srcs and all(s.startswith("s/results/mitsuba/") for s in srcs), srcs
    assert "id='s--mitsuba'" in source and "id='run-1'" in source and "href='#run-1'" in source
    assert "a&#39;b" in source and "<b>s</b>" not in source and "<i>no</i>" not in source
    assert "reference problem: references/&lt;b&gt;s&lt;/b&gt;.exr: truncated: 12 of 4096 bytes" in source
    assert "judged by probes alone: &lt;i&gt;no&lt;/i&gt; usable reference" in source


@pytest.mark.slow
def test_a_value_of_the_wrong_type_does_not_stop_the_report(run, tmp_path):
    """Any one value of the first run, sweep and stability row (or of the top level) replaced by
    another type: the page is still written (what it cannot read is shown as text or left out)."""
    from spectral_bench.batch.report import html
    out = tmp_path / "out"
    shutil.copytree(run, out)
    data = json.loads((out / "metrics.json").read_text())
    data.pop("jobs", None)  # not read by the page
    leaves = []

    def walk(x, path):
        if path and (path[0] not in ("runs", "sweeps", "stability") or len(path) == 1 or path[1] == 0):
            leaves.append(path)
        for k, v in (x.items() if isinstance(x, dict) else enumerate(x) if isinstance(x, list) else ()):
            walk(v, path + (k,))

    walk(data, ())
    assert len(leaves) > 100
    failures = []
    for path in leaves:
        holder = data
        for k in path[:-1]:
            holder = holder[k]
        kept = holder[path[-1]]
        for value in (None, -1.5, True, "text", [], {"a": 1}):
            holder[path[-1]] = value
            write_hand_made_metrics(out, data)
            try:
                html.write(out)
            except Exception as e:  # noqa: BLE001 - collected, all reported at once
                failures.append((path, value, repr(e)))
        holder[path[-1]] = kept
    assert not failures, failures[:10]


def test_summary_md_cells_cannot_break_their_table_or_become_markup(tmp_path):
    """summary.md (also printed on the terminal): every value is one cell of its row, shown as
    text: a '|' or a newline cannot add cells or rows, '<' and backticks and links are escaped."""
    from spectral_bench.batch.report import summary
    payload = "a|b\nc <img src=x onerror=alert(1)> `code` [x](javascript:alert(1))"
    runs = [{"scene": payload, "case": payload, "backend": payload, "mode": payload, "status": "failed",
             "reason": payload, "reference_problems": [{"file": payload, "problem": payload}]}]
    sweeps = [{"scene": payload, "backend": payload, "mode": payload, "points": [], "reason": payload}]
    stability = [{"sweep": payload, "value": payload, "backend": payload, "mode": payload, "status": payload,
                  "problems": [payload]}]
    text = summary.write(tmp_path, runs, 1.0, sweeps, stability)
    lines = text.splitlines()
    tables, shown = 0, 0
    for i, line in enumerate(lines):
        if not line.startswith("|---"):
            continue
        tables += 1
        cells = line.count("|")
        for row in lines[i - 1:i] + [r for r in _until_blank(lines[i + 1:])]:
            assert len(re.findall(r"(?<!\\)\|", row)) == cells, row  # no cell added or split
            unescaped = re.sub(r"\\.", "", row)
            assert "<" not in unescaped and "`" not in unescaped and "](" not in row, row
            shown += payload.split("|")[0] in row
    assert tables >= 4 and shown >= 4, text  # runs, reference problems, sweeps, stability


def _until_blank(lines):
    for line in lines:
        if not line.startswith("|"):
            return
        yield line
