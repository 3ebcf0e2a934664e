"""OUT/report.html: a static page, no server, that shows a run: the summary table (scene x
backend: status, metrics, probes, time), the speed/accuracy charts, and per scene an image viewer
(render / reference / difference / FLIP / z-score, with exposure and zoom) beside its numbers.
Relative links only, so the folder can be moved or zipped."""
import html
import json
from pathlib import Path

from ..verdict.status import ORDER

VIEWS = [("render", "render.png"), ("reference", "reference.png"), ("difference", "diff.png"),
         ("FLIP", "flip.png"), ("z-score", "zscore.png")]

STYLE = """
body{font-family:system-ui,sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:3px 6px}
.failed{background:#fdd}.known{background:#fec}.unjudged{background:#ffd}.ok,.fixed{background:#dfd}.skipped,.unsupported{background:#eee}
.viewer{display:flex;gap:1.5em;margin:1em 0 2em;flex-wrap:wrap}.frame{overflow:auto;max-width:70vw;max-height:70vh;border:1px solid #999}
.frame img{image-rendering:pixelated;transform-origin:0 0}.tabs button.active{font-weight:bold;background:#cde}
"""

SCRIPT = """
function show(id, view){
  var box=document.getElementById(id); if(!box) return;
  box.querySelectorAll('img.view').forEach(function(i){i.style.display = i.dataset.view==view ? '' : 'none';});
  box.querySelectorAll('.tabs button').forEach(function(b){b.classList.toggle('active', b.dataset.view==view);});
  box.dataset.active=view;
}
function expose(id, ev){var box=document.getElementById(id);
  box.querySelectorAll('img.view').forEach(function(i){i.style.filter='brightness('+Math.pow(2,ev)+')';});}
function zoom(id, z){var box=document.getElementById(id);
  box.querySelectorAll('img.view').forEach(function(i){i.style.transform='scale('+z+')';});}
window.addEventListener('load', function(){
  var imgs=[].slice.call(document.images), ok=imgs.filter(function(i){return i.complete && i.naturalWidth>0;});
  document.body.dataset.images=imgs.length; document.body.dataset.loaded=ok.length;
  var m=location.hash.match(/view=([^&]+)/);
  if(m){var p=decodeURIComponent(m[1]).split(':'); show(p[0], p[1]);}
});
"""


def _fmt(x, f="{:.4g}"):
    return "" if x is None else f.format(x)


def _summary(runs):
    rows = ["<table><tr><th>scene</th><th>backend</th><th>mode</th><th>status</th><th>spp</th><th>time (s)</th>"
            "<th>RMSE</th><th>relMSE</th><th>MAPE</th><th>FLIP</th><th>probes</th><th>reason</th></tr>"]
    for r in sorted(runs, key=lambda r: (ORDER.get(r["status"], 9), r["scene"], r["backend"])):
        m, pr = r.get("metrics") or {}, r.get("probes") or []
        probes = f"{sum(p['pass'] is True for p in pr)}/{len(pr)} pass" if pr else ""
        anchor = f"<a href='#{_id(r)}'>{html.escape(r['scene'])}</a>" if r.get("image") else html.escape(r["scene"])
        rows.append(f"<tr class='{r['status']}'><td>{anchor}</td><td>{r['backend']}</td><td>{r.get('mode') or ''}</td>"
                    f"<td>{r['status']}</td><td>{r.get('spp') or ''}</td><td>{_fmt(r.get('time_s'), '{:.2f}')}</td>"
                    f"<td>{_fmt(m.get('rmse'))}</td><td>{_fmt(m.get('relmse'))}</td><td>{_fmt(m.get('mape'))}</td>"
                    f"<td>{_fmt(m.get('flip'))}</td><td>{probes}</td><td>{html.escape(r.get('reason') or '')}</td></tr>")
    return "\n".join(rows + ["</table>"])


def _id(run):
    return f"{run['scene']}--{run['backend']}"


