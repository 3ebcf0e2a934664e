"""OUT/report.html: a static page, no server, that shows a run: the summary table (scene x
backend: status, metrics, probes, time), the speed/accuracy charts, and per scene an image viewer
(render / reference / difference / FLIP / z-score, with exposure and zoom) beside its numbers.
Relative links only, so the folder can be moved or zipped.

Every value of metrics.json is text to this page, never markup: the page is rendered by Jinja2
from templates/report.html with autoescaping on, values inside <script> go through |tojson,
element ids are made here from a safe alphabet, and an image's src is only ever a relative,
percent-encoded path to a file that exists inside the output folder (anything else in an
image or chart field is not linked)."""
import re
from pathlib import Path, PurePosixPath, PureWindowsPath
from urllib.parse import quote

import jinja2

from .. import records
from ..records import noise_test_text
from ..verdict.status import ORDER

VIEWS = [("render", "render.png"), ("reference", "reference.png"), ("difference", "diff.png"),
         ("FLIP", "flip.png"), ("z-score", "zscore.png")]
TEMPLATES = Path(__file__).resolve().parent / "templates"
SAFE_ID = re.compile(r"[A-Za-z0-9_.-]{1,120}")  # ids, #anchors, and the view=ID:VIEW hash of the page

_env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), autoescape=True,
                          undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)


def _text(x):
    """A value as plain text (the template escapes it)."""
    if x is None:
        return ""
    if isinstance(x, (list, tuple)):
        return "; ".join(_text(v) for v in x)
    return str(x)


def _fmt(x, f="{:.4g}"):
    if x is None:
        return ""
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return f.format(x)
    return _text(x)  # not a number where one was expected: shown as it is, as text


def _dict(x):
    return x if isinstance(x, dict) else {}


def _list(x):
    return x if isinstance(x, list) else []


def _verdict(passed, otherwise):
    return "pass" if passed is True else "FAIL" if passed is False else otherwise


def _css(status):
    return status if isinstance(status, str) and status in ORDER else ""


def _local_url(out, rel):
    """``rel`` as a relative, percent-encoded URL if it names a file inside ``out``; else None."""
    text = str(rel) if isinstance(rel, (str, PurePosixPath, PureWindowsPath)) else ""
    if not text or "\0" in text or PurePosixPath(text).is_absolute() or PureWindowsPath(text).anchor:
        return None
    parts = PureWindowsPath(text).parts if "\\" in text else PurePosixPath(text).parts
    if not parts or any(p in ("", ".", "..") for p in parts):
        return None
    try:
        path = (out / Path(*parts)).resolve()
        if not path.is_file() or not path.is_relative_to(out.resolve()):
            return None
    except (OSError, ValueError):
        return None
    return "/".join(quote(p, safe="") for p in parts)


def _reference_problems(run):
    out = []
    for p in _list(run.get("reference_problems")):
        if isinstance(p, dict):
            out.append(f"reference problem: {_text(p.get('file'))}: {_text(p.get('problem'))}")
        else:
            out.append(f"reference problem: {_text(p)}")
    return out


def _summary_rows(runs, anchors):
    rows = []
    order = sorted(range(len(runs)), key=lambda i: (ORDER.get(_css(runs[i].get("status")), 9),
                                                    _text(runs[i].get("scene")), _text(runs[i].get("backend"))))
    for i in order:
        r = runs[i]
        m, pr = _dict(r.get("metrics")), _list(r.get("probes"))
        probes = f"{sum(isinstance(p, dict) and p.get('pass') is True for p in pr)}/{len(pr)} pass" if pr else ""
        rows.append({"css": _css(r.get("status")), "anchor": anchors.get(i), "scene": _text(r.get("scene")),
                     "backend": _text(r.get("backend")), "mode": _text(r.get("mode")), "status": _text(r.get("status")),
                     "spp": _text(r.get("spp") or ""), "time": _fmt(r.get("time_s"), "{:.2f}"),
                     "rmse": _fmt(m.get("rmse")), "relmse": _fmt(m.get("relmse")), "mape": _fmt(m.get("mape")),
                     "flip": _fmt(m.get("flip")), "probes": probes, "reason": _text(r.get("reason")),
                     "reference_problems": _reference_problems(r)})
    return rows


