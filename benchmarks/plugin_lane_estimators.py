"""The rough dispersive plugin's lane mixture against keeping one lane: both unbiased, per-lane
variance of the BSDF sampling weight (N-SF11, GGX alpha 0.05-0.5, light from outside and inside,
four wavelengths 430-680 nm; the same samples for both estimators).

    DRJIT_LIBLLVM_PATH=... .venv/bin/python benchmarks/plugin_lane_estimators.py

The one-lane estimator draws lane j and weights only it, f_j / (p_j / 4); the plugin weights every
lane k with f_k / ((1/4) sum_i p_i). Prints each lane's mean (equal within noise: both unbiased)
and the ratio of variances (one lane / mixture).
"""
import mitsuba as mi, drjit as dr, sys, numpy as np
mi.set_variant("llvm_ad_spectral")
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "exporters" / "mitsuba_plugins"))
import dispersive_dielectric as dd
dd.register()
for alpha in (0.05, 0.2, 0.5):
  for wi in ([0.5, 0.2, 0.8426], [0.3, -0.4, -0.866]):
    b = mi.load_dict({"type": dd.PLUGIN_NAME, "B1": 1.73759695, "B2": 0.313747346, "B3": 1.89878101,
                      "C1": 0.013188707, "C2": 0.0623068142, "C3": 155.23629, "ext_ior": 1.0, "distribution": "ggx", "alpha": alpha})
    n = 2000000
    si = dr.zeros(mi.SurfaceInteraction3f, n); si.wi = dr.normalize(mi.Vector3f(wi)); si.wavelengths = mi.Spectrum(430.0, 510.0, 590.0, 680.0)
    rng = mi.PCG32(n, 3); s1 = rng.next_float32(); s2 = mi.Vector2f(rng.next_float32(), rng.next_float32())
    ctx = mi.BSDFContext()
    bs, w_mix = b.sample(ctx, si, s1, s2)
    j = mi.UInt32(dr.clip(s1 * 4, 0.0, 4 - 1e-4))
    etas = b._eta(si.wavelengths)
    value, _ = b.eval_pdf(ctx, si, bs.wo)
    p_j = b._eval_pdf_rough(ctx, si, bs.wo, True, [b._pick(etas, j)] * 4)[1]
    valid = dr.any(w_mix != 0)
    lanes = []
    for k in range(4):
        lanes.append(dr.select(valid & (j == k) & (p_j > 0), value[k] * 4 / dr.select(p_j > 0, p_j, 1), 0.0))
    wm, w1 = np.array(w_mix), np.array(mi.Spectrum(*lanes))
    print(f"alpha {alpha} wi_z {wi[2]:+.2f}: mean mixture {wm.mean(1).round(4)} one-lane {w1.mean(1).round(4)}; variance one-lane / mixture {(w1.var(1) / wm.var(1)).round(2)}")
