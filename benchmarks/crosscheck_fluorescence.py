"""Mitsuba (sb_fluorescent_path) against ART 2.1.2 (CONST_FLUORESCENT_COLOUR) on the fluorescence
case, each judged on its own noise.

    .venv/bin/python benchmarks/crosscheck_fluorescence.py [--size 128] [--spp 256] [--passes 4] [--write]

Both backends render every scene of the case at --size x --size pixels and one sample count in
``--passes`` independent passes, so each image carries its own per-pixel standard error. Regions
of whole pixels (batch/verdict/raycast.py): the sphere, the floor's inner 70 % and the
environment seen directly. Per region and channel the two means are compared with a two-sample
z-test, each side's variance of the region mean being the sum of its pixels' squared standard
errors over n^2 (pixels are independent); a Sidak correction over the scene's tests (alpha 0.01).
"agree" means no evidence of a difference at that level, not proof of equality: the standard
errors are printed beside each difference. The lone sphere is also judged by its analytic probe,
per backend. Prints Markdown; --write replaces the measured section of benchmarks/FLUORESCENCE.md.

``--art-output spectral`` (default) has ART write its spectral EXR (46 bands, 320-780 nm), which is
turned into linear sRGB here with the CIE 1931 CMFs, as the ART backend does for Stokes scenes:
ART's own conversion to an sRGB EXR (``--art-output srgb``, what the backend renders otherwise)
maps colours outside the sRGB gamut far from their values (measured: the 450 nm light seen
directly, blue 1.00 instead of 5.27), which would hide how ART transports light behind how it
writes it.

``--lone`` renders each scene's sphere alone under the scene's light (floor removed), where the
analytic probe rho L + integral P L is exact: where the two renderers disagree on a scene, it says
which one leaves the ground truth (the probe's film allowance holds for broadband light only;
under the 450 nm light the deviation in % is what to read).
"""
import argparse
import datetime as dt
import json
import math
import os
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

ALPHA = 0.01
SPECTRAL_ROUTE = ("[ IMAGECONVERSION_ARTRAW_TO_ARTCSP removeSource: NO ],",
                  "[ IMAGECONVERSION_ARTRAW_TO_SPECTRAL_EXR removeSource: NO ],")


def markers(route, lone=False):
    flags = f"--art-output {route}" + (" --lone" if lone else "")
    key = route + (" lone" if lone else "")
    return (f"<!-- crosscheck {key}: begin (benchmarks/crosscheck_fluorescence.py {flags} --write) -->",
            f"<!-- crosscheck {key}: end -->")


def alone(scene):
    """The scene's sphere alone under the scene's light."""
    import copy
    sc = copy.deepcopy(scene)
    sc["objects"] = [o for o in sc["objects"] if o["shape"]["type"] == "sphere"]
    sc["name"] += "__alone"
    return sc


def regions(scene, w, h):
    from spectral_bench.batch.verdict import raycast
    objs, cam = scene["objects"], scene["camera"]
    out = {}
    for i, o in enumerate(objs):
        kind = "sphere" if o["shape"]["type"] == "sphere" else "floor"
        out[kind] = raycast.pixels_inside(cam, w, h, objs, i, margin=0.7)
    origin, dirs = raycast.camera_rays(cam, w, h, "corners")
    who, _ = raycast.nearest(objs, origin, dirs)
    miss = who == -1
    out["environment"] = miss[:-1, :-1] & miss[1:, :-1] & miss[:-1, 1:] & miss[1:, 1:]
    return out


def region_stats(img, se, mask):
    n = int(mask.sum())
    mean = img[mask][:, :3].mean(axis=0)
    sem = np.sqrt((se[mask][:, :3] ** 2).sum(axis=0)) / max(n, 1)
    return mean, sem, n


