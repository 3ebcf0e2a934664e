"""A lone Lambertian sphere (fluorescent or not) under a uniform environment, nothing else in the
scene: every point of the sphere sees only the environment, so its radiance is the same in every
direction and at every pixel (Mojzik et al. 2018's bispectral reflection with a Lambertian BRRDF,
exporters/fluorescence.py):

    L_o(l_o) = rho(l_o) L(l_o) + integral P(l_i, l_o) L(l_i) dl_i,

integrated here in numpy from the scene's own IR (P and L piecewise linear, a 0.05 nm trapezoid
rule for l_i, the CIE 1931 CMFs at 1 nm for l_o as exporters/colorimetry.py does). Pixels whose
footprint lies wholly on the sphere are independent draws of that value (box filter,
independent sampling), so the region's mean residual is judged against its own standard error
(batch/verdict/stats.py, Student's t, Sidak over the three channels). A renderer whose film
integrates with other colour-matching tables than the CIE 1931 1 nm ones (Mitsuba 3.9.1: 5 nm
tables, Y normalised by 1/106.7503; measured 0.10 % of Y above the CIE integral in red on this
scene's spectra, benchmarks/calibrate_fluorescence.py) is judged under its own observer too (the
probe's ``alternatives``), which a recorded deviation (known_deviations.toml) may explain. The
renderers integrate a 1 nm tabulation of P (exporters/fluorescence.table): 2e-4 of the
re-radiated light away from P itself, far below the noise at the scene's settings."""
import numpy as np

from ....exporters import colorimetry, fluorescence as fluo, spectra
from .. import raycast, stats
from .common import MIN_PIXELS, probe as _probe

def expected_radiance(bsdf, radiance, wavelengths):
    """rho(l) L(l) + integral P(l_i, l) L(l_i) dl_i at ``wavelengths`` (IR dicts)."""
    light = lambda wl: spectra.evaluate(radiance, wl)  # noqa: E731
    value = spectra.evaluate(bsdf["reflectance"], wavelengths) * light(wavelengths)
    if bsdf.get("fluorescence") is not None:
        value = value + fluo.emitted(bsdf["fluorescence"], light, wavelengths)
    return value


def expected_rgb(bsdf, radiance, obs=colorimetry.GROUND_TRUTH):
    wl = spectra.cie_1931_cmfs()[0]
    return colorimetry.xyz_to_srgb(colorimetry.xyz(expected_radiance(bsdf, radiance, wl), obs))


def applies(scene):
    """Whether ``scene`` is a lone Lambertian sphere under a uniform environment, seen from outside."""
    env, objs = scene.get("environment"), scene["objects"]
    if not env or len(objs) != 1:
        return False
    obj = objs[0]
    b = obj.get("bsdf") or {}
    if obj["shape"]["type"] != "sphere" or b.get("type") != "diffuse" or obj.get("emitter"):
        return False
    cam = np.asarray(scene["camera"]["to_world"], dtype=np.float64)[:3, 3]
    return bool(np.linalg.norm(cam - np.asarray(obj["shape"]["center"])) > obj["shape"]["radius"])


def lone_sphere(m):
    scene, image = m.scene, m.image
    if not applies(scene):
        return []
    env, objs = scene["environment"], scene["objects"]
    obj = objs[0]
    b = obj.get("bsdf") or {}
    kind = "fluorescent " if b.get("fluorescence") is not None else ""
    name = f"lone {kind}Lambertian sphere {obj['name']}: rho L + integral P L"
    expected = expected_rgb(b, env["radiance"])
    h, w = image.shape[:2]
    mask = raycast.pixels_inside(scene["camera"], w, h, objs, 0)
    if mask.sum() < MIN_PIXELS:
        return [_probe(name, expected, None, None, "sigma", None, pixels=int(mask.sum()))]
    px = image[mask][:, :3].astype(np.float64)
    n = len(px)

    def judged(obs):
        e = expected if obs == colorimetry.GROUND_TRUTH else expected_rgb(b, env["radiance"], obs)
        return stats.compare_means(px.mean(axis=0), e, (px - e).std(axis=0, ddof=1) / np.sqrt(n), dof=n - 1)
    stat = judged(colorimetry.GROUND_TRUTH)
    alternatives = {o: judged(o) for o in m.observers if o != colorimetry.GROUND_TRUTH}
    return [_probe(name, expected, px.mean(axis=0), stat["z"], "sigma", stat["pass"], pixels=n, z=stat["z"],
                   stat=stat, alternatives=alternatives)]
