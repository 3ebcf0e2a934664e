"""Render reference images (an explicit request: this is the only thing that changes references/).

    .venv/bin/python batch/make_references.py [-s SCENE ...] [-r NAME] [-e [NAME=]PATH] [--variant V] [--device D]
                                              [--renderers FILE ...] [--art-ggx] [--scale F]
                                              [--spp 4096 | --factor F] [--passes 8]
                                              [--cluster ADDRESS | local:N] [--replace [--accept]]
    .venv/bin/python batch/make_references.py --crosscheck NAME [-s SCENE ...] [--references DIR]
                                              [--spp N | --factor F] [--passes 2] [--detect F] [--no-record]
                                              [--known FILE]

References change only on request: a scene whose reference (its .exr or .json) is already in the
output folder is left alone and named, with what is wrong with it if anything (stale, broken), unless
``--replace`` asks to render it again. Two makers never write one scene's reference at once: each
holds the scene's lock (references/.work/.locks/<scene>.lock) from planning to writing; a scene locked by
another maker is skipped and named (exit status 1).

Any one backend renders it: ``-r NAME`` (default mitsuba) is a built-in backend or a renderer
declared with ``--renderers FILE`` (docs/backends.md, "Add your renderer"); ``-e [NAME=]PATH``, ``--variant``
and ``--device cpu|gpu|auto`` (Mitsuba) and ``--art-ggx`` (ART) mean what they mean to the runner and go through the runner's
own option types and declaration loading (batch/cli.py); a bad value is a usage error (exit 2)
naming the option. Each reference is rendered at the scene's resolution (times ``--scale F``, as
the runner scales it: such a reference judges renders at that resolution or an integer fraction
of it, batch/verdict/references.py ``usable_for``) with ``spp`` samples per pixel in all (or
``factor`` x the scene's own), in ``passes`` independent passes (distinct seeds). Every pass is a
``reference`` job (batch/jobs/job.py) whose backend options rebuild the backend on any worker (a
declared renderer's carry its declaration) on the chosen engine (this machine, or a Dask cluster:
passes of one scene run on several workers at once); each finished pass is kept in
references/.work/, so a run that is stopped resumes where it was. When every pass of a scene is
there, their mean and the standard error of that mean (the pass-to-pass spread) are written as
the reference with its provenance (backend, mode, spp, passes, seeds, resolution and scale, the
versions the passes recorded, a declared renderer's declaration, the executable, the command),
and the passes are removed. The reference is saved as one step (batch/verdict/references.py
``save``: unique temporary files, synced, the record carrying the image's sha256 and renamed
first, so an interrupted save is seen as a broken reference, never as a new image with an old
record).

Replacing (``--replace``) a usable reference judges the new one against the old first, on both
their noises, with the block test that judges every render against a reference
(batch/verdict/references.py ``judge_replacement``), and prints the verdict (p_min against its
Sidak threshold, the mean ratio new/old per channel with its standard error, the smallest uniform
change the test would have refused) and the two provenances side by side. A new reference that
differs from the old beyond noise (or cannot be judged against it: other channels, resolutions
not an integer factor apart) is refused, the old one left untouched (exit status 1; the new passes
stay in references/.work/, so the same command with ``--accept`` replaces it without rendering
again); ``--accept`` replaces it anyway. A stale (the scene changed) or broken old reference is
replaced without a verdict.

History: a replaced reference is never overwritten. Its record and image move to
``<out>/history/<scene>/<UTC time YYYYmmddTHHMMSSZ>-<old backend>/`` with ``replaced.json`` (when,
who: user@host, why: the old one's state and the verdict, whether ``--accept`` overrode it, the
command, both provenances). They are linked there, under the scene's lock, after the new reference
is rendered and judged and before it is saved; the save itself is the same atomic step (the old
files stay current until it). A search never reads history (only <folder>/<scene>.exr/.json are
candidates, and a folder holding ``replaced.json`` is refused even when named with --references);
the extension build leaves history/ out. To restore an old reference, move its two files back.

Cross-checks (``--crosscheck NAME [--references DIR]``, issue 44): each chosen reference is judged
against a render of its scene by another, independent renderer NAME, on both noises (the block and
scale tests of ``judge_replacement``, the diagnosis where they differ: batch/verdict/crosscheck.py),
at the reference's resolution, the scene's spp and 2 passes unless ``--spp``/``--factor``/``--passes``
say otherwise; the outcome goes into the reference's record (``crosschecks``, tied to the image's
sha256), written as one step, and no image changes. Agreements are recorded only at the stated
power (``--detect``, default 0.5 %), disagreements always (a finding); ``--no-record`` writes
nothing. A renderer that differs from the reference by exactly what a recorded deviation of that
renderer predicts (``--known FILE``, default known_deviations.toml: its scale model applied to the
noise test, as the verdict applies it for ``known``) agrees *up to* that deviation: recorded with
its id (``agrees_under``) and the power of the test under its model; a deviation whose model does
not fit leaves it differing. The passes of a cross-check that differs are kept (the same command
judges them again without rendering, e.g. once a deviation is recorded). Exit status 0 when every
scene agrees, 1 naming each that does not, 2 for usage.

Observer layers (``--film cmf --layers OBSERVER``, batch/verdict/observer_layers.py) go to
``<out>/layers/<scene>/<observer>.exr``, a folder no scene name reaches (a scene name may hold
dots: the old place, ``<scene>.<observer>.exr`` beside the reference, is the reference of a scene
named ``<scene>.<observer>``). ``--migrate-layers`` moves the layers of a folder still in that old
layout (only files whose sha256 is their record's; the bytes unchanged, the records' ``file``
pointed at the new place) and renders nothing. A reference whose files would replace another
scene's (that old-layout layer, or a record of another scene where a file system ignores case) is
refused before anything renders, naming both scenes (exit status 1). ``--layers-only`` renders the
layers at the reference's own size: a ``--scale`` that gives another size is a usage error naming
the scene and both sizes (exit status 2).
"""
import argparse
import contextlib
import datetime as dt
import json
import math
import os
import platform
import shlex
import shutil
import sys
from pathlib import Path

import filelock

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

