"""Material error models, through the probes' closed forms (the GGX plates: the scene's truth
recomputed with the material changed) and emitter units (a factor pi on the reference evidence)."""
import copy

import numpy as np

from . import Model, RegionEvidence, reference_model, region_fit

FAMILY = "materials"


def _plates(ev):
    """(scene, plate ids, light ids, rgb render, block) when the GGX probe applies, else None."""
    from .. import compare
    from ..probes import ggx
    found = ggx._applies(ev.scene)
    if not found or "R" not in ev.names:
        return None
    rgb = ev.image[..., [ev.names.index(c) for c in "RGB"]].astype(np.float64)
    return ev.scene, found[0], found[1], rgb, compare.block_size(ev.scene["render"]["spp"], ev.image.shape)


def _plate_model(change, starts=None, bounds=None):
    """A fit on the first GGX plate's region: ``change(bsdf, x)`` edits a copy of the plate's BSDF
    (x: the parameters, [] without any); the expected image is the probe's quadrature of it."""
    def fit(ev):
        from ..probes import ggx
        got = _plates(ev)
        if got is None:
            return None
        scene, plate_ids, light_ids, rgb, block = got
        plate = plate_ids[0]
        h, w = rgb.shape[:2]

        def predict(x):
            sc = scene
            if x is not None:
                sc = copy.deepcopy(scene)
                change(sc["objects"][plate]["bsdf"], x)
            mask, images = ggx.expected_images(sc, plate, light_ids, w, h)
            return np.where(mask[..., None], images["cie1931"], 0.0)
        truth = predict(None)
        mask = np.any(truth != 0, axis=-1)
        region = RegionEvidence(rgb, truth, mask, block)
        if len(region) < 2:
            return None
        f = region_fit(region, predict, starts(scene["objects"][plate]["bsdf"]) if starts else [], bounds)
        return f, scene["objects"][plate]["bsdf"]
    return fit


def _ggx_plates(scene):
    """(plate ids, light ids) of rough conductor rectangles and rectangle lights, whatever else the
    scene holds (a floor): the closed form then gives the plates' direct light only."""
    objs = scene["objects"]
    plates = [i for i, o in enumerate(objs) if (o.get("bsdf") or {}).get("type") == "conductor"
              and o["shape"]["type"] == "rectangle" and (o["bsdf"].get("roughness") or {}).get("alpha", 0) > 0
              and not o["bsdf"].get("thin_film") and not o.get("emitter")]
    lights = [i for i, o in enumerate(objs) if o.get("emitter") and not o.get("bsdf") and o["shape"]["type"] == "rectangle"]
    return (plates, lights) if plates and lights else None


def _reference_plate_model(change, starts):
    """A fit on the reference evidence: the render predicted as the reference plus the change of
    the plates' direct light (the GGX probe's quadrature) when ``change(bsdf, x)`` edits every
    plate's BSDF. The light a plate gets from elsewhere (a floor: the reference minus the
    closed form's direct light, on the plate) changes with the material too, by a factor no
    closed form gives here: where there is such light, a second parameter scales its change
    (``indirect``: 0 unchanged), a nuisance fitted beside the material's parameter."""
    def fit(ev):
        from ..probes import ggx
        found = _ggx_plates(ev.scene) if ev.has_reference else None
        if not found or ev.ref_names[:3] != ["R", "G", "B"]:
            return None
        plates, lights = found
        others = len(ev.scene["objects"]) > len(plates) + len(lights)
        h, w = ev.ref_mean.shape[:2]
        cache = {}

        def direct(x):
            key = None if x is None else tuple(np.round(np.asarray(x, dtype=np.float64), 12))
            if key not in cache:
                sc = ev.scene if x is None else copy.deepcopy(ev.scene)
                total = np.zeros((h, w, 3))
                for plate in plates:
                    if x is not None:
                        change(sc["objects"][plate]["bsdf"], x)
                    mask, images = ggx.expected_images(sc, plate, lights, w, h)
                    total += np.where(mask[..., None], images["cie1931"], 0.0)
                cache[key] = total
            return cache[key]
        base = direct(None)
        on_plate = np.any(base != 0, axis=-1)[..., None]
        indirect = np.where(on_plate, ev.ref_mean[..., :3] - base, 0.0)

        def predict(x, ev):
            out = ev.ref_mean.copy()
            out[..., :3] += direct(x[:1]) - base + (x[1] * indirect if others else 0.0)
            return out
        x0 = [s + ([0.0] if others else []) for s in starts(ev.scene["objects"][plates[0]]["bsdf"])]
        bounds = ([1e-3, -1.0], [1.0, 1.0]) if others else ([1e-3], [1.0])
        return reference_model(predict, starts=x0, bounds=bounds)(ev)
    return fit


