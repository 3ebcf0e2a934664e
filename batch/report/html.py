"""OUT/report.html: a static page, no server, that shows a run: the summary table (scene x
backend: status, metrics, probes, time; failures first), the speed/accuracy charts, and per job
a float image viewer (render / reference / per-channel difference / z / FLIP, Stokes S0..S3,
degree and angle of polarisation; exposure, sRGB or false colour, pixel values under the cursor,
zoom at the cursor, pan, A/B flip and side by side: templates/viewer.js) beside its checks, each
on one line with its statistic, threshold and outcome. Relative links only, so the folder can be
moved or zipped.

The viewer's floats travel as script files beside the images (``view.js`` in a render's folder,
``reference_WxH.js`` beside the scene's shared reference), written here from the EXRs when the
page is made (always: one is kept only where this process wrote it from the EXRs as they still are,
``_fresh``; a data file is a script the page runs, and a run folder is anyone's): half floats (11 significant bits; the standard
error rounded to 5), deflated, as bytes in a string the page loads with charset x-user-defined
(``_js_bytes``), so that the page works from file:// where fetch() does not.

Every value of metrics.json is text to this page, never markup: the page is rendered by Jinja2
from templates/report.html with autoescaping on, values inside <script> and data attributes go
through |tojson or the attribute escaping, element ids are made here from a safe alphabet, and a
src is only ever a relative, percent-encoded path to a file that exists inside the output folder
(anything else in an image or chart field is not linked)."""
import json
import os
import re
import shlex
import tempfile
import zlib
from pathlib import Path

import jinja2
import numpy as np

from .. import exr, previews, records, run_folder
from ..verdict.status import ORDER
from . import grouping, results, spectra

STOKES_VIEWS = ["S0", "S1", "S2", "S3", "DoP", "AoP"]
DATA_JS = "view.js"
SPECTRAL_JS = "spectral_preview.js"  # beside spectral_preview.exr: its bands, for the band slider
PLOTS_JS = "spectral_plots.js"  # beside a spectral job's render: its regions' plots (SVG), loaded when opened
_UMASK = os.umask(0o022)
os.umask(_UMASK)
TEMPLATES = Path(__file__).resolve().parent / "templates"
SAFE_ID = re.compile(r"[A-Za-z0-9_.-]{1,120}")  # ids, #anchors, and the view=ID:VIEW hash of the page

# the viewer's script, put inline into the page (a file of this package, not a value of the run)
VIEWER_JS = (TEMPLATES / "viewer.js").read_text(encoding="utf-8")
assert "<script" not in VIEWER_JS.lower() and "</script" not in VIEWER_JS.lower()
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


def _reference_problems(run):
    out = []
    for p in _list(run.get("reference_problems")):
        if isinstance(p, dict):
            out.append(f"reference problem: {_text(p.get('file'))}: {_text(p.get('problem'))}")
        else:
            out.append(f"reference problem: {_text(p)}")
    return out


def _conversions(run):
    """The scene's conversion warnings (metrics.json ``scene_warnings``) as lines."""
    return [f"conversion: {_text(w.get('object'))}.{_text(w.get('field'))}: {_text(w.get('message'))}"
            for w in _list(run.get("scene_warnings")) if isinstance(w, dict)]


def _summary_rows(runs, anchors, listed=None):
    rows = []
    order = sorted((i for i in range(len(runs)) if listed is None or id(runs[i]) in listed), key=lambda i: (ORDER.get(_css(runs[i].get("status")), 9),
                                                    _text(runs[i].get("scene")), _text(runs[i].get("backend"))))
    for i in order:
        r = runs[i]
        m, pr = _dict(r.get("metrics")), _list(r.get("probes"))
        probes = f"{sum(isinstance(p, dict) and p.get('pass') is True for p in pr)}/{len(pr)} pass" if pr else ""
        rows.append({"css": _css(r.get("status")), "anchor": anchors.get(i), "scene": _text(r.get("scene")),
                     "backend": _text(r.get("backend")), "mode": _text(results.mode_text(r)), "status": _text(r.get("status")),
                     "spp": _text(r.get("spp") or ""), "time": _fmt(r.get("time_s"), "{:.2f}"),
                     "rmse": _fmt(m.get("rmse")), "relmse": _fmt(m.get("relmse")), "mape": _fmt(m.get("mape")),
                     "flip": _text(records.flip_text(r)), "probes": probes or ("none" if r.get("status") in results.JUDGED else ""),
                     "reason": _text(r.get("reason")), "self_check": results.checked_against_itself(r),
                     "crosschecked": _text(results.crosscheck_note(r)), "reference_problems": _reference_problems(r)})
    return rows