def _viewer(out, run):
    image = run.get("image")
    if not isinstance(image, str) or not image:
        return None
    folder = PureWindowsPath(image).parent if "\\" in image else PurePosixPath(image).parent
    views = [{"label": label, "src": src} for label, png in VIEWS if (src := _local_url(out, folder / png))]
    if not views:
        return None
    numbers = [f"{_text(k)}: {_fmt(v)}" for k, v in _dict(run.get("metrics")).items()]
    if isinstance(run.get("test"), dict):
        numbers.append(f"noise test: {noise_test_text(run['test'])}")
    for p in _list(run.get("probes")):
        if not isinstance(p, dict):
            numbers.append(_text(p))
            continue
        mark = _verdict(p.get("pass"), "not measured")
        numbers.append(f"{_text(p.get('name'))}: {_fmt(p.get('error'))} {_text(p.get('unit'))} ({mark})")
    return {"scene": _text(run.get("scene")), "backend": _text(run.get("backend")), "mode": _text(run.get("mode")),
            "status": _text(run.get("status")), "views": views, "numbers": numbers,
            "reference_problems": _reference_problems(run)}


def _section(text, heading):
    """The body of one ``## heading`` section of summary.md (up to the next section), or None."""
    if f"## {heading}" not in text:
        return None
    return text.split(f"## {heading}", 1)[1].split("\n## ")[0].strip()


def _stability(out, stab):
    stab = [r for r in stab if isinstance(r, dict)]
    sections = []
    for name in sorted({_text(r.get("sweep")) for r in stab}):
        rows = [r for r in stab if _text(r.get("sweep")) == name]
        strips = []
        for backend in sorted({_text(r.get("backend")) for r in rows if r.get("backend")}):
            one_name_each = not re.search(r"[/\\]", backend + name)
            src = _local_url(out, PurePosixPath("stability", backend, f"{name}.png")) if one_name_each else None
            if src:
                strips.append({"backend": backend, "src": src, "alt": f"{name} {backend}"})
        cells = [{"css": _css(r.get("status")), "value": _text(r.get("value", "")), "backend": _text(r.get("backend", "")),
                  "status": _text(r.get("status")), "mean": _fmt(r.get("mean")),
                  "problems": _text(r.get("problems")) or _text(r.get("reason", ""))} for r in rows]
        sections.append({"name": name, "strips": strips, "rows": cells})
    return sections


def _ids(runs, viewers):
    """A unique, safe element id per viewer: SCENE--BACKEND when that is safe, else run-N."""
    ids, taken = {}, set()
    for i in viewers:
        base = f"{_text(runs[i].get('scene'))}--{_text(runs[i].get('backend'))}"
        vid = base if SAFE_ID.fullmatch(base) else f"run-{i}"
        n = 2
        while vid in taken or f"{vid}-box" in taken:
            vid, n = f"{base if SAFE_ID.fullmatch(base) else f'run-{i}'}-{n}", n + 1
        taken |= {vid, f"{vid}-box"}
        ids[i] = vid
    return ids


def load(out):
    """The run's metrics.json through batch/records.py (upgraded to the current version; paths
    stay relative to the run folder, as the page links them). Lenient: a file whose version this
    code does not know is shown as far as it can be."""
    return records.read(out, strict=False)


def render(out_dir):
    """The page of an output folder, as a string."""
    out = Path(out_dir)
    data = load(out)
    runs = [r for r in _list(data.get("runs")) if isinstance(r, dict)]
    sweeps = [s for s in _list(data.get("sweeps")) if isinstance(s, dict)]
    viewers = {}
    for i, r in enumerate(runs):
        v = _viewer(out, r)
        if v:
            viewers[i] = v
    ids = _ids(runs, viewers)
    for i, v in viewers.items():
        v["id"] = ids[i]
    summary_md = out / "summary.md"
    summary_text = summary_md.read_text(encoding="utf-8", errors="replace") if summary_md.is_file() else ""
    charts = []
    for c in sorted({_text(s.get("chart")) for s in sweeps if s.get("chart")}):
        src = _local_url(out, c)
        if src:
            charts.append({"src": src, "alt": c})
    stab = _list(data.get("stability"))
    return _env.get_template("report.html").render(
        name=out.name, started=_text(data.get("started", "")), rows=_summary_rows(runs, ids),
        rgb=_section(summary_text, "RGB renderers against the spectral references"), charts=charts,
        sweep_text=_section(summary_text, "Speed against accuracy (sweeps)"),
        stability=_stability(out, stab), viewers=list(viewers.values()))


def write(out_dir):
    path = Path(out_dir) / "report.html"
    path.write_text(render(out_dir), encoding="utf-8")
    return path
