"""A smooth coated diffuse sphere (the IR's ``coated_diffuse``: Mitsuba 3's ``plastic`` with
``nonlinear`` false, docs/scene-format.md 6.6) alone in a uniform environment of radiance L(l).

Every point of the sphere sees the environment over its whole upper hemisphere (a lone convex
object cannot see itself), so the radiance leaving it towards the camera at cos mu_o from its
normal is, per wavelength (reference_code/appearance.py ``coated_diffuse_uniform``):

    L_o = L(l) [F(mu_o) + rho(l) (1 - F(mu_o)) (1 - F_dr,ext) / (eta^2 (1 - F_dr,int))]
        = L(l) [F(mu_o) + rho(l) (1 - F(mu_o))]

F the coat's unpolarised Fresnel reflectance (Hecht eq. 4.42-4.43) at eta = int_ior / ext_ior, the
first term the mirror reflection of the environment, the second the diffuse lobe rho / (1 -
F_dr,int) (1 - F(mu_i)) (1 - F(mu_o)) / (pi eta^2) integrated over the environment (its
integral of (1 - F(mu_i)) cos / pi is 1 - F_dr,ext), and 1 - F_dr,ext = eta^2 (1 - F_dr,int)
(reciprocity: tests/probes/test_coated.py checks the ratio and the whole expression against a
quadrature of the BRDF). Mitsuba 3 takes F_dr,int from a fit (Egan and Hilgeman 1973): at eta 1.5
its diffuse term is 1.00115 times this one (measured: mi.fresnel_diffuse_reflectance(1 / 1.5) =
0.596811 against the integral's 0.596346), which this probe does not resolve at the scene's
settings (docs/scene-format.md 6.6).

The pixels are judged as thin_film.py judges a filmed sphere (the same footprint integral over an
S x S grid of sub-rays per pixel, silhouette pixels left out, 4 x 4 tiles against their own
standard error, Sidak over tiles and channels), with the colour table R(theta, l) L(l) of this
closed form; and once more in rings of the view angle (``view_rings``: the closed form depends on
the angle alone, and a ring pools hundreds of pixels, so an error that moves the whole sphere, such
as a coat of another index, is seen far sooner than tile by tile). Three records: "environment
seen directly" (the renderer's colour scale; left to thin_film.py where a filmed sphere is in the
same scene), "coated <object>" (tiles) and "coated <object> by view angle" (rings); each reports its
verdict under the observers of recorded deviations too (Measurement.observers). A rough coat
(roughplastic) or another object in the scene: no closed form here, said in a record that is not
judged.
"""
import numpy as np

from ....exporters import colorimetry, ir, spectra
from .. import raycast, stats
from ..optics import coated_diffuse_uniform
from . import thin_film
from .common import MIN_PIXELS, probe as _probe, remembered


def _coated_sphere(obj):
    b = obj.get("bsdf") or {}
    return b.get("type") == "coated_diffuse" and obj["shape"]["type"] == "sphere"


def applies(obj):
    """A smooth coated diffuse sphere."""
    return _coated_sphere(obj) and not ((obj["bsdf"].get("roughness") or {}).get("alpha", 0) > 0)


def eta(bsdf):
    return float(bsdf["int_ior"]) / float(bsdf.get("ext_ior", ir.AIR_IOR))


@remembered()
def reflectance_table(bsdf):
    """(theta grid, wavelengths, L_o / L per angle and wavelength) of a smooth coated diffuse: the
    module docstring's closed form on thin_film's uniform theta grid."""
    wl = spectra.cie_1931_cmfs()[0]
    theta = np.linspace(0.0, np.pi / 2, thin_film.THETA_TABLE)
    rho = spectra.evaluate(bsdf["reflectance"], wl)
    return theta, wl, coated_diffuse_uniform(np.cos(theta)[:, None], rho[None, :], eta(bsdf))


@remembered()
def colour_table(bsdf, radiance, obs=colorimetry.GROUND_TRUTH):
    """(theta grid, linear sRGB of R(theta, l) L(l) per angle)."""
    return thin_film._rgb_table(*reflectance_table(bsdf), radiance, obs)


def expected_images(scene, index, width, height, observers=(colorimetry.GROUND_TRUTH,), sub=None):
    """({observer: expected linear sRGB (H, W, 3)}, mask of the sphere's whole pixels)."""
    radiance = scene["environment"]["radiance"]
    bsdf = scene["objects"][index]["bsdf"]
    tables = {o: colour_table(bsdf, radiance, o) for o in observers}
    return thin_film.expected_images(scene, index, width, height, observers, sub, tables=tables)


RINGS = 16  # view-angle rings, uniform in theta over 0-90 degrees