def _pack(planes, keep_bits=10):
    """HxW arrays as the viewer reads them (templates/viewer.js): binary16, plane after plane, the
    low bytes then the high bytes (a third smaller once deflated), zlib; bytes. ``keep_bits`` < 10
    rounds the mantissa to that many bits (non-negative values only: the standard error)."""
    h = np.stack([np.asarray(p, dtype=np.float32) for p in planes]).astype(np.float16).view(np.uint16).ravel()
    if keep_bits < 10:
        drop = 10 - keep_bits
        h = ((h.astype(np.uint32) + (1 << (drop - 1))) >> drop << drop).astype(np.uint16)
    split = np.concatenate([(h & 0xFF).astype(np.uint8), (h >> 8).astype(np.uint8)])
    return zlib.compress(split.tobytes(), ZLIB_LEVEL)


# zlib's level for the page's data. 1 (issue 45 item 1): the default suite's data files took 4.7 s
# of CPU at level 4 (most of the runner's record phase), against 0.8 s of CPU, not 8.1 s, at level
# 9 before that; level 1 deflates its renders' layers in 56 % of level 4's CPU, 3.5 % larger
# (benchmarks/ENGINES.md, 2026-12-04, "judging's share"). The page inflates any level alike.
ZLIB_LEVEL = 1


def _js_bytes(data):
    """``data`` as the inside of a JavaScript string literal in a file the page loads with
    charset x-user-defined (WHATWG Encoding Standard, "x-user-defined": byte b < 0x80 is U+00b,
    byte b >= 0x80 is U+F780 + b - 0x80, a bijection): the bytes as they are but for the four a
    string literal cannot hold (backslash, quote, LF, CR), escaped. 1.6 % larger than the bytes
    where base64 is 33 %."""
    return data.replace(b"\\", b"\\\\").replace(b'"', b'\\"').replace(b"\n", b"\\n").replace(b"\r", b"\\r")


def _write_data(path, w, h, layers):
    """One data file: spectralBench.data(document.currentScript, {...}): ASCII JSON but for each
    layer's ``data``, a string of deflated bytes (``_js_bytes``; templates/viewer.js loads the
    file with charset x-user-defined and turns each character back into its byte)."""
    parts = [b'spectralBench.data(document.currentScript, {"w": %d, "h": %d, "layers": {' % (int(w), int(h))]
    for i, (k, (names, planes, bits)) in enumerate(layers.items()):
        parts.append((", " if i else "").encode() + json.dumps(str(k)).encode("ascii") + b': {"channels": '
                     + json.dumps([str(n) for n in names]).encode("ascii") + b', "data": "'
                     + _js_bytes(_pack(planes, bits)) + b'"}')
    parts.append(b"}});\n")
    _write_atomically(path, b"".join(parts))


def _write_atomically(path, data):
    """``data`` (bytes) as the file ``path``, replaced at once (a page never loads half a file)."""
    fd, tmp = tempfile.mkstemp(suffix=".js", prefix=".tmp-", dir=path.parent)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    os.chmod(tmp, 0o666 & ~_UMASK)
    os.replace(tmp, path)


# The data files this process wrote: {path: (its sources' stat, its own)}. A data file is a script the
# page runs, so one is kept only where this very process wrote it from the sources as they still are
# (the runner writes them while later jobs render, batch/jobs/runner.py page_data, and the page at the
# end keeps them); any other, however new (from another run folder, copied with its times, edited,
# or older sources given newer times), is written again from its EXRs.
_WRITTEN = {}


# The render's channel names of each view.js in _WRITTEN: the page's writer at the end needs only
# those of a data file it keeps, not the render read again (27 EXRs of the default suite).
_NAMES = {}


def _stat_key(path):
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_ino, st.st_dev, st.st_size, st.st_mtime_ns, st.st_ctime_ns


def _sources_key(sources):
    return tuple((str(s), _stat_key(s)) for s in sources)


def _fresh(target, sources):
    """Whether ``target`` is as this process wrote it from ``sources`` as they are now."""
    kept = _WRITTEN.get(os.path.abspath(target))
    return kept is not None and kept == (_sources_key(sources), _stat_key(target))


def _wrote(target, sources, sources_key):
    """Remember ``target`` as written from ``sources`` (``sources_key``: their stat before reading)."""
    if _sources_key(sources) == sources_key:  # not replaced while being read
        _WRITTEN[os.path.abspath(target)] = (sources_key, _stat_key(target))


