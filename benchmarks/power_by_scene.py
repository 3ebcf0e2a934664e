"""Power of the noise test per canonical scene at default settings, from the stored noise model
(no rendering): the committed reference's mean as the truth, its per-sample variance over the
scene's spp for the render (two passes, as the runner renders), its own standard error for the
reference; one simulated unbiased render per scene judged by batch/verdict/compare.py, and its
``detectable`` (the smallest relative uniform scale error detected with 90 % power).

    .venv/bin/python benchmarks/power_by_scene.py [-s SCENE ...]

The per-sample variance of a reference pixel (stderr^2 x its spp) is the render's when the render
uses the same estimator (Mitsuba, the reference's renderer); another renderer's noise differs, and
its run's own ``detectable`` (from its own noise) is what counts for it.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.verdict import compare, references
    ap = argparse.ArgumentParser()
    ap.add_argument("-s", "--scene", action="append")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    print("| scene | resolution | spp | block (px) | block tests | detectable.scale | by | block test alone | scale test alone |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, sc in scene_sources.load([str(scene_sources.DEFAULT_BLEND)]):
        if not isinstance(sc, dict) or (args.scene and name not in args.scene):
            continue
        ref = references.load(name)
        spp = sc["render"]["spp"]
        at = compare.reference_at(ref.mean, ref.stderr, ref.spp, ref.mean.shape, ref.provenance.get("passes", 8))
        sigma2 = np.maximum(at.sigma2, 0.0)
        # two passes of spp/2 samples, fully correlated channels (a path's R, G, B share its noise)
        z = [rng.standard_normal(at.mean.shape[:2] + (1,)) for _ in range(2)]
        passes = [at.mean + np.sqrt(sigma2 / (spp / 2)) * zz for zz in z]
        mean, var = (passes[0] + passes[1]) / 2, (passes[0] - passes[1]) ** 2 / 4
        ref_draw = compare.ReferenceAt(at.mean + np.sqrt(at.var_of_mean) * rng.standard_normal(at.mean.shape),
                                       at.var_of_mean, at.sigma2, at.dof)
        zt = compare.z_test(mean, ref_draw, spp, own_var_of_mean=var, own_passes=2,
                            min_samples=compare.min_samples_for(name))
        det = zt.detectable() or {}
        tests = det.get("tests", {})
        cell = (lambda v: f"{v:.4f}" if v is not None else "> 1")  # noqa: E731
        print(f"| {name} | {mean.shape[1]}x{mean.shape[0]} | {spp} | {zt.block} | {zt.blocks} | "
              f"{cell(det.get('scale'))} | {det.get('by', '-')} | {cell(tests.get('block test'))} | "
              f"{cell(tests.get('scale test'))} |", flush=True)


if __name__ == "__main__":
    main()
