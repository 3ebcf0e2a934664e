"""Calibrate the prism probes (batch/verdict/probes/prism.py) on dispersion_prism.

    .venv/bin/python benchmarks/calibrate_prism_probe.py [--seeds 8] [--write]
    .venv/bin/python benchmarks/calibrate_prism_probe.py --smoke   # seconds: every step at 4 spp, 1 seed; not recorded

Measures (1) the ground truth's own error (1 nm wavelength grid against 0.25 nm), (2) false
alarms on unbiased renders at the scene's default settings (its spp, 2 passes, distinct seeds),
(3) power: fused silica where N-BK7 is declared, N-BK7 with n^2 - 1 scaled so that n_d is 1e-4
higher, a 1 % brighter beam, and (4) what the renderer does at 16x the samples (evidence for the
known deviations: its film's CIE normalisation and the ray-spawn offset at refractions, measured
again with the whole scene moved 30 units away from the origin), (5) Mitsuba's film against
colorimetry.py on a uniform D65 environment. --write records the tables in benchmarks/CALIBRATION.md.
"""
import argparse
import copy
import datetime as dt
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import pkg_bootstrap  # noqa: E402

SMOKE_SPP = 4  # --smoke


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, exr, scene_sources
    from spectral_bench.batch.verdict import probes
    from spectral_bench.batch.verdict.probes import prism
    from spectral_bench.exporters import dispersion, ir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--smoke", action="store_true", help="checks that the script runs: one seed, every render at "
                    f"{SMOKE_SPP} spp in 2 passes (the figures mean nothing); never recorded")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    if args.smoke and args.write:
        ap.error("--smoke checks that the script runs; its figures are never recorded: leave out --write")
    if args.smoke:
        args.seeds = 1
    base = dict(scene_sources.load([str(scene_sources.DEFAULT_BLEND)]))["dispersion_prism"]
    r = base["render"]
    spp = SMOKE_SPP if args.smoke else r["spp"]  # (2), (3): the scene's own
    high_spp, high_passes = (SMOKE_SPP, 2) if args.smoke else (16 * r["spp"], 8)  # (4)
    sky_spp, sky_passes = (SMOKE_SPP, 2) if args.smoke else (4096, 8)  # (5)
    backend = backends.get("mitsuba")
    lines = [f"## Dispersion: prism probes, {dt.date.today().isoformat()} (dispersion_prism, "
             f"{r['width']}x{r['height']}, {spp} spp, 2 passes, alpha 0.01 Sidak over 3 channels)", ""]

    # (1) the ground truth's own error
    fine_nm = 0.5 if args.smoke else 0.25  # --smoke: the finer grid's cost grows with its wavelengths
    fine = prism.expected(base, r["width"], r["height"], step_nm=fine_nm)
    coarse = prism.expected(base, r["width"], r["height"])
    mask = coarse["mask"]
    s = (np.stack(np.nonzero(mask)[::-1], axis=-1) + 0.5 - coarse["centres"][190]) @ coarse["fan_direction"]
    cent = lambda img: [float(np.sum(s * img[mask][:, c]) / np.sum(img[mask][:, c])) for c in range(3)]
    d_pos = np.abs(np.array(cent(fine["image"])) - np.array(cent(coarse["image"])))
    d_flux = np.abs(fine["flux"] / coarse["flux"] - 1)
    lines += [f"Ground truth's own error (1 nm grid against {fine_nm} nm): centroids "
              f"{d_pos.max():.1e} px, flux {d_flux.max():.1e} (relative); beam width "
              f"{coarse['beam_width_px']:.2f} px, fan (420-680 nm) {coarse['fan_spread_px']:.1f} px.", ""]

    def run(scene, spp, passes, seed, tmp):
        sc = copy.deepcopy(scene)
        sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
        xml = backend.export(sc, Path(tmp) / "m")
        backend.render(xml, backend.mode_for(sc)[0], spp, Path(tmp) / "r.exr", passes=passes, seed=seed)
        names, img, se = exr.read_image_and_stderr(Path(tmp) / "r.exr")
        return {p["name"].split(",")[0]: p for p in probes.evaluate(base, names, img, stderr=se)}

    # (2) false alarms
    lines += ["False alarms on unbiased renders:", "", "| seed | positions z | positions | energy z | energy |",
              "|---|---|---|---|---|"]
    fails = 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            p = run(base, spp, 2, 100 * seed, tmp)
            pos, en = p["prism band positions"], p["prism energy"]
            fails += (not pos["pass"]) + (not en["pass"])
            lines.append(f"| {100 * seed} | {pos['error']:.2f} | {'pass' if pos['pass'] else 'FAIL'} | "
                         f"{en['error']:.2f} | {'pass' if en['pass'] else 'FAIL'} |")
    lines += ["", f"{fails} of {2 * args.seeds} probe verdicts failed.", ""]

    # (3) power
    def prism_obj(sc):
        return next(o for o in sc["objects"] if (o.get("bsdf") or {}).get("type") == "dielectric")

    def silica(sc):
        prism_obj(sc)["bsdf"]["int_ior"] = {"type": "named", "name": "fused_silica"}

    def bk7_plus(sc):
        b, c = dispersion.sellmeier({"type": "named", "name": "N-BK7"})
        n_d = dispersion.abbe_number({"type": "named", "name": "N-BK7"})[0]
        k = ((n_d + 1e-4) ** 2 - 1) / (n_d ** 2 - 1)
        prism_obj(sc)["bsdf"]["int_ior"] = {"type": "sellmeier", "B": [k * x for x in b], "C": c}

    def brighter(sc):
        next(o for o in sc["objects"] if o.get("emitter"))["emitter"]["irradiance"]["scale"] *= 1.01

    lines += ["Power (one render each, the probes judging the declared scene):", "",
              "| rendered instead | positions z | positions | energy z | energy |", "|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for label, change in (("fused silica", silica), ("N-BK7 with n_d + 1e-4", bk7_plus), ("beam +1 %", brighter)):
            sc = copy.deepcopy(base)
            change(sc)
            p = run(sc, spp, 2, 7, tmp)
            pos, en = p["prism band positions"], p["prism energy"]
            lines.append(f"| {label} | {pos['error']:.1f} | {'fail (detected)' if not pos['pass'] else 'pass (missed)'} "
                         f"| {en['error']:.1f} | {'fail (detected)' if not en['pass'] else 'pass (missed)'} |")

    # (4) the renderer at 16x the samples, at the origin and moved 30 units along x
    lines += ["", f"Mitsuba at {high_spp} spp, {high_passes} passes (the known deviations):", "",
              "| scene placement | centroid shift R, G, B (px) | standard error (px) | flux relative error R, G, B | standard error |",
              "|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for shift in (0.0, 30.0):
            sc = copy.deepcopy(base)
            for m in [sc["camera"]["to_world"]] + [o["shape"]["to_world"] for o in sc["objects"]]:
                m[0][3] += shift
            sc_json = copy.deepcopy(sc)
            sc_json["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
            xml = backend.export(sc_json, Path(tmp) / f"m{shift:g}")
            backend.render(xml, backend.mode_for(sc_json)[0], high_spp, Path(tmp) / "r.exr", passes=high_passes, seed=500)
            names, img, se = exr.read_image_and_stderr(Path(tmp) / "r.exr")
            p = {q["name"].split(",")[0]: q for q in probes.evaluate(sc_json, names, img, stderr=se)}
            pos, en = p["prism band positions"], p["prism energy"]
            shift_px = np.array(pos["measured"]) - np.array(pos["expected"])
            rel_se = np.array(en["standard_error"]) / np.array(en["expected"])
            lines.append(f"| moved {shift:g} | {', '.join(f'{x:+.4f}' for x in shift_px)} | "
                         f"{', '.join(f'{x:.4f}' for x in pos['standard_error_px'])} | "
                         f"{', '.join(f'{x:+.5f}' for x in en['relative_error'])} | "
                         f"{', '.join(f'{x:.5f}' for x in rel_se)} |")
    # (5) Mitsuba's film against colorimetry.py: a camera path tracer seeing only a uniform D65 sky
    from spectral_bench.exporters import colorimetry
    d65 = {"type": "named", "name": "cie_d65", "scale": 1.0}
    sky = {"format": ir.FORMAT, "version": ir.VERSION, "name": "d65_sky", "case": "custom", "needs": ["spectral"],
           "render": {"spp": sky_spp, "width": 16, "height": 16, "max_depth": 2, "filter": "box", "integrator": "path"},
           "camera": copy.deepcopy(base["camera"]), "environment": {"type": "uniform", "radiance": d65}, "objects": []}
    with tempfile.TemporaryDirectory() as tmp:
        xml = backend.export(sky, Path(tmp) / "m")
        backend.render(xml, backend.mode_for(sky)[0], sky_spp, Path(tmp) / "r.exr", passes=sky_passes, seed=900)
        _, img, se = exr.read_image_and_stderr(Path(tmp) / "r.exr")
    expected = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(d65))
    n = img.shape[0] * img.shape[1]
    ratio = img[..., :3].mean(axis=(0, 1)) / expected
    rel_se = np.sqrt((se[..., :3] ** 2).sum(axis=(0, 1))) / n / expected
    lines += ["", "Mitsuba's spectral film against colorimetry.py (camera path tracer, uniform D65 environment only, "
              f"16x16, {sky_spp} spp x {sky_passes}): rendered / expected R, G, B = "
              + ", ".join(f"{x:.5f}" for x in ratio) + " (standard errors " + ", ".join(f"{x:.1e}" for x in rel_se) + ")."]
    text = "\n".join(lines + [""])
    print(text)
    if args.write:
        path = Path(__file__).resolve().parent / "CALIBRATION.md"
        path.write_text(path.read_text().rstrip("\n") + "\n\n" + text)


if __name__ == "__main__":
    main()