SEED_STRIDE = 1000  # pass k renders with seeds seed + k * SEED_STRIDE + chunk (chunks < 1000)
DEFAULT_BACKEND = "mitsuba"


class Usage(ValueError):
    """A usage error (exit 2); the message names the option."""


def pass_jobs(name, scene, backend, mode, spp, passes, seed, work):
    """One job per pass; passes already in ``work`` (same scene, backend, mode and samples) are skipped."""
    from spectral_bench.batch.jobs import job as jobs
    per_pass = math.ceil(spp / passes)
    todo = []
    for k in range(passes):
        j = jobs.make("reference", name, scene, backend.name, mode, per_pass, work, f"pass{k}", passes=1,
                      backend_options=backend.options, seed=seed + k * SEED_STRIDE, timeout=6 * 3600,
                      label=f"{name} pass {k + 1}/{passes}", extra={"pass": k})
        record = read_done(work / f"pass{k}" / "done.json")
        if not (record and record.get("job") == jobs.job_id(j)):
            todo.append(j)
    return todo, per_pass


def read_done(path):
    """The record of a finished pass (``done.json``: a dict with the job id and its seconds), or None
    when there is none; a file that is unreadable, truncated or not such a record is named on
    stdout and its pass renders again (None)."""
    try:
        record = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError, RecursionError) as exc:
        print(f"{path}: not a readable pass record ({exc}); that pass renders again", flush=True)
        return None
    ok = isinstance(record, dict) and isinstance(record.get("job"), str) and isinstance(record.get("time_s"), (int, float)) \
        and not isinstance(record.get("time_s"), bool) and math.isfinite(record["time_s"])
    if not ok:
        print(f"{path}: not a pass record (no job id and seconds); that pass renders again", flush=True)
        return None
    return record


