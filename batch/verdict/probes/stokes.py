"""Stokes output: S0 >= sqrt(S1^2 + S2^2 + S3^2) at every pixel, up to noise."""
import numpy as np

from .. import compare
from .common import probe as _probe

Z_MAX = 4.0


def validity(m):
    scene, names, image, reference = m.scene, m.names, m.image, m.reference
    if "S0.G" not in names:
        return []
    name = "Stokes S0 >= |(S1, S2, S3)|"
    if reference is None or reference.names != names:
        return [_probe(name, 0.0, None, None, "fraction", None, note="needs the reference's noise")]
    spp = scene["render"]["spp"]
    try:
        mean, var_of_mean, sigma2 = compare.reference_at(reference.mean, reference.stderr, reference.spp, image.shape)
    except ValueError:
        return [_probe(name, 0.0, None, None, "fraction", None, note="resolution not comparable")]
    worst = 0.0
    for c in "RGB":
        idx = [names.index(f"S{k}.{c}") for k in range(4)]
        s = image[..., idx].astype(np.float64)
        sd = np.sqrt(np.sum(sigma2[..., idx] / spp + var_of_mean[..., idx], axis=-1))
        excess = np.linalg.norm(s[..., 1:], axis=-1) - s[..., 0]
        floor = 1e-6 * max(float(np.abs(s[..., 0]).mean()), 1e-12)
        worst = max(worst, float(np.mean(excess > Z_MAX * sd + floor)))
    return [_probe(name, 0.0, worst, worst, "fraction of pixels beyond 4 sigma", worst <= 1e-3)]