def _job_data(job):
    """view.js of a render's folder (written unless this process wrote it from its EXRs as they are): the render's
    channels, the z map with the standard error it divides by (block_stderr.exr; a run from before
    it: the render's per-pixel standard error), the FLIP map and the probes' images
    (``_probe_layers``). Returns the channel names, or None when there is no readable render."""
    render = job.path("render")
    if render is None:
        return None
    z, flip, block_se, probe = (job.folder / job.beside(run_folder.JOB_FILES[k])
                                for k in ("zscore", "flip", "block_stderr", "probe_residual"))
    js = job.folder / job.beside(DATA_JS)
    sources = (render, z, flip, block_se, probe)
    try:
        before = _sources_key(sources)
        if _fresh(js, sources) and os.path.abspath(js) in _NAMES:  # kept: the render's channels as read when it was written
            return _NAMES[os.path.abspath(js)]
        names, img, se = exr.read_image_and_stderr(render)
        if _fresh(js, sources):
            return names
        layers = {"render": (names, [img[..., i] for i in range(len(names))], 10)}
        layers.update(_probe_layers(job.path("probe_residual")))  # overlays (issue 21 item 4): the GGX probe's residual map
        if job.rel("block_stderr") is not None:
            bs = exr.read_rgb(block_se)
            layers["blockse"] = (["R", "G", "B"], [bs[..., i] for i in range(3)], 10)
        elif se is not None:
            layers["stderr"] = (names, [se[..., i] for i in range(len(names))], exr.SE_BITS)  # a run from before block_stderr.exr
        if job.rel("zscore") is not None:
            zr = exr.read_rgb(z)
            layers["z"] = (["R", "G", "B"], [zr[..., i] for i in range(3)], 10)
        if job.rel("flip") is not None:
            layers["flip"] = (["Y"], [exr.read_rgb(flip)[..., 0]], 10)
        _write_data(js, img.shape[1], img.shape[0], layers)
        _wrote(js, sources, before)
        _NAMES[os.path.abspath(js)] = list(names)
        return names
    except (OSError, ValueError, KeyError):
        return None


def _probe_layers(path):
    """The view.js layers of a render's probe images: ``probe`` from probe_residual.exr (batch/
    previews.py ``write_probe_residual``: the GGX probe's expected image and block z, NaN off its
    plates; ``path``: run_folder's, or None), whose channels keep their EXR names. {} when the render has none."""
    if path is None:
        return {}
    try:
        ch = exr.read(path)
    except Exception:  # noqa: BLE001 - an overlay is an aid: an unreadable one leaves the render's views
        return {}
    names = [n for n in previews.PROBE_RESIDUAL_CHANNELS if n in ch]
    return {"probe": (names, [ch[n] for n in names], 10)} if names else {}


def _reference_data(ref_exr):
    """reference_WxH.js beside the scene's shared reference (written unless this process wrote it
    from the reference as it is)."""
    js = ref_exr.with_suffix(".js")
    try:
        if not _fresh(js, (ref_exr,)):
            before = _sources_key((ref_exr,))
            ref = exr.read_rgb(ref_exr)
            _write_data(js, ref.shape[1], ref.shape[0], {"reference": (["R", "G", "B"], [ref[..., i] for i in range(3)], 10)})
            _wrote(js, (ref_exr,), before)
        return js
    except (OSError, ValueError, KeyError):
        return None


def _spectral_data(preview):
    """spectral_preview.js beside a job's spectral_preview.exr (written unless this process wrote it
    from the preview as it is):
    one layer "bands", a plane per wavelength (the EXR's half floats, exactly), channels named by
    their index; returns the wavelengths (nm) or None when the preview cannot be read."""
    from .. import spectral_exr
    js = preview.with_name(SPECTRAL_JS)
    try:
        before = _sources_key((preview,))
        img = spectral_exr.read(preview)
        planes = img.stokes[0]
        if not _fresh(js, (preview,)):
            _write_data(js, planes.shape[1], planes.shape[0],
                        {"bands": ([str(i) for i in range(planes.shape[2])], [planes[..., i] for i in range(planes.shape[2])], 10)})
            _wrote(js, (preview,), before)
        return [float(v) for v in img.wavelengths_nm]
    except (OSError, ValueError, KeyError):  # SpectralEXRError is a ValueError: the plots stay, the slider goes
        return None


