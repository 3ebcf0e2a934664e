"""Mitsuba's spectral image (specfilm, box bands, batch/backends/mitsuba/spectral.py) integrated to
RGB (batch/spectral_exr.py) against Mitsuba's own RGB render (hdrfilm) of the same scene, judged on
both renders' noise; and the band discretisation error expected from the scene's spectra.

    .venv/bin/python scripts/spectral_exr_check.py [--scene ggx_copper_50] [--size 64] [--spp 256]
        [--passes 4] [--band-nm 10]

Prints a markdown report (benchmarks/SPECTRAL_EXR.md records one). tests/backends/test_spectral_exr.py runs
agreement() at a small size.
"""
import argparse
import copy
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
from spectral_bench.batch import backends, exr, spectral_exr  # noqa: E402
from spectral_bench.batch.backends.mitsuba import spectral as mitsuba_spectral  # noqa: E402
from spectral_bench.batch.verdict import compare  # noqa: E402
from spectral_bench.exporters import colorimetry, ir, ir_json, spectra  # noqa: E402


def agreement(scene, workdir, size=64, spp=256, passes=4, band_nm=mitsuba_spectral.BAND_NM, observer="mitsuba3",
              scale=1.0):
    """Render ``scene`` (an IR dict) at size x size with Mitsuba's RGB film and, independently, its
    spectral film (``passes`` passes of ``spp`` each, distinct seeds); integrate each spectral pass
    with ``observer`` (times ``scale``: a deliberately wrong brightness for the test's broken case)
    and run the project's block noise test (batch/verdict/compare.py) of the spectral mean against
    the RGB mean, both with their own per-pixel noise. Returns (ZTest, spectral mean, its standard
    error, RGB mean, RGB standard error)."""
    workdir = Path(workdir)
    sc = copy.deepcopy(scene)
    sc["render"]["width"] = sc["render"]["height"] = size
    sc["render"]["spp"] = spp
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    b = backends.get("mitsuba")
    xml = b.export(sc, workdir / "mitsuba")
    variant = b.mode_for(sc)[0]
    b.render(xml, variant, spp * passes, workdir / "rgb.exr", passes=passes, seed=1000)
    names, rgb, rgb_se = exr.read_image_and_stderr(workdir / "rgb.exr")
    images = []
    for k in range(passes):
        mitsuba_spectral.render(xml, workdir / f"spectral_{k}.exr", spp, seed=k, variant=variant, band_nm=band_nm)
        images.append(spectral_exr.read_render(workdir / f"spectral_{k}.exr", "spectral", observer)[1] * scale)
    stack = np.stack(images)
    mean, se = stack.mean(axis=0), stack.std(axis=0, ddof=1) / math.sqrt(passes)
    ref = compare.reference_at(rgb[..., :3], rgb_se[..., :3], spp * passes, mean.shape, passes)
    zt = compare.z_test(mean, ref, spp * passes, own_var_of_mean=se**2, own_passes=passes)
    return zt, mean, se, rgb[..., :3], rgb_se[..., :3]


def band_error(spectrum_nm, values, band_nm=mitsuba_spectral.BAND_NM, observer="mitsuba3"):
    """Relative RGB error of box bands read as samples at their centres (spectral_exr.to_rgb)
    against the continuous integral, for one spectrum (piecewise linear through the given points,
    as Mitsuba's irregular spectra are), on a 0.01 nm grid."""
    fine = np.linspace(360.0, 830.0, 47001)
    lvals = np.interp(fine, spectrum_nm, values)
    wl, xb, yb, zb, norm = spectral_exr.OBSERVERS[observer]()
    cmfs = np.stack([np.interp(fine, wl, c) for c in (xb, yb, zb)])
    truth = colorimetry.xyz_to_srgb(np.trapz(lvals * cmfs, fine, axis=-1) / norm)
    band_list = mitsuba_spectral.bands(band_nm)
    inside = [(fine >= lo - 1e-6) & (fine <= hi + 1e-6) for lo, hi in band_list]
    avg = np.array([np.trapz(lvals[m], fine[m]) / (hi - lo) for m, (lo, hi) in zip(inside, band_list)])
    centres = tuple((lo + hi) / 2 for lo, hi in band_list)
    est = avg @ spectral_exr.rgb_weights(centres, observer)
    return est / truth - 1.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="ggx_copper_50")
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--band-nm", type=float, default=mitsuba_spectral.BAND_NM)
    ap.add_argument("--work", default="/tmp/spectral_exr_check")
    args = ap.parse_args(argv)
    scene = ir_json.load(ROOT / "golden" / "ir" / f"{args.scene}.json")

    print(f"## Band discretisation ({args.band_nm:g} nm boxes, read at their centres), expected\n")
    light = np.loadtxt(ROOT / "golden" / "mitsuba" / args.scene / "spectra" / "light_radiance.spd")
    eta, k = (spectra.evaluate(s, light[:, 0]) for s in spectra.named_conductor("Cu"))
    fresnel = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)  # copper at normal incidence
    print("| spectrum | observer | R | G | B |\n|---|---|---|---|---|")
    for label, values in (("light (D65 table, 5 nm)", light[:, 1]), ("light x copper R(0)", light[:, 1] * fresnel),
                          ("flat 1", np.ones(len(light)))):
        for obs in ("mitsuba3", "cie1931"):
            e = band_error(light[:, 0], values, args.band_nm, obs)
            print(f"| {label} | {obs} | {e[0]:+.2e} | {e[1]:+.2e} | {e[2]:+.2e} |")

    zt, mean, se, rgb, rgb_se = agreement(scene, args.work, args.size, args.spp, args.passes, args.band_nm)
    print(f"\n## {args.scene} at {args.size}x{args.size}, {args.passes} passes x {args.spp} spp each way\n")
    d = zt.as_dict()
    print(f"block noise test: {'pass' if zt.passed else 'FAIL'}; block {d['block']}, {d['tests']} tests, "
          f"min p {d['p_min']:.3g} (threshold {d['threshold']:.3g}), max |z| {d['z_max']:.2f}")
    ratio = mean.mean(axis=(0, 1)) / rgb.mean(axis=(0, 1))
    # standard error of the image-mean ratio: pixels are independent
    var = (se**2).sum(axis=(0, 1)) / mean[..., 0].size**2 / rgb.mean(axis=(0, 1)) ** 2 + \
        (rgb_se**2).sum(axis=(0, 1)) / rgb[..., 0].size**2 * ratio**2 / rgb.mean(axis=(0, 1)) ** 2
    print("image mean, spectral / RGB - 1: " + ", ".join(
        f"{c} {r - 1:+.2e} +- {s:.1e}" for c, r, s in zip("RGB", ratio, np.sqrt(var))))
    for obs in ("cie1931",):
        alt = np.stack([spectral_exr.read_render(Path(args.work) / f"spectral_{k}.exr", "spectral", obs)[1]
                        for k in range(args.passes)]).mean(axis=0)
        print(f"with observer {obs} instead of mitsuba3: image mean ratio - 1: " + ", ".join(
            f"{c} {r - 1:+.2e}" for c, r in zip("RGB", alt.mean(axis=(0, 1)) / rgb.mean(axis=(0, 1)))))


if __name__ == "__main__":
    main()
