"""Run folders of real EXR renders with Gaussian noise of their own, made without a renderer, for
the tests that compare two runs (the baseline and compare_runs: tests/verdict/, tests/hostile/)."""
import json

import numpy as np

from spectral_bench.batch import exr


def noisy(rng, truth, passes, sigma):
    """Mean and standard error of ``passes`` independent Gaussian passes around ``truth``."""
    p = truth[None] + rng.normal(0.0, sigma, (passes,) + truth.shape)
    return p.mean(axis=0), p.std(axis=0, ddof=1) / np.sqrt(passes)


def noisy_run_folder(out, seed, gains):
    """An outputs folder of real EXR renders with their own noise (4 passes): one job per scene,
    each scene's image times its gain."""
    rng = np.random.default_rng(seed)
    truth = np.broadcast_to(np.linspace(0.2, 1.0, 16)[None, :, None], (16, 16, 3))
    runs = []
    for scene, gain in gains.items():
        mean, se = noisy(rng, truth * gain, 4, 0.05)
        res = out / scene / "results" / "mitsuba"
        res.mkdir(parents=True)
        exr.write_image(res / "render.exr", ["R", "G", "B"], mean.astype(np.float32),
                        {f"stderr.{c}": se[..., i].astype(np.float32) for i, c in enumerate("RGB")})
        runs.append({"scene": scene, "case": "c", "backend": "mitsuba", "mode": "m", "status": "ok", "reason": "",
                     "spp": 4096, "passes": 4, "resolution": [16, 16], "image": f"{scene}/results/mitsuba/render.exr",
                     "channels": ["R", "G", "B"], "metrics": {}, "probes": [], "pass_times": [1.0, 1.1, 0.9, 1.0]})
    (out / "metrics.json").write_text(json.dumps({"options": {"alpha": 0.01, "block": 4}, "runs": runs}))
