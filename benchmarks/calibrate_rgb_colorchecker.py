"""Calibrates the ColorChecker bound of tests/backends/test_rgb_backends.py: renders macbeth_chart_D65 and
macbeth_chart_D50 through Cycles and LuxCore at the test's settings (scale 0.25: 155x105, 64 spp,
4 passes) with several seeds and reports, per patch, |dE00 measured - dE00 predicted by the
reduction rule| (the rule's own error is known without a renderer: what is left is noise and
whatever the renderer does differently). The test's CHART_DE_NOISE must exceed the largest value.

    .venv/bin/python benchmarks/calibrate_rgb_colorchecker.py [--seeds 5] [--write]
    .venv/bin/python benchmarks/calibrate_rgb_colorchecker.py --smoke   # seconds: 1 seed, 4 spp, 2 passes; not recorded

--write appends the result to benchmarks/CALIBRATION.md.
"""
import argparse
import copy
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

SCALE, SPP, PASSES = 0.25, 64, 4
SMOKE_SPP, SMOKE_PASSES = 4, 2  # --smoke: the figures mean nothing


def main(argv=None):
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, exr, scene_sources
    from spectral_bench.batch.studies import rgb_error
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--smoke", action="store_true", help=f"checks that the script runs: one seed, {SMOKE_SPP} spp in "
                    f"{SMOKE_PASSES} passes; never recorded")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    if args.smoke and args.write:
        ap.error("--smoke checks that the script runs; its figures are never recorded: leave out --write")
    spp, passes = (SMOKE_SPP, SMOKE_PASSES) if args.smoke else (SPP, PASSES)
    if args.smoke:
        args.seeds = 1
    golden = {n: s for n, s in scene_sources.load([str(scene_sources.DEFAULT_BLEND)])
              if n in ("macbeth_chart_D65", "macbeth_chart_D50")}
    rows, worst = [], {}
    for chart, base in sorted(golden.items()):
        sc = copy.deepcopy(base)
        sc["render"]["width"] = round(sc["render"]["width"] * SCALE)
        sc["render"]["height"] = round(sc["render"]["height"] * SCALE)
        for name in ("cycles", "luxcore"):
            b = backends.get(name)
            with tempfile.TemporaryDirectory() as tmp:
                path = b.export(sc, Path(tmp) / "export")
                diffs, measured = [], []
                for seed in range(args.seeds):
                    b.render(path, "rgb", spp, Path(tmp) / "r.exr", passes=passes, seed=100 * seed)
                    _, img = exr.read_image(Path(tmp) / "r.exr")
                    errs = rgb_error.chart_errors(sc, img)
                    diffs.append([abs(m - p) for m, p, _ in errs.values()])
                    measured.append([m for m, _, _ in errs.values()])
            d = np.array(diffs)
            worst[chart, name] = float(d.max())
            rows.append(f"| {chart} | {name} | {args.seeds} | {d.mean():.3f} | {np.percentile(d, 99):.3f} | {d.max():.3f} "
                        f"| {np.mean(measured):.3f} | {np.max(measured):.3f} |")
            print(rows[-1], flush=True)
    head = ["| chart | renderer | seeds | mean abs(dE meas - dE rule) | 99th pct | max | mean dE00 vs truth | max dE00 vs truth |",
            "|---|---|---|---|---|---|---|---|"]
    text = "\n".join(head + rows)
    print(text)
    print(f"largest: {max(worst.values()):.3f}")
    if args.write:
        with open(Path(__file__).resolve().parent / "CALIBRATION.md", "a") as fh:
            fh.write("\n## RGB backends: ColorChecker CIEDE2000 against the reduction rule's prediction\n\n"
                     "`benchmarks/calibrate_rgb_colorchecker.py` renders both charts through Cycles and LuxCore at "
                     f"the settings of `tests/backends/test_rgb_backends.py` (scale {SCALE}, {SPP} spp, {PASSES} passes), "
                     f"{args.seeds} seeds each, and compares every patch's dE00 against the spectral truth with "
                     "the dE00 the rule predicts without a renderer (`exporters/rgb_reduction.predicted_error`). "
                     "What remains is noise (and anything a renderer does beyond the rule).\n\n"
                     f"{text}\n\nLargest difference {max(worst.values()):.3f} dE00: the test's bound "
                     "`CHART_DE_NOISE` is 0.3.\n")


if __name__ == "__main__":
    main()
