"""Calibration of the Airy probe (batch/verdict/probes/thin_film.py) on iridescent_sphere_smooth.

    .venv/bin/python benchmarks/calibrate_thin_film_probe.py [--seeds 4] [--write]

Measures (1) how far the footprint integral is from converged at the supersampling the probe uses
(tile means at S and 2S sub-rays per side), (2) the probe's two records on Mitsuba renders of the
scene's own film over several seeds, at the scene's resolution and at a quarter of it, with the
CIE colorimetry of the project (colour-science's CMFs, Y normalised by their integral), and the
film judged absolutely with Mitsuba's own colour constants instead (its CMF table, its Y
normalisation 1/106.7503, its XYZ -> sRGB matrix) to locate what fails, and (3) the film record's
power against films a little thinner than the scene's. --write appends the tables to benchmarks/CALIBRATION.md.
"""
import argparse
import copy
import sys
import tempfile
import types
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

SCENE = "iridescent_sphere_smooth"


def mitsuba_colour():
    """Mitsuba 3's spectral film constants as a stand-in for exporters/colorimetry (``xyz`` takes
    the probe's observer argument and ignores it: the film has one observer)."""
    import mitsuba as mi
    mi.set_variant("scalar_spectral")
    from spectral_bench.exporters import spectra
    wl = spectra.cie_1931_cmfs()[0]
    cmf = np.array([[float(v) for v in mi.cie1931_xyz(float(w))] for w in wl])
    m = np.array([[float(mi.xyz_to_srgb(mi.ScalarColor3f(*e))[i]) for e in np.eye(3)] for i in range(3)])
    return types.SimpleNamespace(
        xyz=lambda v, obs=None: np.trapz(np.asarray(v)[:, None] * cmf, wl, axis=0) * mi.MI_CIE_Y_NORMALIZATION,
        xyz_to_srgb=lambda x: np.asarray(x) @ m.T)


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, exr
    from spectral_bench.batch.verdict import probes, stats
    from spectral_bench.batch.verdict.probes import thin_film
    from spectral_bench.exporters import colorimetry, ir, ir_json

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--smoke", action="store_true", help="seconds: 64x64 at 16 spp, one seed, one film offset; not recorded")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    configs = ((64, 16, 1),) if args.smoke else ((64, None, args.seeds), (256, None, args.seeds), (256, 1024, 1))
    offsets = (200.0,) if args.smoke else (200.0, 20.0, 5.0, 1.0)
    golden = ir_json.load(pkg_bootstrap.ROOT / "golden" / "ir" / f"{SCENE}.json")
    backend = backends.get("mitsuba")
    lines = []

    lines += ["| image | sub-rays per side S | worst tile: mean(S) / mean(2S) - 1 |", "|---|---|---|"]
    for size in (32,) if args.smoke else (32, 64, 256):
        s = thin_film.supersampling(size, size)
        e1, m = thin_film.expected_image(golden, 0, size, size)
        e2, _ = thin_film.expected_image(golden, 0, size, size, sub=2 * s)
        worst = max(np.abs(e1[ys, xs].mean(0) / e2[ys, xs].mean(0) - 1).max() for ys, xs in thin_film.tiles(m))
        lines.append(f"| {size}x{size} | {s} | {worst:.1e} |")

    def render(size, thickness, seed, tmp, spp=None):
        sc = copy.deepcopy(golden)
        sc["render"]["spp"] = spp or sc["render"]["spp"]
        sc["render"]["width"] = sc["render"]["height"] = size
        sc["objects"][0]["bsdf"]["thin_film"]["thickness"] = thickness
        sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
        out = Path(tmp) / f"{size}_{thickness:g}_{seed}_{sc['render']['spp']}"
        xml = backend.export(sc, out / "m")
        backend.render(xml, backend.mode_for(sc)[0], sc["render"]["spp"], out / "r.exr", seed=seed)
        names, img = exr.read_image(out / "r.exr")
        judged = copy.deepcopy(golden)
        judged["render"]["width"] = judged["render"]["height"] = size
        return judged, names, img

    def verdict(sc, names, img, colour, record=-1, tile=None):
        thin_film.colorimetry, default_tile = colour, thin_film.TILE_PIXELS
        thin_film.TILE_PIXELS = tile or default_tile
        try:
            p = probes.evaluate(sc, names, img)[record]
        finally:
            thin_film.colorimetry, thin_film.TILE_PIXELS = colorimetry, default_tile
        ratio = f"x {' '.join(f'{r:.5f}' for r in p['ratio'])}, " if "ratio" in p else ""
        return f"{ratio}{p['error']:.1f} {'pass' if p['pass'] else 'FAIL'}"

    mitsuba = mitsuba_colour()

    def absolute(sc, names, img, colour):
        """The film record without the environment scale (the probe's expected values as they are)."""
        thin_film.colorimetry = colour
        try:
            expected, mask = thin_film.expected_image(sc, 0, img.shape[1], img.shape[0])
        finally:
            thin_film.colorimetry = colorimetry
        blocks = thin_film.tiles(mask)
        res = [stats.region_mean_test(img[ys, xs, :3] - expected[ys, xs], tests=3 * len(blocks)) for ys, xs in blocks]
        return f"{max(r['z'] for r in res):.1f} {'pass' if all(r['pass'] for r in res) else 'FAIL'}"
    film = golden["objects"][0]["bsdf"]["thin_film"]["thickness"]
    lines += ["", "| image, spp | seed | tiles | environment seen directly (CIE): rendered / expected, t, verdict "
              "| airy film, relative to the environment (CIE): max t, verdict "
              "| the same with 8x8 tiles | airy film, absolute, Mitsuba's colour constants: max t, verdict |",
              "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for size, spp, seeds in configs:
            for seed in range(seeds):
                sc, names, img = render(size, film, seed, tmp, spp)
                tiles = probes.evaluate(sc, names, img)[-1]["tiles"]
                thin_film_abs = copy.deepcopy(sc)
                lines.append(f"| {size}x{size}, {spp or golden['render']['spp']} | {seed} | {tiles} "
                             f"| {verdict(sc, names, img, colorimetry, 0)} | {verdict(sc, names, img, colorimetry)} "
                             f"| {verdict(sc, names, img, colorimetry, tile=8)} "
                             f"| {absolute(thin_film_abs, names, img, mitsuba)} |")
                print(lines[-1], flush=True)
        lines += ["", f"| rendered film (scene: {film:g} nm), 64x64 | max t | verdict |", "|---|---|---|"]
        for d in offsets:
            sc, names, img = render(64, film - d, 0, tmp, 16 if args.smoke else None)
            lines.append(f"| {film - d:g} nm | {verdict(sc, names, img, colorimetry)} |".replace(" pass", " | pass").replace(" FAIL", " | FAIL"))
            print(lines[-1], flush=True)
    text = "\n".join(["", "## Airy probe (iridescent_sphere_smooth)", "",
                      f"Measured by `benchmarks/calibrate_thin_film_probe.py`. Tiles of {thin_film.TILE_PIXELS}x{thin_film.TILE_PIXELS} pixels, each tile's mean "
                      "residual against its standard error (Student t), Sidak over tiles and channels at alpha 0.01.", ""]
                     + lines + [""])
    print(text)
    if args.write and not args.smoke:
        with open(pkg_bootstrap.ROOT / "benchmarks" / "CALIBRATION.md", "a") as f:
            f.write(text)


if __name__ == "__main__":
    main()
