"""The pbrt writer's absolute radiometry, rendered by pbrt-v4 and judged by closed forms
(tests/pbrt_checks.py): a white Lambertian plate under a uniform D65 environment and under a D65
area light (64x64, 128 spp, 4 passes), and canonical GGX copper scenes at their own settings
judged by the GGX probe with pbrt's height-correlated shadowing and with the IR's separable one.

    .venv/bin/python benchmarks/pbrt_writer_checks.py [-s SCENE ...] [--write]
    .venv/bin/python benchmarks/pbrt_writer_checks.py --smoke   # the plates only, 1 GGX scene at 32x32, 8 spp

--write prepends the tables to benchmarks/PBRT_WRITER.md. Without a pbrt (scripts/build_pbrt.sh, or
on PATH) it prints that nothing was measured and why, and exits 0.
"""
import argparse
import copy
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
import record  # noqa: E402

OUT = Path(__file__).resolve().parent / "PBRT_WRITER.md"
HEAD = "# The pbrt-v4 writer's radiometry, measured\n\nRecorded by `benchmarks/pbrt_writer_checks.py --write`; newest first.\n\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-s", "--scene", action="append", help="a canonical GGX scene (default: ggx_copper_grazing, "
                    "ggx_copper_50_isolated)")
    ap.add_argument("--smoke", action="store_true", help="seconds: 1 GGX scene at 32x32, 8 spp (never recorded)")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    if args.smoke and args.write:
        ap.error("--smoke runs are never recorded")
    import pbrt_checks
    from spectral_bench.exporters import ir_json
    if pbrt_checks.PBRT is None:
        print(f"Not measured: {pbrt_checks.MISSING}")
        return 0
    load = os.getloadavg()[0]
    lines = [f"## pbrt-v4 writer checks, {__import__('datetime').date.today().isoformat()}", "",
             f"Machine: {record.machine()}; load average {load:.1f} at the start; pbrt {pbrt_checks.PBRT}.", "",
             "| check | settings | measured | expected | judged | pbrt s |", "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        env = pbrt_checks.env_plate(Path(tmp) / "env")
        rel = env["measured"] / env["expected"] - 1
        lines.append(f"| white plate, D65 environment (Lambert probe) | 64x64, 128 spp x 4 | RGB {env['measured'].round(5).tolist()} "
                     f"(rel. {rel.round(6).tolist()}) | {env['expected'].round(5).tolist()} | "
                     f"{'pass' if all(r['pass'] for r in env['records']) else 'FAIL'}, rel. se of G {env['rel_se']:.1e} | "
                     f"{env['seconds']:.1f} |")
        area = pbrt_checks.area_plate(Path(tmp) / "area")
        res = area["result"]
        lines.append(f"| white plate, D65 area light (Lambert's polygon) | 64x64, 128 spp x 4, {area['pixels']} px | "
                     f"mean rel. residual {[round(x, 6) for x in res['mean']]} | 0 | "
                     f"{'pass' if res['pass'] else 'FAIL'} (z {res['z']:.2f}), resolves {area['resolved']:.1e} | "
                     f"{area['seconds']:.1f} |")
        goldens = {p.stem: p for p in (ROOT / "golden" / "ir").glob("*.json")}
        for name in args.scene or (["ggx_copper_50_isolated"] if args.smoke else ["ggx_copper_grazing", "ggx_copper_50_isolated"]):
            sc = copy.deepcopy(ir_json.load(goldens[name]))
            if args.smoke:
                sc["render"].update(width=32, height=32, spp=8)
            r = sc["render"]
            forms, wall = pbrt_checks.ggx_plate(sc, Path(tmp) / name)
            for form, records in forms.items():
                for rec in records:
                    lines.append(f"| {name}: {rec['name']}, {form} shadowing | {r['width']}x{r['height']}, {r['spp']} spp x 4 | "
                                 f"rel. error {rec['error']:+.5f} | 0 | "
                                 f"{'pass' if rec['pass'] else 'FAIL'} (z {rec.get('z') or 0:.2f}) | {wall:.1f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write:
        record.prepend(OUT, HEAD, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