def _spectra(job):
    """A spectral job's part of the page (issue 33): its band record's plots (batch/report/
    spectra.py), each failing region's worst band, and the band slider's data (spectral_preview.js,
    loaded when the section is opened) with one {nm, lo, hi} per plane. None without a record."""
    rec = spectra.record(job.entry)
    if not rec:
        return None
    src, bands = "", []
    preview = job.preview()
    wls = _spectral_data(job.folder / preview) if preview is not None else None
    if wls:
        src = run_folder.local_url(job.folder, job.beside(SPECTRAL_JS)) or ""
        by_centre = dict(zip(rec["centres"], rec["edges"]))
        for nm in wls:
            lo, hi = by_centre.get(nm, (None, None))
            bands.append({"nm": nm, "label": spectra.band_text(lo, hi) if lo is not None else f"{nm:g} nm"})
    failing = sum(r["pass"] is False for r in rec["regions"])
    head = (f"{len(rec['centres'])} bands ({rec['model'] or 'model not recorded'}"
            + (f", {rec['source']}" if rec["source"] else "") + f"), {len(rec['regions'])} probe regions, {failing} failing"
            + (f"; a band fails where |z| > {rec['z_crit']:.3g} (p < {rec['threshold']:.3g}, alpha "
               f"{_fmt(rec['alpha'])} Sidak over bands and regions)" if rec["z_crit"] else ""))
    return {"head": head, "plots": _plots_data(job, spectra.plots(rec)), "src": src, "bands": json.dumps(bands),
            "worst": spectra.worst_lines(job.entry)}


def _plots_data(job, plots):
    """spectral_plots.js in the job's folder: spectralBench.markup(document.currentScript, "<svg
    ..."), the regions' plots as templates/spectra_plots.html renders them (autoescaped), so that a
    page of many jobs carries none of them until a section is opened. Its URL, or "" when it
    cannot be written."""
    if job.beside(PLOTS_JS) is None:
        return ""
    path = job.folder / job.beside(PLOTS_JS)
    markup = _env.get_template("spectra_plots.html").render(plots=plots)
    try:
        _write_atomically(path, b"spectralBench.markup(document.currentScript, " + json.dumps(markup).encode("ascii") + b");\n")
    except OSError:
        return ""
    return run_folder.local_url(job.folder, job.beside(PLOTS_JS)) or ""