def _viewer(out, run):
    folder = Path(run["image"]).parent
    views = [(label, f"{folder.as_posix()}/{png}") for label, png in VIEWS if (out / folder / png).is_file()]
    if not views:
        return ""
    vid = _id(run)
    tabs = "".join(f"<button data-view='{l}' onclick=\"show('{vid}','{l}')\">{l}</button>" for l, _ in views)
    imgs = "".join(f"<img class='view' data-view='{l}' src='{html.escape(src)}' alt='{l}'>" for l, src in views)
    m = run.get("metrics") or {}
    numbers = [f"<li>{k}: {_fmt(v)}</li>" for k, v in m.items()]
    test = run.get("test")
    if test and test.get("p_min") is not None and test.get("pass") is not None:
        numbers.append(f"<li>noise test: p_min {test['p_min']:.3g} vs {test['threshold']:.3g} "
                       f"({'pass' if test['pass'] else 'FAIL'})</li>")
    elif test:
        numbers.append(f"<li>noise test: {html.escape(test.get('reason') or '')} "
                       f"({ {True: 'pass', False: 'FAIL', None: 'not judged'}[test.get('pass')]})</li>")
    for p in run.get("probes") or []:
        mark = {True: "pass", False: "FAIL", None: "not measured"}[p["pass"]]
        numbers.append(f"<li>{html.escape(p['name'])}: {_fmt(p['error'])} {html.escape(p['unit'] or '')} ({mark})</li>")
    return (f"<h3 id='{vid}'>{html.escape(run['scene'])} / {run['backend']} {run.get('mode') or ''}: {run['status']}</h3>"
            f"<div class='viewer' id='{vid}-box' data-active='{views[0][0]}'><div>"
            f"<div class='tabs'>{tabs}</div>"
            f"<label>exposure <input type='range' min='-4' max='4' step='0.5' value='0' "
            f"oninput=\"expose('{vid}-box', this.value)\"></label> "
            f"<label>zoom <input type='range' min='1' max='8' step='1' value='1' oninput=\"zoom('{vid}-box', this.value)\"></label>"
            f"<div class='frame'>{imgs}</div></div><ul>{''.join(numbers)}</ul></div>"
            f"<script>show('{vid}-box','{views[0][0]}')</script>")


def write(out_dir):
    out = Path(out_dir)
    data = json.loads((out / "metrics.json").read_text())
    runs, sweeps = data.get("runs", []), data.get("sweeps", [])
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>Spectral benchmark: {out.name}</title>"
             f"<style>{STYLE}</style><script>{SCRIPT}</script></head><body>",
             f"<h1>Spectral benchmark results</h1><p>{html.escape(out.name)}, started {data.get('started', '')}. "
             "A render passes when it agrees with its reference within the reference's noise and every "
             "analytic probe holds.</p>", "<h2>Summary</h2>", _summary(runs)]
    summary_text = (out / "summary.md").read_text() if (out / "summary.md").exists() else ""
    if "## RGB renderers against the spectral references" in summary_text:
        rgb = summary_text.split("## RGB renderers against the spectral references")[1].split("\n## ")[0]
        parts += ["<h2>RGB renderers against the spectral references</h2>", "<pre>" + html.escape(rgb.strip()) + "</pre>"]
    charts = sorted({l["chart"] for l in sweeps if l.get("chart")})
    if charts:
        parts.append("<h2>Speed against accuracy</h2>")
        parts += [f"<img class='chart' src='{c}' alt='{c}'>" for c in charts]
        summary_md = (out / "summary.md").read_text() if (out / "summary.md").exists() else ""
        if "## Speed against accuracy" in summary_md:
            parts.append("<pre>" + html.escape(summary_md.split("## Speed against accuracy (sweeps)")[1]) + "</pre>")
    stab = data.get("stability") or []
    if stab:
        parts.append("<h2>Stability</h2>")
        for name in sorted({r["sweep"] for r in stab}):
            parts.append(f"<h3>{html.escape(name)}</h3>")
            for backend in sorted({r.get("backend") for r in stab if r["sweep"] == name and r.get("backend")}):
                if (out / "stability" / backend / f"{name}.png").is_file():
                    parts.append(f"<p>{html.escape(backend)}</p><img class='strip' src='stability/{backend}/{name}.png' "
                                 f"alt='{name} {backend}' style='image-rendering:pixelated;width:90%'>")
            cells = "".join(f"<tr class='{r['status']}'><td>{r.get('value', '')}</td><td>{r.get('backend', '')}</td>"
                            f"<td>{r['status']}</td><td>{_fmt(r.get('mean'))}</td>"
                            f"<td>{html.escape('; '.join(r.get('problems') or []) or r.get('reason', ''))}</td></tr>"
                            for r in stab if r["sweep"] == name)
            parts.append("<table><tr><th>value</th><th>backend</th><th>status</th><th>mean</th><th>problems</th></tr>"
                         f"{cells}</table>")
    parts.append("<h2>Images</h2>")
    parts += [_viewer(out, r) for r in runs if r.get("image")]
    parts.append("</body></html>")
    path = out / "report.html"
    path.write_text("\n".join(parts))
    return path