def render(backend, scene, folder, spp, passes, seed, art_output="spectral"):
    mode, why = backend.mode_for(scene)
    if mode is None:
        return None, why
    path = backend.export(scene, folder / backend.name)
    if backend.name == "art" and art_output == "spectral" and "IMAGECONVERSION_ARTRAW_TO_SPECTRAL_EXR" not in path.read_text():
        # the writer's spectral EXR route is its default now; an older .arm (ARTCSP) is switched to it
        text = path.read_text()
        assert SPECTRAL_ROUTE[0] in text, "the ART writer's actions changed"
        lines = [l for l in text.replace(*SPECTRAL_ROUTE).splitlines() if "IMAGECONVERSION_ARTCSP_TO_EXR" not in l]
        path.write_text("\n".join(lines) + "\n")
    info = backend.render(path, mode, spp, folder / f"{backend.name}.exr", passes=passes, seed=seed,
                          timeout=6 * 3600, log_path=folder / f"{backend.name}.log")
    from spectral_bench.batch import exr
    names, img, se = exr.read_image_and_stderr(folder / f"{backend.name}.exr")
    return (names, img, se, mode, info), None


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, scene_sources
    from spectral_bench.batch.jobs import plan
    from spectral_bench.batch.verdict import probes, stats

    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-s", "--scene", action="append")
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--art-output", choices=("spectral", "srgb"), default="spectral")
    ap.add_argument("--lone", action="store_true", help="each scene's sphere alone: both against the probe")
    ap.add_argument("--json", help="also write the numbers to this file")
    args = ap.parse_args()

    scenes = [(n, s) for n, s in scene_sources.load([str(scene_sources.DEFAULT_BLEND)])
              if isinstance(s, dict) and s.get("case") == "fluorescence" and (not args.scene or n in args.scene)]
    if args.lone:
        scenes = [(n, alone(s)) for n, s in scenes if n != "fluorescent_sphere_lone"]
    mitsuba, art = backends.get("mitsuba"), backends.get("art")
    ok, why = art.availability()
    if not ok:
        raise SystemExit(f"ART is not available: {why}")
    rows, record = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, scene in scenes:
            sc = plan.for_run(scene, {"spp": args.spp, "scale": None})
            r = sc["render"]
            r["width"] = r["height"] = args.size  # every scene is square
            results = {}
            for b in (mitsuba, art):
                res, why = render(b, sc, Path(tmp) / name, args.spp, args.passes, args.seed, args.art_output)
                if res is None:
                    raise SystemExit(f"{name} / {b.name}: {why}")
                results[b.name] = res
                print(f"{name} / {b.name} {res[3]}: {res[4]['time_s']:.1f} s", flush=True)
            masks = {k: m for k, m in regions(sc, r["width"], r["height"]).items() if m.sum() >= 4}
            tests = 3 * len(masks)
            threshold = stats.sidak_threshold(ALPHA, tests)
            record[name] = {"resolution": [r["width"], r["height"]], "spp": args.spp, "passes": args.passes,
                            "modes": {k: v[3] for k, v in results.items()}, "regions": {}}
            for region, mask in masks.items():
                (m_mean, m_se, n), (a_mean, a_se, _) = (region_stats(results[k][1], results[k][2], mask)
                                                        for k in ("mitsuba", "art"))
                z = (a_mean - m_mean) / np.sqrt(m_se ** 2 + a_se ** 2)
                p = [math.erfc(abs(v) / math.sqrt(2)) for v in z]
                agree = [pv >= threshold for pv in p]
                record[name]["regions"][region] = {"pixels": n, "mitsuba": m_mean.tolist(), "mitsuba_se": m_se.tolist(),
                                                   "art": a_mean.tolist(), "art_se": a_se.tolist(), "z": z.tolist(),
                                                   "agree": agree}
                cells = " | ".join(f"{m:.4g} / {a:.4g} ({'+' if a >= m else ''}{(a - m) / abs(m) * 100 if m else float('nan'):.1f} %, z {zz:+.1f})"
                                   for m, a, zz in zip(m_mean, a_mean, z))
                rows.append(f"| {name} | {region} ({n} px) | {cells} | {'yes' if all(agree) else 'NO'} |")
            for backend_name, (names, img, se, mode, _) in results.items():
                for rec in probes.evaluate(sc, names, img, stderr=se):
                    if rec["name"].startswith("lone "):
                        record[name].setdefault("probe", {})[backend_name] = rec
                        e, m = (np.asarray(rec[k]) for k in ("expected", "measured"))
                        se = np.asarray(rec["stat"]["se"])  # the region mean's standard error per channel
                        cells = " | ".join(f"{mv:.4g} vs {ev:.4g} ({(mv - ev) / abs(ev) * 100:+.1f} %, "
                                           f"z {(mv - ev) / sv:+.1f})" for ev, mv, sv in zip(e, m, se))
                        rows.append(f"| {name}{' (sphere alone)' if args.lone else ''} | probe rho L + integral P L, "
                                    f"{backend_name}: measured vs expected | {cells} | "
                                    f"{'pass' if rec['pass'] else 'FAIL'} ({rec['error']:.1f} sigma beyond the film "
                                    f"allowance) |")
    begin, end = markers(args.art_output, args.lone)
    route = ("its spectral EXR converted here with the CIE 1931 CMFs" if args.art_output == "spectral"
             else "its own sRGB EXR (the ART backend's route)")
    text = "\n".join([
        begin,
        f"Measured {dt.date.today().isoformat()} by `benchmarks/crosscheck_fluorescence.py --size {args.size} "
        f"--spp {args.spp} --passes {args.passes}` ({platform.system()}, {os.cpu_count()} cores): Mitsuba "
        f"{next(iter(record.values()))['modes']['mitsuba'] if record else ''} with sb_fluorescent_path, ART "
        f"{next(iter(record.values()))['modes']['art'] if record else ''} (`-s46e -wp d65`, {route}). Each cell: Mitsuba / ART "
        f"(ART's difference, z on both renders' own noise); agree: every channel's p >= the Sidak threshold for "
        f"alpha {ALPHA} over the scene's tests.",
        "",
        "| scene | region | R | G | B | agree |",
        "|---|---|---|---|---|---|",
        *rows,
        end,
    ])
    print(text)
    if args.json:
        Path(args.json).write_text(json.dumps(record, indent=1))
    if args.write:
        doc = Path(__file__).resolve().parent / "FLUORESCENCE.md"
        old = doc.read_text()
        if begin not in old or end not in old:
            raise SystemExit(f"{doc} has no measured section between {begin} and {end}")
        doc.write_text(old[:old.index(begin)] + text + old[old.index(end) + len(end):])


if __name__ == "__main__":
    main()