def write_done(path, record):
    """``done.json`` written whole or not at all (a new file renamed over the name): an interrupted
    write never leaves a truncated record."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps(record, default=str), encoding="utf-8")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _pass_recorder(remaining, complete):
    """The scheduler's callback for one rendered pass: it is recorded in its folder's done.json (a
    run of the same command resumes after it), counted against ``remaining`` {scene: passes left},
    and ``complete(scene)`` is called when a scene's last pass is in; a failed or unrecordable pass
    is said and left for the next run."""
    from spectral_bench.batch.jobs import job as jobs

    def finished(job, record):
        work = Path(job["out"])
        if record.get("status") != "rendered":
            print(f"{job['scene_name']}: pass {job['extra']['pass']} failed: {record.get('reason')}", flush=True)
            return
        try:
            write_done(work / job["folder"] / "done.json", dict(record, job=jobs.job_id(job)))
        except OSError as exc:
            print(f"{job['scene_name']}: pass {job['extra']['pass']}: cannot record it in {work / job['folder']}: "
                  f"{exc.strerror or exc}; run the same command again to render it", flush=True)
            return
        remaining[job["scene_name"]] -= 1
        print(f"{job['label']}: {record['time_s']:.1f} s", flush=True)
        if remaining[job["scene_name"]] == 0:
            complete(job["scene_name"])
    return finished


def merge(work, passes, expect=None):
    """(names, mean, standard error of the mean, summed render seconds, versions) of the passes;
    ``expect``: the (width, height) they were rendered at (checked in each EXR's header before its
    pixels are read)."""
    import numpy as np
    from spectral_bench.batch import exr
    images, seconds, versions = [], 0.0, None
    for k in range(passes):
        names, img = exr.read_image(work / f"pass{k}" / "render.exr", expect=expect)
        record = read_done(work / f"pass{k}" / "done.json")
        if record is None:
            raise ValueError(f"{work / f'pass{k}' / 'done.json'}: no pass record: run the same command again to render it")
        seconds += record["time_s"]
        versions = record.get("versions")
        images.append(img.astype(np.float64))
    stack = np.stack(images)
    return names, stack.mean(axis=0), stack.std(axis=0, ddof=1) / math.sqrt(passes), seconds, versions


def parser():
    from spectral_bench.batch import cli
    from spectral_bench.batch.verdict import references
    T = cli.TYPES  # the runner's checked option types: a bad value exits 2 naming the option
    ap = argparse.ArgumentParser(prog="batch/make_references.py", description=__doc__.splitlines()[0])
    ap.add_argument("-i", "--input", nargs="+", action="extend", type=T["input"],
                    help="scenes.blend or scene IR JSON files (repeatable; default: scenes.blend)")
    ap.add_argument("-s", "--scene", action="append", type=T["scene"])
    ap.add_argument("-r", "--renderer", type=T["renderer"], metavar="NAME",
                    help=f"the backend that renders the references: a built-in one or a renderer declared with "
                         f"--renderers (one, not a group; default {DEFAULT_BACKEND})")
    ap.add_argument("-e", "--exec", action="append", type=T["exec"], metavar="[NAME=]PATH",
                    help="the renderer's executable, e.g. mitsuba=/opt/mitsuba/mitsuba (a bare PATH is -r's)")
    ap.add_argument("--variant", type=T["variant"], help="force a Mitsuba variant (-r mitsuba; default: cheapest that models the scene)")
    ap.add_argument("--film", type=T["film"], default="rgb", metavar="rgb|cmf",
                    help="-r mitsuba: rgb (Mitsuba's own film; default) or cmf (the scene format's colour: CIE 1931 "
                         "at 1 nm and the IEC 61966-2-1 matrix; unpolarised scenes only)")
    from spectral_bench.exporters import colorimetry
    others = [o for o in colorimetry.OBSERVERS if o != colorimetry.GROUND_TRUTH]
    ap.add_argument("--layers", action="append", choices=others, metavar="OBSERVER",
                    help="with --film cmf: also render, from the same paths, the difference each of these observers' "
                         f"films would see ({', '.join(others)}; repeatable), kept in the output folder as "
                         "layers/<scene>/<observer>.exr (batch/verdict/observer_layers.py)")
    ap.add_argument("--layers-only", action="store_true",
                    help="with --layers: add the layers to current CMF-film references without rendering their images "
                         "again (the layers' own --spp and --passes; the image is not touched)")
    ap.add_argument("--migrate-layers", action="store_true",
                    help="move the observer layers of the references in --out (or of -s scenes) from the old layout "
                         "<scene>.<observer>.exr, beside the reference, to layers/<scene>/<observer>.exr, the bytes "
                         "unchanged and their records pointed there; renders nothing")
    ap.add_argument("--device", type=T["device"], default="auto", metavar="cpu|gpu|auto",
                    help="-r mitsuba: render on the GPU (cuda_ad_* variants; an error where CUDA does not render), the "
                         "CPU, or the GPU where a CUDA probe renders (default auto)")
    ap.add_argument("--renderers", action="append", type=T["renderers"], metavar="FILE",
                    help="declare renderers that run as a command ([renderers.NAME] tables; repeatable); select one with -r NAME")
    ap.add_argument("--art-ggx", action="store_true",
                    help="-r art: write GGX_MICROFACET_DISTRIBUTION_CONST for an ART build that has GGX")
    ap.add_argument("--scale", type=T["scale"], default=None, metavar="F",
                    help="resolution scale as the runner's --scale (default 1.0: the scene's resolution); the "
                         "reference then judges renders at that resolution or an integer fraction of it")
    ap.add_argument("--spp", type=T["spp"], default=None, help="reference samples per pixel in all (default 4096; "
                    "--crosscheck: the scene's own)")
    ap.add_argument("--factor", type=cli.int_in(1, 1 << 16), help="reference spp = factor x the scene's spp (instead of --spp)")
    ap.add_argument("--passes", type=cli.int_in(2, cli.MAX_PASSES), default=None,
                    help="independent passes (at least 2: their spread is the reference's noise; default 8; "
                         "--crosscheck: 2, as a run's)")
    ap.add_argument("--seed", type=T["seed"], default=1000, help="first seed (distinct from the runner's default 0)")
    ap.add_argument("--out", type=T["out"], default=None, help=f"where references are written (default {references.REFERENCE_DIR})")
    ap.add_argument("--cluster", metavar="ADDRESS", type=T["cluster"], help="a Dask scheduler, or local:N (default: this machine)")
    ap.add_argument("--replace", action="store_true",
                    help="render again scenes whose reference is already in the output folder (default: leave them); "
                         "the new one is judged against the old, which is kept in <out>/history/")
    ap.add_argument("--accept", action="store_true",
                    help="with --replace: replace a reference even where the new one differs from the old beyond noise")
    ap.add_argument("--alpha", type=T["alpha"], help="with --replace: significance level of the noise test of new "
                    "against old, as the runner's --alpha (default 0.01)")
    ap.add_argument("--block", type=T["block"], help="with --replace: block side in pixels of that test (default: from --min-samples)")
    ap.add_argument("--min-samples", type=T["min_samples"], help="with --replace: samples pooled per block of that test "
                    "(default 65536, as the runner's; larger blocks see smaller uniform changes)")
    ap.add_argument("--crosscheck", type=T["renderer"], metavar="NAME",
                    help="judge the references against renders of the same scenes by another, independent renderer NAME "
                         "(a built-in backend or a declared renderer) on both noises, and record the outcome in each "
                         "reference's provenance (crosschecks); renders and changes no reference image")
    ap.add_argument("--references", type=T["out"], metavar="DIR",
                    help=f"with --crosscheck: the folder whose references are cross-checked (default {references.REFERENCE_DIR})")
    ap.add_argument("--detect", type=T["detect"], metavar="F",
                    help="with --crosscheck: the stated power, the uniform relative error a cross-check must detect "
                         f"with 90 %% power (default {0.005:g}); one that cannot is not recorded (exit status 1)")
    ap.add_argument("--no-record", action="store_true",
                    help="with --crosscheck: judge and print only; write nothing into the references' records")
    ap.add_argument("--known", type=T["known"], metavar="FILE",
                    help="with --crosscheck: the known deviations a renderer may agree up to (default: known_deviations.toml)")
    return ap


def colour_route(backend, mode):
    """How a reference's RGB was made (its provenance's ``colour``): the film, the observer and
    the matrix, as far as this project knows them for the backend."""
    from spectral_bench.batch.backends.mitsuba import spectral as mitsuba_spectral
    if backend.name == "mitsuba":
        if backend.options.get("film") == "cmf":
            return {"film": mitsuba_spectral.CMF_FILM, "observer": "cie1931", "matrix": "IEC 61966-2-1"}
        if mode and ("mono" in mode or mode.endswith("_rgb")):
            return {"film": f"Mitsuba hdrfilm ({mode}): constant spectra, exact for the flat spectrum of the scene",
                    "observer": "cie1931", "matrix": "IEC 61966-2-1"}
        return {"film": f"Mitsuba hdrfilm ({mode})", "observer": "mitsuba3 (5 nm CIE 1931, 1 / 106.7502)",
                "matrix": "Mitsuba's xyz_to_srgb (six digits)"}
    decl = getattr(backend, "decl", None)
    observer = decl.get("observer") if isinstance(decl, dict) else None  # a declared spectral renderer's
    return {"film": f"{backend.name} ({mode})", "observer": observer or "the renderer's own", "matrix": "unknown"}


def chosen_backend(args):
    """(backend, its name) from -r, -e, --variant, --renderers and --art-ggx, built by the runner
    (batch/jobs/runner.py ``make_backend``) from the options dict the runner's parser gives;
    raises Usage naming the option."""
    from spectral_bench.batch import backends, cli
    from spectral_bench.batch.backends import command
    from spectral_bench.batch.jobs import runner
    try:
        declared = cli.merge_declarations([(f, command.load_file(f)) for f in args.renderers or []])
    except command.DeclarationError as exc:
        raise Usage(f"--renderers: {exc}") from None
    name = args.renderer or DEFAULT_BACKEND
    known = backends.known_names(declared)
    if name not in known:
        raise Usage(f"-r {name}: unknown backend or declared renderer (known: {', '.join(known)})")
    members = backends.expand([name], declared)
    if members != [name]:
        raise Usage(f"-r {name}: a group ({', '.join(members)}); a reference comes from one backend: -r NAME")
    execs = {}
    for item in args.exec or []:
        who, path = cli.split_exec(item)
        if who != "*" and who not in known:
            raise Usage(f"-e {item}: {who!r} is no backend or declared renderer (known: {', '.join(known)})")
        if who not in ("*", name):
            raise Usage(f"-e {item}: the references are rendered by -r {name}, not {who}")
        execs[name] = path
    if args.variant and name != "mitsuba":
        raise Usage(f"--variant {args.variant}: a Mitsuba variant, but -r {name} renders the references")
    if args.art_ggx and name != "art":
        raise Usage(f"--art-ggx: an ART option, but -r {name} renders the references")
    if args.accept and not args.replace:
        raise Usage("--accept: only with --replace (it lets a reference be replaced by one that differs beyond noise)")
    if args.device == "gpu" and name != "mitsuba":
        raise Usage(f"--device gpu: Mitsuba's CUDA variants, but -r {name} renders the references")
    if args.film != "rgb" and name != "mitsuba":
        raise Usage(f"--film {args.film}: a Mitsuba film, but -r {name} renders the references")
    if args.layers and args.film != "cmf":
        raise Usage(f"--layers {args.layers[0]}: observer layers are rendered through the CMF film: add --film cmf")
    if args.layers_only and not args.layers:
        raise Usage("--layers-only: name the observers with --layers")
    if args.layers_only and args.replace:
        raise Usage("--layers-only adds layers to a reference and never replaces its image: drop --replace")
    opts = {"renderer": [name], "exec": execs, "variant": args.variant, "device": args.device, "art_ggx": args.art_ggx,
            "film": args.film, "layers": sorted(set(args.layers or [])),
            "approximate": False, "renderers": declared or None}
    return runner.make_backend(name, opts), name


def migrate_layers(out, scenes):
    """--migrate-layers: every reference record in ``out`` (or those of ``scenes``) has its
    old-layout observer layers moved (batch/verdict/observer_layers.py ``migrate``). Exit status 0,
    or 1 where a layer file could not be moved (named with why)."""
    from spectral_bench.batch.verdict import observer_layers, references
    from spectral_bench.exporters import names
    left_any, moved_any = False, False
    for meta_path in sorted(Path(out).glob("*.json")):
        name = meta_path.stem
        if (scenes and name not in scenes) or names.scene_problem(name) is not None or references.is_history(out):
            continue
        moved, left = observer_layers.migrate(out, name)
        for old, new in moved:
            print(f"{name}: {old} -> {new}", flush=True)
            moved_any = True
        for path, why in left:
            print(f"{name}: {path}: {why}", flush=True)
            left_any = True
    if not moved_any and not left_any:
        print(f"{out}: no observer layer in the old layout; nothing moved", flush=True)
    return 1 if left_any else 0


def main(argv=None):
    pkg_bootstrap.package()
    args = parser().parse_args(argv)
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.verdict import references
    if args.crosscheck is not None:
        try:
            crosscheck_usage(args)
            backend, _name = chosen_backend(args)
        except Usage as exc:
            print(f"batch/make_references.py: error: {exc}".replace(f"-r {args.crosscheck}", f"--crosscheck {args.crosscheck}"),
                  file=sys.stderr, flush=True)
            return 2
    else:
        stray = [o for o, v in (("--references", args.references), ("--detect", args.detect),
                                ("--no-record", args.no_record), ("--known", args.known)) if v]
        if stray:
            print(f"batch/make_references.py: error: {stray[0]}: only with --crosscheck NAME", file=sys.stderr, flush=True)
            return 2
        args.out = args.out or str(references.REFERENCE_DIR)
        args.scale = 1.0 if args.scale is None else args.scale
        args.spp = 4096 if args.spp is None else args.spp
        args.passes = args.passes or 8
    if args.migrate_layers:
        return migrate_layers(Path(args.out), args.scene)
    if args.crosscheck is None:
        try:
            backend, _name = chosen_backend(args)
        except Usage as exc:
            print(f"batch/make_references.py: error: {exc}", file=sys.stderr, flush=True)
            return 2
    ok, why = backend.availability()
    if not ok:
        option = "--crosscheck" if args.crosscheck else "-e" if args.exec else "-r"
        print(f"batch/make_references.py: error: {option} {backend.name}: cannot render here: {why}", file=sys.stderr, flush=True)
        return 2
    args.input = args.input or [str(scene_sources.DEFAULT_BLEND)]
    if backend.name == "mitsuba":
        problem = backend.device_problem()
        if problem:
            print(f"batch/make_references.py: error: {problem}", file=sys.stderr, flush=True)
            return 2
        print(backend.llvm_message(), flush=True)
    if args.crosscheck is not None:
        return crosscheck(args, argv, backend)
    out = Path(args.out)
    with contextlib.ExitStack() as held:  # the scenes' locks, released however this ends
        try:
            return _make(args, argv, out, held, backend)
        except Usage as exc:  # found while planning (a --scale the reference is not at): nothing rendered
            print(f"batch/make_references.py: error: {exc}", file=sys.stderr, flush=True)
            return 2


def existing_state(out, name, scene):
    """What the output folder holds for ``name``: current, stale or broken (naming the file)."""
    from spectral_bench.batch.verdict import references
    found = references.search(name, out, scene=scene)
    if found.ref is not None:
        return f"its reference {found.ref.path} exists and is current"
    return "its reference exists but is not usable: " + "; ".join(f"{p['file']}: {p['problem']}" for p in found.problems)


# -- replacing: the old reference against the new -------------------------------------------------
SHOWN = ("backend", "mode", "colour", "spp", "passes", "resolution", "scale", "versions", "date")


def _cell(value):
    if isinstance(value, dict):
        return "; ".join(f"{k} {v}" for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))) or "-"
    if isinstance(value, list):
        return "x".join(map(str, value)) if all(isinstance(v, int) for v in value) else ", ".join(map(str, value))
    return "-" if value is None else str(value)


def provenance_table(old, new):
    """Lines: the old and the new provenance side by side (what a reader checks before trusting
    the replacement); values from the old record are any text: shown with repr where not plain."""
    shown = lambda t: (t if t.isprintable() else repr(t))[:120]
    rows = [(key, shown(_cell(old.get(key))) if old is not None else "(no readable record)", _cell(new.get(key)))
            for key in SHOWN]
    if "declaration" in new or (old or {}).get("declaration"):
        src = lambda p: (p or {}).get("declaration", {}).get("source") if isinstance((p or {}).get("declaration"), dict) else None
        rows.append(("declared in", shown(_cell(src(old))), _cell(src(new))))
    width = max(len(r[1]) for r in rows)
    return [f"  {'':<12}{'old':<{width + 2}}new"] + [f"  {k:<12}{o:<{width + 2}}{n}" for k, o, n in rows]


def verdict_lines(v):
    """The verdict of judge_replacement as lines."""
    if not v["comparable"]:
        return [f"  cannot judge the new reference against the old: {v['reason']}"]
    t = v["test"]
    block_ok = t.get("block_pass", t["pass"])
    lines = [f"  new against old on both noises ({t['name']}, alpha {t['alpha']}, {t['tests']} tests of "
             f"{t['block']}x{t['block']} px blocks at {v['judged_at'][0]}x{v['judged_at'][1]}): p_min = {t['p_min']:.3g} "
             f"{'>=' if block_ok else '<'} threshold {t['threshold']:.3g}, max |z| = {t['z_max']:.2f}"]
    sc = t.get("scale_test")
    if isinstance(sc, dict) and sc.get("p_min") is not None:  # the pooled scale test, which sees a uniform change
        lines.append(f"  scale test (Sidak over channels): p_min = {sc['p_min']:.3g} "
                     f"{'>=' if sc.get('pass') else '<'} threshold {sc['threshold']:.3g}")
    lines[-1] += ": " + ("the same within noise" if v["same"] else "they DIFFER beyond noise")
    ratios = ", ".join(f"{c} {r[0]:.5f} +- {r[1]:.5f}" if r else f"{c} -" for c, r in v["ratio"].items())
    lines.append(f"  mean ratio new/old (+- standard error): {ratios}")
    d = v["detectable"]
    lines.append("  the test would have refused a uniform change of the whole image of "
                 + (f"+-{100 * d:.2g} % or more (detected half the time at that size)" if d is not None else "no size up to 100 %"))
    return lines


def _who():
    import getpass
    try:
        user = getpass.getuser()
    except Exception:  # noqa: BLE001 - no user name in this environment
        user = f"uid {os.getuid()}" if hasattr(os, "getuid") else "unknown"
    return f"{user}@{platform.node()}"


def _make(args, argv, out, held, backend):
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.jobs import job as jobs, plan as planning
    from spectral_bench.batch.verdict import references
    plans, failed = [], []
    for name, scene in scene_sources.load(args.input):
        if args.scene and name not in args.scene:
            continue
        if isinstance(scene, Exception):
            print(f"{name}: {scene}", flush=True)
            failed.append(name)
            continue
        try:
            rendered = planning.for_run(scene, {"scale": args.scale}, judged=False)
        except Exception as exc:  # noqa: BLE001 - a scale that leaves the IR's bounds fails this scene
            print(f"{name}: {exc}", flush=True)
            failed.append(name)
            continue
        mode, why = backend.mode_for(rendered)
        if mode is None:
            print(f"{name}: unsupported: {why}", flush=True)
            continue
        lock = references.scene_lock(out, name)
        try:
            lock.acquire(timeout=0)
        except filelock.Timeout:
            print(f"{name}: another make_references is writing this reference (lock {lock.lock_file}); skipped",
                  flush=True)
            failed.append(name)
            continue
        held.callback(lock.release)
        if args.layers_only:
            from spectral_bench.batch.verdict import observer_layers
            found = references.search(name, out, scene=scene)
            own = observer_layers.own_observer(found.ref.provenance) if found.ref is not None else None
            if found.ref is None or own != "cie1931":
                why = (existing_state(out, name, scene) if found.ref is None
                       else f"its reference was made with the {own or 'unrecorded'} observer, not the CMF film")
                print(f"{name}: no layers added: {why}", flush=True)
                failed.append(name)
                continue
            r = scene["render"]
            w, h = planning.scaled_size(r["width"], r["height"], args.scale)
            H, W = found.ref.mean.shape[:2]
            if (h, w) != (H, W):  # a layer is the reference's difference pixel by pixel: its size
                raise Usage(f"--scale {args.scale:g}: scene {name}'s reference {found.ref.path} is {W}x{H} (recorded "
                            f"--scale {found.ref.provenance.get('scale', 'not recorded')}), its layers would be "
                            f"{w}x{h}: --layers-only renders them at the reference's size: give its --scale")
        elif (owner := references.owner_elsewhere(out, name)) is not None:  # before anything renders
            print(f"{name}: refusing to write its reference into {out}: {owner}; nothing rendered, nothing replaced",
                  flush=True)
            failed.append(name)
            continue
        # checked under the lock: a reference another maker has just written counts as existing
        elif not args.replace and any(p.exists() for p in (out / f"{name}.exr", out / f"{name}.json")):
            print(f"{name}: {existing_state(out, name, scene)}; left as it is (--replace renders it again)",
                  flush=True)
            continue
        spp = scene["render"]["spp"] * args.factor if args.factor else args.spp
        # a layers-only run's passes: .work/.layers/<scene>, where no scene's own passes (.work/<scene>) can be
        work = out / ".work" / ".layers" / name if args.layers_only else out / ".work" / name
        todo, per_pass = pass_jobs(name, rendered, backend, mode, spp, args.passes, args.seed, work)
        plans.append((name, scene, mode, per_pass, work, todo))
        if len(todo) < args.passes:
            print(f"{name}: resuming, {args.passes - len(todo)} of {args.passes} passes already rendered", flush=True)
    remaining = {name: len(todo) for name, *_, todo in plans}
    command = "batch/make_references.py " + shlex.join(argv if argv is not None else sys.argv[1:])

    finished = _pass_recorder(remaining, lambda name: write_reference(next(p for p in plans if p[0] == name)))

    def write_reference(plan):
        name = plan[0]
        try:
            _write_reference(plan)
        except references.Collision as exc:  # another scene's file where this reference would go
            failed.append(name)
            print(f"{name}: {exc}; the passes are kept in {plan[4]}", flush=True)
        except OSError as exc:  # a full disk, a folder that cannot be written: the old reference is untouched
            failed.append(name)
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"{name}: cannot write the reference into {out}: {where}{exc.strerror or exc}; the old "
                  f"reference (if any) is left as it was and the passes are kept in {plan[4]}: run the same "
                  "command again once it can be written", flush=True)
        except ValueError as exc:  # a pass whose EXR or record is not what a pass writes
            failed.append(name)
            print(f"{name}: cannot merge the passes: {exc}", flush=True)

    def _write_reference(plan):
        name, scene, mode, per_pass, work, _todo = plan
        r = scene["render"]
        names, mean, stderr, seconds, versions = merge(work, args.passes,
                                                       planning.scaled_size(r["width"], r["height"], args.scale))
        layers = None
        if args.layers:
            from spectral_bench.batch.verdict import observer_layers
            names, mean, stderr, layers = observer_layers.split(names, mean, stderr)
            layer_info = {"spp": per_pass * args.passes, "passes": args.passes, "seed": args.seed, "mode": mode,
                          "film": colour_route(backend, mode)["film"], "versions": versions, "command": command,
                          "time_s": round(seconds, 2), "date": dt.datetime.now().isoformat(timespec="seconds")}
            if args.layers_only:
                ref = references.search(name, out, scene=scene).ref
                if ref is None:
                    raise ValueError("its reference is no longer current; no layers added")
                paths = observer_layers.save(out, name, layers, layer_info, ref.stderr)
                ratios = references.read_record(out / f"{name}.json")[0][observer_layers.RECORD_KEY]
                print(f"{name}: observer layers ({layer_info['spp']} spp) -> {', '.join(p.name for p in paths)}; their noise over "
                      f"the reference's as stored (median, R G B): " + "; ".join(
                          f"{o} {' '.join(f'{x:.3f}' for x in ratios[o]['noise_ratio'])}" for o in layers), flush=True)
                shutil.rmtree(work, ignore_errors=True)
                return
        prov = {"backend": backend.name, "mode": mode, "spp": per_pass * args.passes, "passes": args.passes,
                "seed": args.seed, "resolution": [int(mean.shape[1]), int(mean.shape[0])], "scale": args.scale,
                "time_s": round(seconds, 2), "date": dt.datetime.now().isoformat(timespec="seconds"),
                "versions": versions, "engine": args.cluster or "local",
                "machine": f"{platform.machine()} {platform.system()}, {os.cpu_count()} cores", "command": command}
        prov["colour"] = colour_route(backend, mode)
        if getattr(backend, "decl", None) is not None:
            prov["declaration"] = backend.decl
        if backend.options.get("executable"):
            prov["executable"] = backend.options["executable"]
        if args.art_ggx:
            prov["art_ggx"] = True
        if not replace_or_refuse(name, scene, names, mean, stderr, prov, work):
            failed.append(name)
            return
        if layers:
            observer_layers.save(out, name, layers, layer_info, stderr)
        shutil.rmtree(work, ignore_errors=True)

    def replace_or_refuse(name, scene, names, mean, stderr, prov, work):
        """Judge the new reference against the one it replaces, print both, keep the old one in
        history and save the new one, or refuse (False)."""
        import numpy as np
        new = references.Reference(names, mean, stderr, prov, None)
        bad_new = references.usable_for(new) or (None if np.isfinite(mean).all() and np.isfinite(stderr).all()
                                                 else "non-finite values in its mean or noise")
        if bad_new:
            print(f"{name}: the new reference cannot be used ({bad_new}); nothing replaced", flush=True)
            return False
        old, problem = references.examine(out, name, references.fingerprint(scene))
        exists = problem is not None or old is not None
        verdict, state = None, "none"
        if exists:
            if old is not None and problem is None:
                state, old_prov = "usable", old.provenance
                verdict = references.judge_replacement(old, new, args.alpha, args.min_samples, args.block)
            else:
                state = ("stale" if old is not None else "broken") + f": {problem['file']}: {problem['problem']}"
                old_prov = old.provenance if old is not None else references.read_record(out / f"{name}.json")[0]
            print(f"{name}: the old reference ({state.split(':')[0]}) against the new one", flush=True)
            for line in provenance_table(old_prov, prov):
                print(line, flush=True)
            if verdict is not None:
                for line in verdict_lines(verdict):
                    print(line, flush=True)
            else:
                print(f"  not judged against the old one: it is {state}", flush=True)
            if old is not None and mean.shape[0] < old.mean.shape[0]:
                (H, W), (h, w) = old.mean.shape[:2], mean.shape[:2]
                print(f"  note: the new reference is {w}x{h}, the old one {W}x{H}: renders at {W}x{H} (or any size that "
                      f"is not {w}x{h} divided by an integer) can no longer be judged against it", flush=True)
            if verdict is not None and not verdict["same"] and not args.accept:
                why = "differs from the old beyond noise" if verdict["comparable"] else "cannot be judged against the old one"
                print(f"{name}: NOT replaced: the new reference {why}; the old one is left as it is (exit status 1). "
                      f"If the change is intended, run the same command with --accept: the new passes are kept in "
                      f"{work}, so it replaces the reference without rendering again.", flush=True)
                return False
        now = dt.datetime.now(dt.timezone.utc)
        record = {"scene": name, "replaced_at": now.isoformat(timespec="seconds"), "by": _who(), "command": command,
                  "why": {"old": state, "verdict": verdict,
                          "accepted_despite_verdict": bool(verdict is not None and not verdict["same"])},
                  "old": {k: (old_prov or {}).get(k) for k in (*SHOWN, "exr_sha256")} if exists else None,
                  "new": {k: prov.get(k) for k in SHOWN}}
        path, kept = references.replace(scene, names, mean, stderr, prov, out, record, now.strftime("%Y%m%dT%H%M%SZ"))
        print(f"{name}: {prov['spp']} spp in {prov['time_s']:.1f} s -> {path} "
              f"(mean stderr / mean = {float(stderr.mean() / max(mean.mean(), 1e-12)):.2e})", flush=True)
        if kept is not None:
            print(f"{name}: replaced" + (" (--accept: despite the verdict)" if record["why"]["accepted_despite_verdict"] else "")
                  + f"; the old reference is kept in {kept}", flush=True)
        return True

    for plan in plans:
        if not plan[5]:
            write_reference(plan)  # every pass was already there
    status = run_passes(args.cluster, [j for p in plans for j in p[5]], finished, "references/.work")
    if status is not None:
        return status
    return 1 if failed or any(remaining.values()) else 0


def run_passes(cluster, jobs, finished, kept_in):
    """Render ``jobs`` on the engine ``--cluster`` names (here by default), ``finished`` called
    for each; None when they ran, else the exit status: 2 when the cluster cannot be reached, 130
    when interrupted (the finished passes stay in ``kept_in`` for the same command to resume)."""
    from spectral_bench.batch.jobs import engines
    try:
        engine = engines.make(cluster)
    except engines.ClusterError as exc:
        print(f"batch/make_references.py: error: --cluster {cluster}: {exc}", file=sys.stderr, flush=True)
        return 2
    try:
        engine.map(jobs, finished)
    except engines.Interrupted:
        print(f"interrupted: the finished passes are kept in {kept_in}; run the same command to resume", flush=True)
        return 130
    finally:
        engine.close()
    return None


# -- cross-checks (issue 44): the references judged against another renderer --------------------
CROSSCHECK_PASSES = 2  # a run's default: the cross-check renders at the settings a run judges at
NOT_WITH_CROSSCHECK = (("-r", "renderer"), ("--replace", "replace"), ("--accept", "accept"), ("--layers", "layers"),
                       ("--layers-only", "layers_only"), ("--migrate-layers", "migrate_layers"), ("--out", "out"),
                       ("--scale", "scale"))


def crosscheck_usage(args):
    """--crosscheck's options checked before anything is read or rendered (Usage naming the option)."""
    for option, key in NOT_WITH_CROSSCHECK:
        if getattr(args, key):
            why = ("renders at the reference's own resolution" if key == "scale" else
                   "reads the references from --references DIR and writes only their records" if key == "out" else
                   "names the renderer" if key == "renderer" else "changes no reference image")
            raise Usage(f"{option}: not with --crosscheck {args.crosscheck}, which {why}")
    args.renderer = args.crosscheck
    if args.references is not None:
        from spectral_bench.batch.verdict import references
        folder = Path(args.references)
        if not folder.is_dir():
            raise Usage(f"--references {args.references}: " + ("not a folder" if folder.exists() else "no such folder"))
        if references.is_history(folder):
            raise Usage(f"--references {args.references}: a history folder of a replaced reference "
                        f"({references.HISTORY_RECORD}), never current references")
    if args.known is not None:
        from spectral_bench.batch.verdict import known
        if not Path(args.known).is_file():
            raise Usage(f"--known {args.known}: " + ("not a file" if Path(args.known).exists() else "no such file"))
        try:
            known.load(args.known)
        except (known.KnownDeviationsError, OSError, UnicodeDecodeError) as exc:
            raise Usage(f"--known {args.known}: {exc}") from exc
    args.passes = args.passes or CROSSCHECK_PASSES


