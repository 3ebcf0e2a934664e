"""False alarms of the noise test (block test and scale test) on the rough glass spheres, over many
seeds: the scenes whose caustic paths are heavy-tailed (issue 20, item 3).

    .venv/bin/python benchmarks/calibrate_glass_false_alarms.py render --seeds 100 --scale 0.25 --cache DIR
    .venv/bin/python benchmarks/calibrate_glass_false_alarms.py judge --cache DIR

``render`` keeps every render (mean and per-pixel standard error from 2 passes, the scene's own spp)
in DIR, so the judging can be re-run with any version of the tests without rendering again; a render
already in DIR is not redone. ``judge`` applies batch/verdict/compare.py's noise test (block test and
scale test, each at its share of alpha; samples per block as the runner chooses them,
compare.min_samples_for; the column "before" is the block test alone at the whole alpha, with
65536 samples per block, as before issue 20) against the committed reference downsampled to the render's
resolution, and prints the false-alarm counts with Clopper-Pearson 95 % intervals.

Reduced resolution (--scale 0.25: 128x128 instead of 512x512) keeps what the heavy tail depends on:
the same samples per pixel (256), two passes, and the same samples per block (16x16 px x 256 spp =
65536), so a block's statistic is a mean of as many samples as at full resolution; it has 16x fewer
blocks (192 tests instead of 3072), so the block test's Sidak threshold is less extreme (|z| ~ 3.8
instead of ~4.5) and a false alarm there is a milder check of the tail than at full resolution; the
scale test pools all pixels at any resolution.
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

SCENES = ("ggx_glass", "beckmann_glass")
SEED0 = 20_000  # distinct from the runner's (0), the references' and calibrate_noise_test.py's (10000 + 100 k)


def clopper_pearson(k, n, conf=0.95):
    """Exact binomial confidence interval (Clopper and Pearson 1934, via the beta distribution)."""
    a = (1 - conf) / 2
    lo = 0.0 if k == 0 else float(st.beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(st.beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def render(args):
    pkg_bootstrap.package()
    from spectral_bench.batch import backends, scene_sources
    from spectral_bench.batch.jobs import job as jobs, plan
    backend = backends.get("mitsuba")
    scenes = {n: s for n, s in scene_sources.load([str(scene_sources.DEFAULT_BLEND)])
              if isinstance(s, dict) and n in (args.scene or SCENES)}
    cache = Path(args.cache)
    settings = plan.verdict_settings({"alpha": 0.01, "min_samples": 65536, "block": None, "flip": False,
                                      "references": None, "known": None})
    for k in range(args.seeds):
        for name, sc0 in scenes.items():
            sc = plan.for_run(sc0, {"scale": args.scale})
            folder = cache / f"{name}_s{args.scale:g}" / f"seed{k}"
            if (folder / "done.json").exists():
                continue
            mode, _ = backend.mode_for(sc)
            job = jobs.make("render", name, sc, "mitsuba", mode, sc["render"]["spp"], cache,
                            folder.relative_to(cache), passes=2, seed=SEED0 + 100 * k, source_scene=sc0, verdict=settings)
            t = time.perf_counter()
            rec = jobs.execute(job)
            (folder / "done.json").write_text(json.dumps({"image": rec["image_path"], "spp": rec["spp"],
                                                          "passes": rec["passes"], "time_s": rec["time_s"]}))
            print(f"{name} seed {k}: {time.perf_counter() - t:.1f} s", flush=True)


def judge(args):
    pkg_bootstrap.package()
    from spectral_bench.batch import exr
    from spectral_bench.batch.verdict import compare, references
    cache = Path(args.cache)
    rows = []
    for folder in sorted(p for p in cache.iterdir() if p.is_dir() and any(p.glob("seed*/done.json"))):
        name = folder.name.rsplit("_s", 1)[0]
        ref = references.load(name)
        outcome = {"block": [], "scale": [], "any": [], "z_scale": [], "time": [], "detectable": [], "block_only": []}
        for done in sorted(folder.glob("seed*/done.json")):
            info = json.loads(done.read_text())
            names, img, se = exr.read_image_and_stderr(info["image"])
            at = compare.reference_at(ref.mean, ref.stderr, ref.spp, img.shape, ref.provenance.get("passes", 8))
            own = se.astype(np.float64) ** 2
            nt = compare.z_test(img, at, info["spp"], own_var_of_mean=own, own_passes=info["passes"], alpha=0.01,
                                min_samples=compare.min_samples_for(name, args.min_samples))
            old = compare.z_test(img, at, info["spp"], own_var_of_mean=own, own_passes=info["passes"], alpha=0.01,
                                 scale_test=False)  # the block test alone at the whole alpha (before issue 20)
            outcome["block_only"].append(not old.passed)
            outcome["block"].append(not nt.block_passed)
            outcome["scale"].append(not nt.scale["pass"])
            outcome["any"].append(not nt.passed)
            outcome["z_scale"].append(nt.scale["z_max"])
            outcome.setdefault("z_all", []).extend(nt.scale["z"])
            outcome["time"].append(info["time_s"])
            outcome["detectable"].append(nt.detectable()["scale"])
        n = len(outcome["any"])
        if not n:
            continue
        cells = []
        for key in ("block_only", "block", "scale", "any"):
            k = int(sum(outcome[key]))
            lo, hi = clopper_pearson(k, n)
            cells.append(f"{k}/{n} [{100 * lo:.1f}, {100 * hi:.1f}] %")
        rows.append(f"| {folder.name} | {img.shape[1]}x{img.shape[0]} | {nt.samples_per_block} | {nt.blocks} | {' | '.join(cells)} | "
                    f"{np.median(outcome['z_scale']):.2f} | {np.std(outcome['z_all']):.2f} | "
                    f"{np.mean(np.abs(outcome['z_all']) > 2.576):.3f} | {np.median(outcome['detectable']):.4f} | "
                    f"{np.median(outcome['time']):.1f} |")
    print("| scene (scale) | resolution | samples per block | block tests | block test alone at alpha (before) [95 % CI] | "
          "block test at alpha/2 [95 % CI] | scale test at alpha/2 [95 % CI] | noise test (both) [95 % CI] | "
          "median max abs z (scale test) | sd of scale z (every channel) | fraction abs z > 2.576 (0.010 if normal) | "
          "median detectable.scale | median render s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=("render", "judge"))
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("-s", "--scene", action="append")
    ap.add_argument("--cache", required=True)
    ap.add_argument("--min-samples", type=int, default=65536,
                    help="--min-samples of the judged noise test (the scene's own larger figure wins: compare.SCENE_MIN_SAMPLES)")
    args = ap.parse_args()
    {"render": render, "judge": judge}[args.what](args)


if __name__ == "__main__":
    main()