def _set_alpha(bsdf, x):
    bsdf["roughness"]["alpha"] = float(x[0])


def _alpha_fit(ev):
    """On the reference evidence where there is one (the plates' change of direct light), else on
    the GGX probe's region."""
    starts = lambda b: [[b["roughness"]["alpha"]]]  # noqa: E731
    f = _reference_plate_model(_set_alpha, starts)(ev)
    if f is None:
        got = _plate_model(_set_alpha, starts=starts, bounds=([1e-3], [1.0]))(ev)
        f = None if got is None else got[0]
    found = _ggx_plates(ev.scene)
    if f is None or not found:
        return f
    declared = float(ev.scene["objects"][found[0][0]]["bsdf"]["roughness"]["alpha"])
    for label, value in (("sqrt(alpha): the renderer squares it", declared ** 0.5),
                         ("alpha^2: the renderer takes roughness for alpha", declared ** 2)):
        if abs(f.values[0] - value) <= 2 * f.se[0]:
            f.note = f"alpha {value:.4g} = {label}"
    return f


def _beckmann(bsdf, x):
    if bsdf["roughness"]["distribution"] != "ggx":
        raise _NotApplicable
    bsdf["roughness"]["distribution"] = "beckmann"


def _no_k(bsdf, x):
    from ....exporters import spectra
    if "material" in bsdf:
        eta, _k = spectra.named_conductor(bsdf.pop("material"))
        bsdf["eta"] = eta
    bsdf["k"] = {"type": "constant", "value": 0.0}


class _NotApplicable(Exception):
    pass


def _fixed(change):
    def fit(ev):
        try:
            got = _plate_model(change)(ev)
        except _NotApplicable:
            return None
        return None if got is None else got[0]
    return fit


def _emitter_units(ev):
    """The reference evidence with the render pi (or 1/pi) times the reference: no free parameter;
    the freely fitted scale is reported beside it (its value and standard error)."""
    from .image import _uniform
    free = reference_model(_uniform, starts=[[1.0]])(ev)
    if free is None:
        return None
    factor = np.pi if free.values[0] > 1 else 1 / np.pi
    f = reference_model(lambda x, e: _uniform([factor], e))(ev)
    f.values, f.se, f.note = free.values, free.se, f"fixed factor {factor:.6g}"
    return f


def _ior_fit(ev):
    """The dielectric's IOR fitted on the Fresnel probe's region (the reflection through the
    camera's polariser, or unpolarised): the closed form at each trial IOR."""
    from .polarisation import fresnel_image, fresnel_setup
    got = fresnel_setup(ev)
    if got is None:
        return None
    scene, di, li, rgb, light, block = got
    h, w = rgb.shape[:2]
    pol = scene["camera"].get("polarizer")
    angle = None if not pol else float(pol["angle"])
    declared = float(scene["objects"][di]["bsdf"]["int_ior"])
    mask, truth = fresnel_image(scene, di, li, w, h, light, angle)
    if mask.sum() < 8:
        return None

    def predict(x):
        if x is None:
            return truth
        sc = copy.deepcopy(scene)
        sc["objects"][di]["bsdf"]["int_ior"] = float(x[0])
        return np.where(mask[..., None], fresnel_image(sc, di, li, w, h, light, angle)[1], 0.0)
    region = RegionEvidence(rgb, truth, mask, block)
    if len(region) < 2:
        return None
    return region_fit(region, predict, [[declared]], bounds=([1.0], [4.0]))


MODELS = [
    Model("GGX alpha", FAMILY, ("alpha", "indirect"), "reference+ggx",
          "the microfacet roughness is not the declared alpha (or alpha vs alpha squared conventions)",
          lambda ev: _alpha_fit(ev), slow=True),
    Model("Beckmann for GGX", FAMILY, (), "probe:ggx",
          "a Beckmann distribution rendered where GGX is declared", _fixed(_beckmann), slow=True),
    Model("conductor without k", FAMILY, (), "probe:ggx",
          "the conductor's extinction coefficient k dropped (only eta used)", _fixed(_no_k), slow=True),
    Model("dielectric IOR", FAMILY, ("ior",), "probe:fresnel",
          "the dielectric's index of refraction is not the declared one (another IOR, or one of another medium)",
          _ior_fit, slow=True),
    Model("emitter radiance x pi", FAMILY, ("factor",), "reference",
          "emitter units: radiance where exitance was due, or the other way (a factor pi)",
          _emitter_units, deviation=lambda f: {"scale": float(np.pi if f.values[0] > 1 else 1 / np.pi), "scale_se": 0.0}),
]
