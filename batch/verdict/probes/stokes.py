"""Stokes output must describe physical light: S0 >= sqrt(S1^2 + S2^2 + S3^2).

Judged per block of pixels and colour channel on the render's own noise (its per-pixel standard
error from independent passes): averaging keeps the inequality (the norm of a mean is at most the
mean of the norms), so each block's mean Stokes vector must satisfy it up to noise. One-sided test
of the excess |S123| - S0 against its standard error (delta method), Student's t with
Satterthwaite's degrees of freedom, Sidak over blocks and channels; the blocks are those of the
noise test (batch/verdict/compare.py), pooling enough samples for heavy-tailed pixels.
"""
import numpy as np

from .. import compare, stats
from .common import probe as _probe


def validity(m):
    names, image, stderr = m.names, m.image, m.stderr
    if "S0.G" not in names:
        return []
    name = "Stokes S0 >= |(S1, S2, S3)|"
    if stderr is None:
        return [_probe(name, 0.0, None, None, "sigma", None,
                       note="needs the render's own noise (render with --passes >= 2)")]
    h, w = image.shape[:2]
    passes = max(int(m.passes or 2), 2)
    b = compare.block_size(m.scene["render"]["spp"], image.shape)
    ey, ex = compare.block_edges(h, b), compare.block_edges(w, b)
    n = compare.block_sums(np.ones((h, w, 1)), ey, ex)[..., 0]
    zs, ps, dofs = [], [], []
    for c in "RGB":
        idx = [names.index(f"S{k}.{c}") for k in range(4)]
        s = compare.block_sums(image[..., idx].astype(np.float64), ey, ex) / n[..., None]
        v = compare.block_sums(stderr[..., idx].astype(np.float64) ** 2, ey, ex) / n[..., None] ** 2
        v2 = compare.block_sums(stderr[..., idx].astype(np.float64) ** 4, ey, ex) / n[..., None] ** 4
        norm = np.linalg.norm(s[..., 1:], axis=-1)
        unit = s[..., 1:] / np.maximum(norm, 1e-300)[..., None]
        var = v[..., 0] + np.sum(unit**2 * v[..., 1:], axis=-1)
        floor = (1e-6 * max(float(np.abs(s[..., 0]).mean()), 1e-12)) ** 2
        z = (norm - s[..., 0]) / np.sqrt(var + floor)
        dof = var**2 / np.maximum(v2[..., 0] + np.sum(unit**4 * v2[..., 1:], axis=-1), 1e-300) * max(passes - 1, 1)
        zs.append(z)
        dofs.append(dof)
        ps.append(stats.one_sided_p(z, dof))
    z, p = np.stack(zs), np.stack(ps)
    threshold = stats.sidak_threshold(stats.ALPHA, p.size)
    return [_probe(name, 0.0, float(z.max()), float(z.max()), "sigma", bool(p.min() >= threshold),
                   z=float(z.max()), p=float(p.min()), threshold=threshold, blocks=int(p.size))]