def view_rings(scene, index, width, height, mask):
    """Lists of (row, column) index arrays of ``mask``'s pixels, one per ring of the view angle
    theta_o at the pixel centre (RINGS rings uniform over 0-90 degrees; rings with fewer than
    MIN_PIXELS pixels left out). The closed form depends on theta_o alone, so a coat of the wrong
    index (or a wrong diffuse term) moves every pixel of a ring the same way: each ring pools
    hundreds of pixels where a 4 x 4 tile has 16."""
    cam, obj = scene["camera"], scene["objects"][index]
    origin, dirs = raycast.camera_rays(cam, width, height)
    centre, radius = np.asarray(obj["shape"]["center"], dtype=np.float64), float(obj["shape"]["radius"])
    oc = origin - centre
    b = dirs @ oc
    disc = b * b - (oc @ oc - radius * radius)
    t = -b - np.sqrt(np.clip(disc, 0.0, None))
    n = (origin + t[..., None] * dirs - centre) / radius
    theta = np.arccos(np.clip(-np.sum(dirs * n, axis=-1), 0.0, 1.0))
    ring = np.minimum((theta / (np.pi / 2) * RINGS).astype(int), RINGS - 1)
    out = []
    for k in range(RINGS):
        ys, xs = np.nonzero(mask & (disc > 0) & (ring == k))
        if len(ys) >= MIN_PIXELS:
            out.append((ys, xs))
    return out


def coated_spheres(m, alpha=None):
    alpha = stats.ALPHA if alpha is None else alpha
    scene, image = m.scene, m.image
    env = scene.get("environment")
    objs = scene["objects"]
    coated = [i for i, obj in enumerate(objs) if _coated_sphere(obj)]
    if not env or not coated or "R" not in m.names[:3]:
        return []
    h, w = image.shape[:2]
    rgb = image[..., :3].astype(np.float64)
    observers = [o for o in m.observers if o != colorimetry.GROUND_TRUTH]
    out = []
    if not any(thin_film.applies(o) for o in objs):  # else thin_film.py judges the environment
        bg = thin_film.environment_pixels(scene, w, h)
        if bg.sum() >= MIN_PIXELS:
            n = int(bg.sum())

            def env_stat(obs):
                expected = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(env["radiance"], obs=obs))
                return stats.compare_means(rgb[bg].mean(axis=0), expected, rgb[bg].std(axis=0, ddof=1) / np.sqrt(n),
                                           dof=n - 1, alpha=alpha)
            stat = env_stat(colorimetry.GROUND_TRUTH)
            expected = np.array(stat["expected"])
            out.append(_probe("environment seen directly", expected, rgb[bg].mean(axis=0), stat["z"], "sigma",
                              stat["pass"], pixels=n, ratio=rgb[bg].mean(axis=0) / expected, z=stat["z"],
                              stat=stat, alternatives={o: env_stat(o) for o in observers}))
    for i in coated:
        obj = objs[i]
        name = f"coated {obj['name']}"
        if not applies(obj):
            out.append(_probe(name, None, None, None, "sigma", None,
                              note="a rough coat (roughplastic): no closed form here"))
            continue
        if len(objs) > 1:
            out.append(_probe(name, None, None, None, "sigma", None,
                              note="other objects in the scene: the diffuse lobe's closed form needs the whole "
                                   "environment above every point of the sphere"))
            continue
        images, mask = expected_images(scene, i, w, h, (colorimetry.GROUND_TRUTH, *observers))
        expected = images[colorimetry.GROUND_TRUTH]
        blocks = thin_film.tiles(mask)
        if mask.sum() < MIN_PIXELS or not blocks:
            out.append(_probe(name, None, None, None, "sigma", None, pixels=int(mask.sum()),
                              note="needs whole pixels of the sphere"))
            continue
        stat = thin_film._tile_stat(rgb, expected, blocks, alpha)
        alternatives = {o: thin_film._tile_stat(rgb, images[o], blocks, alpha) for o in observers}
        used = np.zeros_like(mask)
        for ys, xs in blocks:
            used[ys, xs] = True
        out.append(_probe(name, expected[used].mean(axis=0), rgb[used].mean(axis=0), stat["z"], "sigma",
                          stat["pass"], pixels=int(used.sum()), tiles=len(blocks), z=stat["z"], stat=stat,
                          alternatives=alternatives, coat_eta=eta(obj["bsdf"])))
        rings = view_rings(scene, i, w, h, used)
        if rings:
            stat = thin_film._tile_stat(rgb, expected, rings, alpha)
            alternatives = {o: thin_film._tile_stat(rgb, images[o], rings, alpha) for o in observers}
            out.append(_probe(f"{name} by view angle", expected[used].mean(axis=0), rgb[used].mean(axis=0), stat["z"],
                              "sigma", stat["pass"], pixels=int(used.sum()), rings=len(rings), z=stat["z"], stat=stat,
                              alternatives=alternatives, coat_eta=eta(obj["bsdf"])))
    return out