def crosscheck(args, argv, backend):
    """--crosscheck NAME: each chosen scene's reference (in --references DIR) judged against a render
    by NAME (batch/verdict/crosscheck.py), the outcome printed and, unless --no-record, recorded in
    the reference's provenance. Exit status 0 when every scene agrees at the stated power, 1 naming
    each that does not (or could not be cross-checked), 2 for usage (nothing rendered)."""
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.jobs import plan as planning
    from spectral_bench.batch.verdict import crosscheck as cc, observer_layers, references
    from spectral_bench.batch.backends import rgb_common
    from spectral_bench.exporters import names as scene_names, rgb_scene
    from spectral_bench.batch.verdict import known as known_mod
    folder = Path(args.references) if args.references else references.REFERENCE_DIR
    detect = args.detect if args.detect is not None else cc.DEFAULT_DETECT
    name = backend.name
    deviations = known_mod.load(args.known)  # checked by crosscheck_usage
    loaded = list(scene_sources.load(args.input))
    known = [n for n, _ in loaded]
    missing = [s for s in args.scene or [] if s not in known]
    if missing:
        print(f"batch/make_references.py: error: -s {missing[0]}: no such scene in {', '.join(args.input)}",
              file=sys.stderr, flush=True)
        return 2
    chosen = [(n, sc) for n, sc in loaded if not args.scene or n in args.scene]
    failed, agreed, plans = [], [], []

    def fail(scene_name, why):
        failed.append(scene_name)
        print(f"{scene_name}: NOT cross-checked: {why}", flush=True)

    for scene_name, scene in chosen:
        if isinstance(scene, Exception):
            fail(scene_name, str(scene))
            continue
        stem = scene_names.file_stem(scene_name)  # a name that is no plain scene name reaches no path
        ref, bad = references.examine(folder, stem, references.fingerprint(scene))
        if ref is None or bad:
            fail(scene_name, f"no usable reference in {folder}: " + (f"{bad['file']}: {bad['problem']}" if bad else "none"))
            continue
        if ref.provenance.get("backend") == name:
            print(f"batch/make_references.py: error: --crosscheck {name}: scene {scene_name}'s reference "
                  f"{ref.path} was made by {name}: a cross-check needs another, independent renderer", file=sys.stderr, flush=True)
            return 2
        observer = observer_layers.own_observer(ref.provenance)
        if observer not in ("cie1931", None) and name != "mitsuba":
            fail(scene_name, f"its reference's colour is {observer}'s film, not the scene format's (CIE 1931 at 1 nm) "
                             f"that {name} is read with: they would differ by the observer; re-make it with --film cmf")
            continue
        scale = ref.provenance.get("scale") if isinstance(ref.provenance.get("scale"), (int, float)) else 1.0
        try:
            rendered = planning.for_run(scene, {"scale": scale}, judged=False)
        except Exception as exc:  # noqa: BLE001 - a scale that leaves the IR's bounds fails this scene
            fail(scene_name, str(exc))
            continue
        r = rendered["render"]
        if (r["height"], r["width"]) != ref.mean.shape[:2]:
            fail(scene_name, f"its reference {ref.path} is {ref.mean.shape[1]}x{ref.mean.shape[0]}, the scene at its "
                             f"recorded scale {scale:g} renders {r['width']}x{r['height']}")
            continue
        mode, why = backend.mode_for(rendered)
        if mode is None:
            if args.scene:
                fail(scene_name, f"{name} cannot render it: {why}")
            else:
                print(f"{scene_name}: skipped: {name} cannot render it: {why}", flush=True)
            continue
        inexact = rgb_scene.wavelength_dependent(scene) if isinstance(backend, rgb_common.RgbBackend) else []
        if inexact:  # an RGB render differs from the spectral truth there by design, not by error
            why = (f"{name} renders in RGB, exact only where every BSDF is wavelength-independent "
                   "(docs/backends.md, RGB renderers as cross-checks): "
                   + "; ".join(f"{o}.{f}: {m}" for o, f, m in inexact[:3])
                   + (f"; and {len(inexact) - 3} more" if len(inexact) > 3 else ""))
            if args.scene:
                fail(scene_name, why)
            else:
                print(f"{scene_name}: skipped: {why}", flush=True)
            continue
        spp = args.spp or scene["render"]["spp"] * (args.factor or 1)
        work = folder / ".work" / ".crosscheck" / scene_names.file_stem(name) / stem
        todo, per_pass = pass_jobs(scene_name, rendered, backend, mode, spp, args.passes, args.seed, work)
        plans.append(dict(name=scene_name, scene=rendered, ref=ref, mode=mode, per_pass=per_pass, work=work, todo=todo,
                          sha=references.sha256_of(ref.path)))
        if len(todo) < args.passes:
            print(f"{scene_name}: resuming, {args.passes - len(todo)} of {args.passes} passes already rendered", flush=True)
    remaining = {p["name"]: len(p["todo"]) for p in plans}
    command = "batch/make_references.py " + shlex.join(argv if argv is not None else sys.argv[1:])

    finished = _pass_recorder(remaining, lambda name: judge(next(p for p in plans if p["name"] == name)))

    def judge(plan):
        scene_name, ref = plan["name"], plan["ref"]
        try:
            names_, mean, stderr, _seconds, versions = merge(plan["work"], args.passes, tuple(ref.mean.shape[1::-1]))
        except (OSError, ValueError) as exc:
            fail(scene_name, f"cannot merge {name}'s passes: {exc}")
            return
        first = read_done(plan["work"] / "pass0" / "done.json") or {}
        spp = plan["per_pass"] * args.passes
        check = references.Reference(names_, mean, stderr, {"spp": spp, "passes": args.passes, "backend": name}, None)
        film = getattr(backend, "film", None) if name == "mitsuba" else ""
        result = cc.judge(ref, check, plan["scene"], name, plan["mode"], alpha=args.alpha, min_samples=args.min_samples,
                          block=args.block, deviations=deviations, versions=versions, film=film)
        item = cc.entry(result, renderer=name, mode=plan["mode"], versions=versions, spp=spp, passes=args.passes,
                        seed=args.seed, resolution=[int(mean.shape[1]), int(mean.shape[0])], reference_sha256=plan["sha"],
                        fingerprint=ref.provenance.get("fingerprint"), approximated=first.get("approximated"),
                        command=command)
        who = cc.renderer_label(name, item["version"])
        det = result.get("detectable")
        power = (f"detects {cc.percent(det)} with 90 % power" if det is not None else "detects no uniform error up to 100 %")
        ratio = ", ".join(f"{c} {v[0]:.5f} +- {v[1]:.5f}" for c, v in (result.get("ratio") or {}).items() if v)
        under = result.get("agrees_under")
        if under:
            power += " under its model"
        if result.get("agrees"):
            weak = det is None or det > detect
            print(f"{scene_name}: agrees with {who}" + (f" up to the known deviation {under} (scale "
                  f"{result['deviation']['scale']:g} +- {result['deviation']['scale_se']:g})" if under else "")
                  + f" ({spp} spp in {args.passes} passes; {power}, stated "
                  f"{cc.percent(detect)}); {name} / reference: {ratio}", flush=True)
            if under:
                for line in cc.difference_lines(result):
                    print(f"  plainly: {line}", flush=True)
            if weak:
                fail(scene_name, f"the cross-check {power}, more than the stated {cc.percent(detect)} (--detect): it "
                                 "decides nothing at that power and is not recorded; render more samples (--spp, --factor)")
                shutil.rmtree(plan["work"], ignore_errors=True)
                return
            agreed.append(scene_name)
        else:
            failed.append(scene_name)
            print(f"{scene_name}: DIFFERS from {who} beyond noise ({spp} spp in {args.passes} passes; {power})"
                  + (f"; {name} / reference: {ratio}" if ratio else ""), flush=True)
            for line in cc.difference_lines(result):
                print(f"  {line}", flush=True)
        if not args.no_record:
            try:
                path = cc.record(folder, plan["ref"].path.stem, item)
                print(f"{scene_name}: recorded in {path} ({cc.RECORD_KEY})", flush=True)
            except (OSError, ValueError) as exc:
                if scene_name not in failed:
                    failed.append(scene_name)
                print(f"{scene_name}: NOT recorded: {exc}", flush=True)
        if scene_name in failed:  # a disagreement is a finding: its passes stay, the same command re-judges them
            print(f"{scene_name}: {name}'s passes kept in {plan['work']} (the same command judges them again "
                  "without rendering; remove the folder to render anew)", flush=True)
            return
        shutil.rmtree(plan["work"], ignore_errors=True)

    from spectral_bench.batch.jobs import job as jobs
    for plan in plans:
        if not plan["todo"]:
            judge(plan)  # every pass was already there
    status = run_passes(args.cluster, [j for p in plans for j in p["todo"]], finished, folder / ".work" / ".crosscheck")
    if status is not None:
        return status
    for scene_name, left in remaining.items():
        if left and scene_name not in failed:
            fail(scene_name, f"{left} of {args.passes} passes of {name} did not render")
    print(f"cross-check by {name}: {len(agreed)} agree" + (f"; {len(failed)} do not: {', '.join(failed)}" if failed else ""),
          flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
