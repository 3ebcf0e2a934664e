"""Polarisation error models: Stokes conventions (frame, handedness), a depolarising renderer, and
a camera polariser whose angle is measured from the other axis."""
import numpy as np

from . import Model, RegionEvidence, channel_parts, reference_model, region_fit

FAMILY = "polarisation"


def _stokes_index(names):
    """{(colour, k): channel index} of the Stokes channels, or {} without Stokes output."""
    return {p: i for i, p in enumerate(channel_parts(names)) if p[1] is not None}


def _rotated(x, ev):
    """The Stokes frame turned by x[0] degrees: S1' = c S1 + s S2, S2' = -s S1 + c S2."""
    idx = _stokes_index(ev.ref_names)
    if not idx:
        return None
    m = ev.ref_mean
    out = m.copy()
    a = np.radians(2 * x[0])
    c, s = np.cos(a), np.sin(a)
    for colour in range(3):
        if (colour, 1) in idx and (colour, 2) in idx:
            i1, i2 = idx[(colour, 1)], idx[(colour, 2)]
            out[..., i1] = c * m[..., i1] + s * m[..., i2]
            out[..., i2] = -s * m[..., i1] + c * m[..., i2]
    return out


def _rotation_fit(ev):
    f = reference_model(_rotated, starts=[[0.0], [45.0], [90.0], [-45.0]])(ev) \
        if ev.has_reference and _stokes_index(ev.ref_names) else None
    if f is not None:
        f.values[0] = (f.values[0] + 45.0) % 180.0 - 45.0  # one turn of the frame is 180 degrees: (-45, 135]
    return f


def _components(scale):
    """Predict with Stokes components 1..3 multiplied by ``scale`` (a tuple of three)."""
    def predict(x, ev):
        idx = _stokes_index(ev.ref_names)
        if not idx:
            return None
        out = ev.ref_mean.copy()
        for (colour, k), i in idx.items():
            if k > 0:
                out[..., i] *= scale[k - 1]
        return out
    return predict


def fresnel_setup(ev):
    """(scene, dielectric, light, rgb render, the light's RGB, block) where the Fresnel probe
    applies (a smooth dielectric rectangle and a rectangle light), else None."""
    from ....exporters import colorimetry
    from .. import compare
    scene, names, image = ev.scene, ev.names, ev.image
    if "R" not in names:
        return None
    objs = scene["objects"]
    diel = [i for i, o in enumerate(objs) if (o.get("bsdf") or {}).get("type") == "dielectric"
            and isinstance(o["bsdf"].get("int_ior"), (int, float)) and o["shape"]["type"] == "rectangle"]
    lights = [i for i, o in enumerate(objs) if o.get("emitter") and o["shape"]["type"] == "rectangle"]
    if not diel or not lights:
        return None
    light = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(objs[lights[0]]["emitter"]["radiance"]))
    rgb = image[..., [names.index(c) for c in "RGB"]].astype(np.float64)
    return scene, diel[0], lights[0], rgb, light, compare.block_size(scene["render"]["spp"], image.shape)


def fresnel_image(scene, di, li, w, h, light, angle):
    """(mask, expected RGB per pixel) of the reflection: through an ideal polariser at ``angle``
    degrees, I = (S0 + S1 cos 2t + S2 sin 2t) / 2, or S0 without one (None)."""
    from ..probes import fresnel
    mask, factor, _eta, _cos = fresnel._expected(scene, di, li, w, h, None)
    if angle is None:
        i = factor[..., 0]
    else:
        t = np.radians(2 * angle)
        i = 0.5 * (factor[..., 0] + factor[..., 1] * np.cos(t) + factor[..., 2] * np.sin(t))
    return mask, np.where(mask[..., None], i[..., None] * light, 0.0)


def _polariser_fit(ev):
    """The camera polariser's angle fitted on the Fresnel probe's region (the closed form of the
    reflection's Stokes vector through a polariser at any angle)."""
    from ..probes import fresnel
    got = fresnel_setup(ev)
    pol = ev.scene["camera"].get("polarizer")
    if got is None or not pol:
        return None
    scene, di, li, rgb, light, block = got
    h, w = rgb.shape[:2]
    mask, factor, _eta, _cos = fresnel._expected(scene, di, li, w, h, None)
    if mask.sum() < 8:
        return None
    declared = float(pol["angle"])

    def predict(x):
        t = np.radians(2 * (declared if x is None else x[0]))
        i = 0.5 * (factor[..., 0] + factor[..., 1] * np.cos(t) + factor[..., 2] * np.sin(t))
        return np.where(mask[..., None], i[..., None] * light, 0.0)
    region = RegionEvidence(rgb, predict(None), mask, block)
    if len(region) < 2:
        return None
    f = region_fit(region, predict, [[declared], [declared + 90.0], [declared + 45.0], [declared - 45.0]])
    if f is not None:
        f.values[0] = (f.values[0] - declared + 45.0) % 180.0 - 45.0 + declared
        other = (90.0 - declared + 45.0) % 180.0 - 45.0
        if abs(f.values[0] - other) <= 2 * max(f.se[0], 0.5):
            f.note = f"the angle measured from the other axis: {other:g} deg for the declared {declared:g} deg"
    return f


MODELS = [
    Model("Stokes frame rotated", FAMILY, ("angle deg",), "reference",
          "S1 and S2 given in a frame turned by this angle (another reference axis or up vector)",
          _rotation_fit),
    Model("S3 sign", FAMILY, (), "reference",
          "circular polarisation of the other handedness (S3 negated)",
          reference_model(_components((1.0, 1.0, -1.0)))),
    Model("depolarised", FAMILY, (), "reference",
          "the renderer writes unpolarised light (S1, S2, S3 zero)",
          reference_model(_components((0.0, 0.0, 0.0)))),
    Model("polariser angle", FAMILY, ("angle deg",), "probe:fresnel",
          "the camera polariser at another angle than declared (e.g. measured from the other axis)",
          _polariser_fit, slow=True),
]
