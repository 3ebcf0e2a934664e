"""Calibration and power of the noise test on real renders (not timings).

    .venv/bin/python benchmarks/calibrate_noise_test.py [--size 64] [--spp 256] [--seeds 10] [--write]

False alarms: unbiased renders (same scene, new seeds) judged against the committed reference,
for several block sizes (samples pooled per block). A calibrated test fails about alpha of them,
and the median of p_min * (number of tests) is near ln 2 = 0.69 for independent tests (larger
when channels are correlated, as R, G, B are). Power: deliberately wrong variants of the scene,
judged the same way. --write appends the tables to benchmarks/CALIBRATION.md.
"""
import argparse
import copy
import datetime as dt
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import pkg_bootstrap  # noqa: E402

SCENES = ["ggx_copper_50", "ggx_copper_70", "ggx_copper_80", "ggx_glass"]
BLOCK_SAMPLES = (4096, 16384, 65536)


def variants():
    def metal(name):
        def f(sc):
            for o in sc["objects"]:
                if (o.get("bsdf") or {}).get("type") == "conductor":
                    o["bsdf"]["material"] = name
        return f

    def alpha(a):
        def f(sc):
            for o in sc["objects"]:
                if (o.get("bsdf") or {}).get("roughness"):
                    o["bsdf"]["roughness"]["alpha"] = a
        return f

    def light(factor):
        def f(sc):
            for o in sc["objects"]:
                if o.get("emitter"):
                    o["emitter"]["radiance"]["scale"] *= factor
        return f
    return {"Au instead of Cu": metal("Au"), "alpha 0.2 -> 0.22": alpha(0.22), "light +2 %": light(1.02)}


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, exr
    from spectral_bench.batch.verdict import compare, references
    from spectral_bench.exporters import ir_json
    from spectral_bench.exporters.ir import derived_needs

    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    golden = Path(__file__).resolve().parents[1] / "golden" / "ir"
    backend = backends.get("mitsuba")

    def judge(sc, name, seed, tmp, min_samples, tag=""):
        sc = copy.deepcopy(sc)
        sc["render"]["width"] = sc["render"]["height"] = args.size
        sc["needs"] = derived_needs(sc)
        xml = backend.export(sc, Path(tmp) / f"{name}{tag}_{seed}")
        mode, _ = backend.mode_for(sc)
        out = Path(tmp) / f"{name}{tag}_{seed}.exr"
        backend.render(xml, mode, args.spp, out, seed=10_000 + seed)
        t = exr.read_rgb(out)
        ref = references.load(name)
        m, v, s2 = compare.reference_at(ref.mean, ref.stderr, ref.spp, t.shape)
        return [compare.z_test(t, m, v, s2, args.spp, alpha=args.alpha, min_samples=ms) for ms in min_samples]

    rows, power = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name in SCENES:
            sc = ir_json.load(golden / f"{name}.json")
            per = [judge(sc, name, s, tmp, BLOCK_SAMPLES) for s in range(args.seeds)]
            for i, ms in enumerate(BLOCK_SAMPLES):
                tests = [p[i] for p in per]
                fails = sum(not t.passed for t in tests)
                med = float(np.median([t.p_min * t.blocks for t in tests]))
                rows.append(f"| {name} | {ms} | {tests[0].block} | {tests[0].blocks} | {fails}/{len(tests)} | {med:.2f} |")
            for label, change in variants().items():
                if "Cu" in label and "copper" not in name:
                    continue
                wrong = copy.deepcopy(sc)
                change(wrong)
                zt = judge(wrong, name, 0, tmp, (compare.MIN_SAMPLES,), tag="_wrong")[0]
                power.append(f"| {name} | {label} | {'fail (detected)' if not zt.passed else 'pass (missed)'} "
                             f"| {zt.z_max:.1f} |")
    text = "\n".join([
        f"## Noise test, {dt.date.today().isoformat()}: {args.size}x{args.size}, {args.spp} spp, alpha {args.alpha}, "
        f"{args.seeds} seeds per scene, {os.cpu_count()} cores",
        "", "False alarms on unbiased renders:", "",
        "| scene | samples per block | block (px) | tests | failed | median p_min x tests |",
        "|---|---|---|---|---|---|", *rows,
        "", f"Power ({compare.MIN_SAMPLES} samples per block, the default; one render each):", "",
        "| scene | wrong variant | verdict | max abs z |", "|---|---|---|---|", *power, ""])
    print(text)
    if args.write:
        from record import prepend
        prepend(Path(__file__).resolve().parent / "CALIBRATION.md", "# Calibration of the noise test\n\nRecorded by `benchmarks/calibrate_noise_test.py --write`.\n\n", text)


if __name__ == "__main__":
    main()