def _num(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _check_line(name, stat, shown=None):
    """``name: statistic vs threshold -> outcome`` for a noise test or a probe's test."""
    stat = _dict(stat)
    parts = [name + ":"]
    if shown:
        parts.append(shown + ";")
    if _num(stat.get("z")):  # compare_means: the largest |z|; a one-sided test (Stokes): its largest signed z
        parts.append(f"{'|z|' if 'blocks' not in stat else 'largest one-sided z'} {stat['z']:.3g},")
    if _num(stat.get("p")) and _num(stat.get("threshold")):
        ok = stat["p"] >= stat["threshold"]
        parts.append(f"p {stat['p']:.3g} {'>=' if ok else '<'} threshold {stat['threshold']:.3g}")
    return " ".join(parts)


def _checks(run):
    """Each check on one line (failures first): its statistic, threshold and outcome; under each
    recorded observer model where the probe reports one (metrics.json ``alternatives``)."""
    lines = []
    test = run.get("test")
    if isinstance(test, dict):
        verdict = _verdict(test.get("pass"), "not judged")
        if _num(test.get("p_min")) and _num(test.get("threshold")) and test.get("pass") is not None:
            # the cell of summary.md, JUnit and the panel (batch/records.py): each part with its own figures
            text = (f"noise test ({_text(test.get('tests'))} blocks of {_text(test.get('block'))} px x channels, on the "
                    f"render's {_text(test.get('noise'))} noise, alpha {_text(test.get('alpha'))}, Sidak): "
                    + records.noise_test_text(test))
        else:
            text = f"noise test: {_text(test.get('reason'))}"
        lines.append({"text": text, "verdict": verdict})
    known = ", ".join(_text(k) for k in _list(run.get("known")))
    for p in _list(run.get("probes")):
        if not isinstance(p, dict):
            lines.append({"text": _text(p), "verdict": ""})
            continue
        verdict = _verdict(p.get("pass"), "not measured")
        shown = f"{_fmt(p.get('error'))} {_text(p.get('unit'))}".strip()
        if _num(p.get("resolvable_dE00")):
            shown += f" (the test resolves {p['resolvable_dE00']:.2g} dE00)"
        stat = p.get("stat") if isinstance(p.get("stat"), dict) else p
        line = {"text": _check_line(_text(p.get("name")), stat, shown), "verdict": verdict}
        alts = _dict(p.get("alternatives"))
        if alts:
            line["under"] = [f"under the {_text(o)} observer{' (recorded: ' + known + ')' if known else ''}: "
                             + _check_line("", a).lstrip(": ") + f" -> {_verdict(_dict(a).get('pass'), '?')}"
                             for o, a in alts.items()]
        if p.get("note"):
            line["text"] += f" ({_text(p.get('note'))})"
        lines.append(line)
    rank = {"FAIL": 0, "not measured": 1, "not judged": 1}
    return sorted(lines, key=lambda l: rank.get(l["verdict"], 2))


def _extras(run):
    """What a judged run could have detected (``detectable``); its baseline comparison is
    ``_baseline``'s."""
    out = []
    det = run.get("detectable")
    if isinstance(det, dict) and _num(det.get("scale")):
        out.append(f"could have detected: a uniform radiance scale error of {100 * det['scale']:.3g} % with "
                   f"{_fmt(det.get('power'))} power at alpha {_fmt(det.get('alpha'))} ({_text(det.get('method'))})"
                   + (f"; a ColorChecker patch shift of {_fmt(det.get('patch_de00'))} dE00" if _num(det.get("patch_de00")) else ""))
    return out


TEV_KINDS = ("render", "reference", "zscore", "block_stderr", "flip", "probe_residual")


def _tev(job):
    """A tev command line (run from the output folder) for a render that failed: the render, the
    reference, the z map, the standard error z divides by, FLIP and the probe's images (those
    present: batch/run_folder.py)."""
    if _text(job.entry.get("status")) not in ("failed", "known"):
        return None
    files = [str(job.rel(k)) for k in TEV_KINDS if job.rel(k) is not None]
    return "tev " + " ".join(shlex.quote(f) for f in files)


def _regions(out, run, w, h):
    """Probe regions to outline: [{box: [x0, y0, x1, y1] pixels, label, pass, expected}]: each
    Lambertian patch's measured region (found as the probe finds it: batch/verdict/probes/
    lambert.py, from the scene's IR in <scene>/json/), and for every other probe the bounding box
    of the object its name names (the probe measures a part of it)."""
    scene_name = _text(run.get("scene"))
    if not SAFE_ID.fullmatch(scene_name):
        return []
    ir = run_folder.scene_ir(out, scene_name)
    probes = {_text(p.get("name")): p for p in _list(run.get("probes")) if isinstance(p, dict)}
    if ir is None or not probes:
        return []
    try:
        from ..verdict import raycast
        from ..verdict.probes import lambert
        scene = json.loads(ir.read_text())
        cam, objs = scene["camera"], scene["objects"]
        hits = raycast.corner_hits(cam, w, h, objs)
        out_regions = []
        for i in lambert._patches(scene):
            p = probes.get(f"lambert {objs[i]['name']}")
            if p is None:
                continue
            ys, xs = np.nonzero(raycast.pixels_inside(cam, w, h, objs, i, margin=0.7, hits=hits))
            if not len(xs):
                continue
            exp = p.get("expected")
            out_regions.append({"box": [int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1],
                                "label": _fmt(p.get('error'), '{:.2f}'), "pass": p.get("pass"),
                                "expected": exp if isinstance(exp, list) and len(exp) == 3 and all(_num(x) for x in exp) else None})
        # every other probe: the object it names, outlined by its bounding box in the image
        names = sorted(((o.get("name"), i) for i, o in enumerate(objs) if isinstance(o.get("name"), str)),
                       key=lambda t: -len(t[0]))
        per_object = {}
        for pname, p in probes.items():
            words = set(re.split(r"[\s,:]+", pname))
            index = next((i for n, i in names if n in words), None)
            if not pname.startswith("lambert ") and index is not None:
                per_object.setdefault(index, []).append(p.get("pass"))
        for index, verdicts in per_object.items():
            ys, xs = np.nonzero(raycast.pixels_inside(cam, w, h, objs, index, margin=1.0, hits=hits))
            if len(xs):
                ok = False if False in verdicts else True if all(v is True for v in verdicts) else None
                out_regions.append({"box": [int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1],
                                    "label": str(objs[index]["name"])[:40], "pass": ok, "expected": None})
        return out_regions
    except Exception:  # noqa: BLE001 - an outline is an aid: a scene it cannot read has none
        return []


PRISM_POSITIONS = "prism band positions"


def _pair(x):
    return isinstance(x, list) and len(x) == 2 and all(_num(v) for v in x)


def _prism_marks(run):
    """The prism's band positions to mark on the image (issue 21 item 4), from its positions
    probe's record (batch/verdict/probes/prism.py ``_positions``): position s (px along the fan
    from 550 nm's band centre) lies at origin_px + s * fan_direction in image pixels. Ticks: 550 nm
    and the Fraunhofer lines (where Snell's law puts those wavelengths' band centres), each
    channel's centroid as expected and as measured. None when the run has no such record."""
    from ...exporters import dispersion
    for p in _list(run.get("probes")):
        if not (isinstance(p, dict) and _text(p.get("name")).startswith(PRISM_POSITIONS)):
            continue
        exp, meas = _list(p.get("expected")), _list(p.get("measured"))
        if not (_pair(p.get("origin_px")) and _pair(p.get("fan_direction")) and len(exp) == 3):
            continue
        ticks = [{"s": 0.0, "label": "550", "kind": "wavelength"}]
        for line, s in _dict(p.get("fraunhofer_px")).items():
            nm = dispersion.FRAUNHOFER_NM.get(line)
            if _num(s):
                ticks.append({"s": float(s), "label": f"{_text(line)[:8]} {nm:.0f}" if nm else _text(line)[:8],
                              "kind": "wavelength"})
        for c, e, m in zip("RGB", exp, meas + [None] * (3 - len(meas))):
            if _num(e) and np.isfinite(e):
                ticks.append({"s": float(e), "label": c, "kind": "expected", "channel": c})
            if _num(m) and np.isfinite(m):
                ticks.append({"s": float(m), "label": c, "kind": "measured", "channel": c})
        height = p.get("band_height_px") if _num(p.get("band_height_px")) else p.get("beam_width_px")
        return {"origin": [float(v) for v in p["origin_px"]], "u": [float(v) for v in p["fan_direction"]],
                "half": float(height) / 2 if _num(height) and np.isfinite(height) else 2.0,
                "pass": p.get("pass") if isinstance(p.get("pass"), bool) else None, "ticks": ticks}
    return None


def _prism_line(run):
    """The prism's band positions in words beside the marks: each channel's centroid expected and
    measured (px along the fan from 550 nm's band centre, with its standard error), the colour
    order expected and measured; None without a positions record."""
    for p in _list(run.get("probes")):
        if not (isinstance(p, dict) and _text(p.get("name")).startswith(PRISM_POSITIONS)):
            continue
        exp, meas, se = _list(p.get("expected")), _list(p.get("measured")), _list(p.get("standard_error_px"))
        if len(exp) != 3:
            return None
        parts = []
        for c, e, m, s in zip("RGB", exp, meas + [None] * 3, se + [None] * 3):
            parts.append(f"{c} {_fmt(e, '{:.2f}')} expected, {_fmt(m, '{:.2f}') or '?'} measured"
                         + (f" +- {s:.2g}" if _num(s) else ""))
        return ("band positions (px along the fan from 550 nm's band centre; marked on the image): " + "; ".join(parts)
                + f"; colour order {_text(p.get('order_expected'))} expected, {_text(p.get('order_measured'))} measured")
    return None


def _probe_views(job):
    """The views of a render's probe images: "probe residual" (render - the GGX probe's expected
    image, per pixel) and "probe z" (its blocks' z) when probe_residual.exr is there."""
    return ["probe residual", "probe z"] if job.rel("probe_residual") is not None else []


def _baseline(out, run):
    """The job's comparison with a baseline run (metrics.json ``baseline``, batch/verdict/
    baseline.py): status, the two-sample noise test's parts (records.noise_test_text: the failing
    one first, each with its own figures; a record without them: the smallest p against its
    threshold), the mean ratio per channel, what it could detect and the time ratio
    (baseline.how_much), the reason, and links to its z-map (EXR and PNG) when they are files
    inside the run folder. None without a record."""
    from ..verdict import baseline
    base = run.get("baseline")
    if not isinstance(base, dict):
        return None
    text = f"against baseline {_text(base.get('run'))}: {_text(baseline.shown_status(base))}"
    test = records.noise_test_text(base.get("test"))
    failure = records.noise_test_failure(base.get("test"))
    named = bool(failure) and failure in _text(base.get("reason"))  # the reason (below) says it with its figures
    if test and not named:  # the two-sample test's parts, the failing one first with its own figures (the job's cell's words)
        text += f" (two-sample noise test {test})"
    elif not test and _num(base.get("p_min")) and _num(base.get("threshold")):  # a record without the test's parts
        ok = base["p_min"] >= base["threshold"]
        text += f" (smallest p {base['p_min']:.3g} {'>=' if ok else '<'} threshold {base['threshold']:.3g})"
    try:
        much = baseline.how_much(base)
    except (TypeError, ValueError, KeyError, IndexError):  # a hand-edited record: shown without it
        much = ""
    if much:
        text += f"; {much}"
    if base.get("reason"):
        text += f": {_text(base.get('reason'))}"
    links = []
    zmap = base.get("zmap")
    if isinstance(zmap, str) and zmap:
        for label, rel in (("z-map (EXR)", zmap), ("z-map (PNG)", run_folder.zmap_png(zmap))):
            url = run_folder.local_url(out, rel)
            if url:
                links.append({"label": label, "src": url})
    status = base.get("status") if base.get("status") in baseline.STATUSES else ""  # a CSS class: known words only
    return {"text": text, "status": status, "links": links}


def _deviations(options):
    """{id: first sentence of its explanation} of the repository's known_deviations.toml when the
    run used it ({} when it used its own --known file: a path from metrics.json is never opened)."""
    from ..verdict import known
    if _dict(options).get("known"):
        return {}
    try:
        devs = known.load()
    except Exception:  # noqa: BLE001 - an explanation is an aid: without it the ids are shown
        return {}
    return {d.id: " ".join(d.explanation.split()).split(". ")[0].rstrip(".") + "." for d in devs}


def _known_lines(run, deviations):
    """Why a known run is known: each recorded deviation it matched, with its explanation."""
    return [f"recorded deviation {_text(k)} (known_deviations.toml): " + deviations.get(_text(k), "see its evidence there")
            for k in _list(run.get("known"))]


def data_files(out, run):
    """Write the page's data files of a render (its view.js, the scene's reference_WxH.js) unless
    this process wrote them from their EXRs as they are: (job, the render's channel names or None
    without a readable render, the reference's data file or None). The runner calls it as each job
    finishes (batch/jobs/runner.py ``page_data``), the page's writer for every render at the end."""
    job = run_folder.Job(out, run)
    if job.rel("render") is None:
        return job, None, None
    names = _job_data(job)
    ref = job.rel("reference")  # the scene's shared reference, or a run's own copy from before issue 21
    ref_js = _reference_data(out / ref) if names and ref is not None else None
    return job, names, ref_js


def _viewer(out, run, deviations=None):
    job, names, ref_js = data_files(out, run)
    data = run_folder.local_url(out, job.beside(DATA_JS)) if names else None
    if not data:
        return None
    ref = job.rel("reference")
    ref_data = run_folder.local_url(out, ref.with_suffix(".js")) if ref_js else None
    views = ["render"] + (["reference", "difference"] if ref_data else [])
    views += [v for v, k in (("z-score", "zscore"), ("FLIP", "flip")) if job.rel(k) is not None]
    views += _probe_views(job)
    if all(f"S{k}.{c}" in names for k in range(4) for c in "RGB"):
        views += STOKES_VIEWS
    lines = _checks(run)
    status = _text(run.get("status"))
    first = "difference" if status in ("failed", "known") and "difference" in views else "render"
    w, h = (run.get("resolution") or [0, 0])[:2] if isinstance(run.get("resolution"), list) else (0, 0)
    regions = _regions(out, run, int(w), int(h)) if _num(w) and _num(h) and w and h else []
    return {"scene": _text(run.get("scene")), "backend": _text(run.get("backend")), "mode": _text(run.get("mode")),
            "status": status, "css": _css(run.get("status")), "views": views, "first": first,
            "src": data, "ref": ref_data or "", "checks": lines, "extras": _extras(run),
            "reason": _text(run.get("reason")), "known": _known_lines(run, deviations or {}),
            "judged_by": _text(results.judged_by(run)), "self_check": results.checked_against_itself(run),
            "tev": _tev(job), "regions": json.dumps(regions),
            "marks": json.dumps(_prism_marks(run)), "prism": _prism_line(run), "baseline": _baseline(out, run),
            "numbers": [f"{_text(k)}: {_text(records.flip_text(run)) if k == 'flip' else _fmt(v)}"
                        for k, v in _dict(run.get("metrics")).items()],
            "reference_problems": _reference_problems(run), "conversions": _conversions(run), "why": _why(out, run),
            "spectra": _spectra(job)}


def _why(out, run):
    """The report's "why" box of a diagnosed render (metrics.json ``diagnosis``, issue 34): the
    diagnosis in words, each ranked model as a line, the ready known_deviations.toml entry, and a
    link to the reference as the likely model predicts the render (an EXR inside the run folder).
    None without a diagnosis. Every value is anyone's text: shown escaped, numbers checked."""
    from ..verdict import diagnosis
    diag = run.get("diagnosis")
    if not isinstance(diag, dict):
        return None
    lines = []
    for m in diag.get("models") if isinstance(diag.get("models"), list) else []:
        if not isinstance(m, dict) or not isinstance(m.get("params"), dict):
            continue
        try:
            line = diagnosis.short(m)
        except (TypeError, ValueError, KeyError):
            line = _text(m.get("model"))
        full = "fully explains" if m.get("fully_explains") is True else "does not fully explain"
        lines.append(f"{line} ({full}; {_text(m.get('evidence'))}): {_text(m.get('explanation'))}"
                     + (f" [{_text(m['note'])}]" if m.get("note") else ""))
    image = run_folder.Job(out, run).diagnosis_image()
    url = run_folder.local_url(out, image) if image is not None else None
    return {"text": _text(diag.get("text")), "models": lines, "toml": _text(diag.get("known_deviation") or ""),
            "image": url or ""}


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
            src = run_folder.local_url(out, run_folder.stability_strip(backend, name))
            if src:
                strips.append({"backend": backend, "src": src, "alt": f"{name} {backend}"})
        cells = [{"css": _css(r.get("status")), "value": _text(r.get("value", "")), "backend": _text(r.get("backend", "")),
                  "status": _text(r.get("status")), "mean": _fmt(r.get("mean")),
                  "problems": _text(r.get("problems")) or _text(r.get("reason", ""))} for r in rows]
        sections.append({"name": name, "strips": strips, "rows": cells})
    return sections


def _studies(out, rows):
    """--study spectral-vs-rgb: per render pair, the two renders at one exposure and the dE00 map
    side by side, with the numbers of summary.md (batch/studies/spectral_vs_rgb.py)."""
    pairs = []
    for r in (r for r in rows if isinstance(r, dict)):
        images = _dict(r.get("images"))
        srcs = {k: run_folder.local_url(out, images[k]) for k in ("spectral", "rgb", "de00") if isinstance(images.get(k), str)}
        d, t = _dict(r.get("de00")), _dict(r.get("test"))
        numbers = (f"CIEDE2000 over {_text(d.get('blocks'))} blocks of {_text(d.get('block'))} px: mean {_fmt(d.get('mean'), '{:.2f}')}, "
                   f"95th percentile {_fmt(d.get('p95'), '{:.2f}')}, max {_fmt(d.get('max'), '{:.2f}')} (noise alone: "
                   f"{_fmt(d.get('noise_p95'), '{:.2f}')}; visible from {_fmt(d.get('visible'))}); beyond noise: "
                   f"{'yes' if t.get('beyond_noise') else 'no'} (p {_fmt(t.get('p_min'), '{:.2g}')}, threshold "
                   f"{_fmt(t.get('threshold'), '{:.2g}')})") if d else ""
        pairs.append({"scene": _text(r.get("scene")), "light": _text(r.get("light")),
                      "rgb": _text(" ".join(str(x) for x in (r.get("rgb"), r.get("rgb_mode")) if x)),
                      "status": _text(r.get("status")), "verdict": _text(r.get("verdict") or r.get("status")),
                      "reason": _text(r.get("reason")), "numbers": numbers, "top": _fmt(images.get("de00_top"), "{:.2g}"),
                      "srcs": srcs if len(srcs) == 3 else {}})
    return pairs


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
    """The run's metrics.json (batch/run_folder.py ``read_lenient``: paths relative to the run
    folder, as the page links them; a version this code does not know shown as far as it can be)."""
    return run_folder.read_lenient(out)


def render(out_dir):
    """The page of an output folder, as a string."""
    out = Path(out_dir)
    data = load(out)
    runs = [r for r in _list(data.get("runs")) if isinstance(r, dict)]
    sweeps = [s for s in _list(data.get("sweeps")) if isinstance(s, dict)]
    viewers = {}
    deviations = _deviations(data.get("options")) if any(r.get("known") for r in runs) else {}
    for i, r in enumerate(runs):
        v = _viewer(out, r, deviations)
        if v:
            viewers[i] = v
    ids = _ids(runs, viewers)
    for i, v in viewers.items():
        v["id"] = ids[i]
    shown = sorted(viewers, key=lambda i: (ORDER.get(viewers[i]["css"], 9), viewers[i]["scene"], viewers[i]["backend"]))
    listed, not_run = grouping.not_run_everywhere(runs)
    listed_ids = {id(r) for r in listed}
    summary_text = run_folder.summary_text(out)
    charts = []
    for c in sorted({_text(s.get("chart")) for s in sweeps if s.get("chart")}):
        src = run_folder.local_url(out, c)
        if src:
            charts.append({"src": src, "alt": c})
    stab = _list(data.get("stability"))
    return _env.get_template("report.html").render(
        name=out.name, started=_text(data.get("started", "")), rows=_summary_rows(runs, ids, listed_ids),
        not_run=[{k: _text(v) for k, v in g.items()} for g in not_run], viewer_js=VIEWER_JS,
        rgb=_section(summary_text, "RGB renderers against the spectral references"), charts=charts,
        sweep_text=_section(summary_text, "Speed against accuracy (sweeps)"),
        stability=_stability(out, stab), studies=_studies(out, _list(data.get("studies"))),
        viewers=[viewers[i] for i in shown])


def write(out_dir):
    path = Path(out_dir) / run_folder.REPORT
    path.write_text(render(out_dir), encoding="utf-8")
    return path
