"""Blender's own data -> the scene IR: the formulas of the conversion, without bpy.

extract_blender.py reads a Blender scene (the only bpy import of exporters/) into plain values
and calls these where a material, light or world has no spectral annotation (an annotation always
wins). Every conversion that is not exact, and everything that cannot be carried over, is a
warning ``(object, field, message)``: nothing is lost silently. docs/scene-format.md, section 11,
states every formula; the radiometric ones were measured with Cycles (bpy 5.0.1) and are checked
by tests/exporters/test_blender_conversion.py.

Colour: Blender's colours are linear Rec.709/sRGB (the IR's film space, section 9).
- A reflectance colour is uplifted to a smooth spectrum with Jakob and Hanika 2019 (colour-science's
  ``colour.recovery``, method "Jakob 2019"), fitted under D65 (the sRGB white); a grey (r = g = b)
  is the constant reflectance of that value, which is its exact smoothest uplift.
- An emission colour c with a radiometric factor s is s max(c) R(l) D65(l) / Y(D65), R the
  reflectance uplift of c / max(c): white is D65, which the IR's film shows as RGB (1, 1, 1)
  (the sRGB white), so a white Blender light of radiance L renders as L in every channel, as in
  Cycles; a grey is the named table cie_d65, scaled.
- A blackbody (a Blackbody node, a light's temperature) stays a blackbody of that temperature,
  scaled to Cycles' normalisation (the node's colour has luminance Y = 1, measured).
"""
import math
from functools import lru_cache

import numpy as np

from . import spectra

UPLIFT_METHOD = "Jakob and Hanika 2019 (colour.recovery 'Jakob 2019', fitted under D65)"
CONDUCTOR_FIT = "Gulbrandsen 2014 (JCGT 3(4)): eta, k per wavelength from the uplifted base colour r and edge tint g"
SRGB_TO_XYZ = np.linalg.inv(np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415],
                                      [0.0557, -0.2040, 1.0570]]))
GRID_STEP = 5.0
NAMED_METAL_DE00 = 3.0  # a metallic base colour this close (CIEDE2000) to a named conductor's F0 becomes it
DISK_SEGMENTS = 128  # a disk/ellipse area light is this polygon, scaled to the ellipse's exact area


def grid():
    return np.arange(spectra.LAMBDA_MIN, spectra.LAMBDA_MAX + 0.5 * GRID_STEP, GRID_STEP)


def _rounded(xs, digits=6):
    return [round(float(x), digits) for x in xs]


@lru_cache(maxsize=1)
def _d65_y():
    """Y of cie_d65 (1.0 at 560 nm) by the IR's film rule (section 9)."""
    wl, _x, y, _z = spectra.cie_1931_cmfs()
    return float(np.trapz(spectra.evaluate({"type": "named", "name": "cie_d65"}, wl) * y, wl) / np.trapz(y, wl))


def spectrum_rgb(values_at, illuminated=True):
    """Linear sRGB of a spectrum (a function of wavelength) by the IR's film rule: as a reflectance
    under D65 of luminance 1 (``illuminated``) or as an emission."""
    wl, x, y, z = spectra.cie_1931_cmfs()
    v = values_at(wl)
    if illuminated:
        v = v * spectra.evaluate({"type": "named", "name": "cie_d65"}, wl) / _d65_y()
    xyz = np.array([np.trapz(v * c, wl) for c in (x, y, z)]) / np.trapz(y, wl)
    return np.linalg.solve(SRGB_TO_XYZ, xyz)


@lru_cache(maxsize=512)
def _jakob(rgb):
    import colour
    from colour.recovery import XYZ_to_sd
    shape = colour.SpectralShape(spectra.LAMBDA_MIN, spectra.LAMBDA_MAX, GRID_STEP)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    d65 = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    sd, _error = XYZ_to_sd(SRGB_TO_XYZ @ np.asarray(rgb), method="Jakob 2019", cmfs=cmfs, illuminant=d65,
                           additional_data=True)
    return tuple(float(v) for v in np.clip(sd.values, 0.0, 1.0))


def reflectance(rgb):
    """(IR spectrum, the uplift's own round trip in linear sRGB) of a reflectance colour; values
    outside [0, 1] are clipped first (the caller warns)."""
    c = tuple(round(float(v), 6) for v in np.clip(rgb, 0.0, 1.0))
    if max(c) - min(c) < 1e-6:
        return {"type": "constant", "value": c[0]}, np.array(c)
    values = _jakob(c)
    spec = {"type": "sampled", "wavelengths": _rounded(grid(), 3), "values": _rounded(values),
            "source": f"{UPLIFT_METHOD} from linear sRGB ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g})"}
    return spec, spectrum_rgb(lambda wl: spectra.evaluate(spec, wl))


def emission(rgb, scale):
    """IR spectrum of an emission colour ``rgb`` (linear sRGB) times the radiometric factor
    ``scale``: renders as scale * rgb (see the module docstring)."""
    c = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, None)
    peak = float(c.max())
    if peak <= 0 or scale <= 0:
        return {"type": "constant", "value": 0.0}
    if c.max() - c.min() < 1e-6 * peak:
        return {"type": "named", "name": "cie_d65", "scale": round(float(scale) * peak / _d65_y(), 9)}
    shape = np.asarray(_jakob(tuple(round(float(v), 6) for v in c / peak)))
    wl = grid()
    d65 = spectra.evaluate({"type": "named", "name": "cie_d65"}, wl) / _d65_y()
    return {"type": "sampled", "wavelengths": _rounded(wl, 3), "values": _rounded(scale * peak * shape * d65, 9),
            "source": f"{UPLIFT_METHOD} of the colour ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g}) times D65, x {scale:.6g}"}


def emission_note(spec):
    """How an emission spectrum from ``emission`` was made and what it renders as (linear sRGB by
    the format's film rule): for a warning."""
    made = "cie_d65 scaled (white is D65, the sRGB white)" if spec["type"] == "named" else (
        "0" if spec["type"] == "constant" else f"an emission spectrum ({UPLIFT_METHOD}, times D65)")
    return f"{made}; renders as {fmt(spectrum_rgb(lambda wl: spectra.evaluate(spec, wl), illuminated=False))}"


def blackbody(temperature, luminance):
    """A blackbody of ``temperature`` K scaled to luminance Y = ``luminance`` (Cycles' Blackbody
    node is a colour of luminance 1: measured)."""
    wl, _x, y, _z = spectra.cie_1931_cmfs()
    unit = {"type": "blackbody", "temperature": float(temperature), "scale": 1.0}
    y_unit = float(np.trapz(spectra.evaluate(unit, wl) * y, wl) / np.trapz(y, wl))
    return {"type": "blackbody", "temperature": float(temperature), "scale": round(float(luminance) / y_unit, 9)}


def tinted_blackbody(temperature, colour, scale):
    """(IR spectrum, note) of a blackbody light whose colour is not white: Cycles multiplies the
    Blackbody colour (luminance 1) by the colour channel by channel; here the blackbody is
    multiplied by the colour's smooth reflectance uplift (a filter, Jakob and Hanika 2019) and
    scaled to Cycles' luminance, scale x Y(blackbody rgb x colour). The note compares the RGB it
    renders as with Cycles' product."""
    colour = np.clip(np.asarray(colour, dtype=np.float64), 0.0, None)
    unit = blackbody(temperature, 1.0)
    bb_rgb = spectrum_rgb(lambda wl: spectra.evaluate(unit, wl), illuminated=False)
    cycles = scale * bb_rgb * colour
    peak = float(colour.max())
    if peak <= 0 or scale <= 0:
        return {"type": "constant", "value": 0.0}, "black"
    wl = grid()
    values = spectra.evaluate(unit, wl) * np.asarray(_jakob(tuple(round(float(v), 6) for v in colour / peak)))
    spec = {"type": "sampled", "wavelengths": _rounded(wl, 3), "values": list(values)}
    spec["values"] = _rounded(np.asarray(values) * luminance(cycles) / luminance(
        spectrum_rgb(lambda w: spectra.evaluate(spec, w), illuminated=False)), 9)
    spec["source"] = (f"blackbody {temperature:g} K times {UPLIFT_METHOD} of the colour ({colour[0]:.4g}, "
                      f"{colour[1]:.4g}, {colour[2]:.4g}), luminance {luminance(cycles):.6g}")
    back = spectrum_rgb(lambda w: spectra.evaluate(spec, w), illuminated=False)
    return spec, f"renders as {fmt(back)} where Cycles multiplies to {fmt(cycles)}"


def luminance(rgb):
    """Y of a linear sRGB colour (the IEC matrix's second row of its inverse)."""
    return float(SRGB_TO_XYZ[1] @ np.asarray(rgb, dtype=np.float64))


# --- lights: Blender's watts to the IR's radiometry (Cycles' conventions, measured with bpy 5.0.1)


def point_intensity(power):
    """Point and spot lights: radiant intensity I = P / (4 pi) per steradian."""
    return power / (4 * math.pi)


def area_radiance(power, area, normalize=True):
    """Area lights: radiance L = P / (pi A) (Lambertian, one-sided); with Blender's Normalize off
    the power is not divided by the area: L = P / pi."""
    return power / (math.pi * (area if normalize else 1.0))


def sun_irradiance(strength):
    """Sun: its strength is the irradiance E in W/m^2 on a surface facing it."""
    return strength


def ellipse_polygon(sx, sy, n=DISK_SEGMENTS):
    """(vertices, faces) of an ellipse with half-axes sx, sy in the local z = 0 plane, its normal
    +Z, as a fan of n triangles, scaled so its area is exactly pi sx sy."""
    k = math.sqrt(math.pi / (0.5 * n * math.sin(2 * math.pi / n)))
    verts = [[0.0, 0.0, 0.0]] + [[k * sx * math.cos(2 * math.pi * i / n), k * sy * math.sin(2 * math.pi * i / n), 0.0]
                                 for i in range(n)]
    faces = [[0, 1 + i, 1 + (i + 1) % n] for i in range(n)]
    return verts, faces


def spot_cone(spot_size, spot_blend):
    """(cutoff_angle, beam_width) in degrees of Blender's spot (full cone angle in radians, blend
    0-1): the cone's half-angle, and the half-angle where the blend's falloff starts (Blender
    blends smoothly over the outer ``blend`` part of the cone; the IR falls linearly in angle)."""
    cutoff = math.degrees(spot_size / 2)
    return cutoff, cutoff * (1.0 - min(max(spot_blend, 0.0), 1.0))


# --- conductors


@lru_cache(maxsize=1)
def named_metal_colours():
    """{name: linear sRGB of the conductor's normal-incidence reflectance under D65}."""
    out = {}
    for name in spectra.NAMED_CONDUCTORS:
        eta, k = spectra.named_conductor(name)

        def f0(wl, eta=eta, k=k):
            n, kk = spectra.evaluate(eta, wl), spectra.evaluate(k, wl)
            return ((n - 1) ** 2 + kk ** 2) / ((n + 1) ** 2 + kk ** 2)
        out[name] = spectrum_rgb(f0)
    return out


def _de00(rgb_a, rgb_b):
    import colour
    lab = [colour.XYZ_to_Lab(SRGB_TO_XYZ @ np.clip(np.asarray(c, float), 0, None),
                             colour.XYZ_to_xy(SRGB_TO_XYZ @ np.ones(3))) for c in (rgb_a, rgb_b)]
    return float(colour.delta_E(lab[0], lab[1], method="CIE 2000"))


def nearest_named_metal(rgb):
    """(name, CIEDE2000) of the named conductor whose F0 colour is nearest to ``rgb``."""
    return min(((n, _de00(rgb, c)) for n, c in named_metal_colours().items()), key=lambda t: t[1])


def conductor(base, edge_tint):
    """(IR conductor dict without roughness, message): a named conductor when the base colour is
    within NAMED_METAL_DE00 of one's F0 (and the edge tint is white), else eta and k fitted with
    Gulbrandsen 2014 to the uplifted base colour (F0) and edge tint."""
    base = np.clip(np.asarray(base, float), 0.0, 1.0)
    tint = np.clip(np.asarray(edge_tint, float), 0.0, 1.0)
    name, de = nearest_named_metal(base)
    if de <= NAMED_METAL_DE00 and tint.min() > 0.999:
        return {"type": "conductor", "material": name}, (
            f"metallic with base colour ({base[0]:.3g}, {base[1]:.3g}, {base[2]:.3g}) is within CIEDE2000 {de:.2f} "
            f"(<= {NAMED_METAL_DE00}) of the measured conductor {name}'s normal-incidence colour: rendered as {name}")
    r_spec, _ = reflectance(base)
    g_spec, _ = reflectance(tint)
    wl = grid()
    r = np.clip(spectra.evaluate(r_spec, wl), 0.0, 0.999)
    g = np.clip(spectra.evaluate(g_spec, wl), 0.0, 1.0)
    sr = np.sqrt(r)
    n = g * (1 - r) / (1 + r) + (1 - g) * (1 + sr) / (1 - sr)
    k = np.sqrt(np.clip((r * (n + 1) ** 2 - (n - 1) ** 2) / (1 - r), 0.0, None))
    src = f"{CONDUCTOR_FIT}; base colour ({base[0]:.4g}, {base[1]:.4g}, {base[2]:.4g}), edge tint ({tint[0]:.4g}, {tint[1]:.4g}, {tint[2]:.4g})"
    out = {"type": "conductor",
           "eta": {"type": "sampled", "wavelengths": _rounded(wl, 3), "values": _rounded(n), "source": src},
           "k": {"type": "sampled", "wavelengths": _rounded(wl, 3), "values": _rounded(k), "source": src}}
    return out, (f"metallic: a conductor fitted to base colour and edge tint by {CONDUCTOR_FIT.split(':')[0]} "
                 f"(nearest measured conductor {name} is CIEDE2000 {de:.1f} away); Blender's F82-tint Fresnel differs "
                 "from it towards grazing angles")


def ggx_alpha(roughness):
    """Blender's roughness r -> GGX alpha = r^2 (Blender's convention, docs/scene-format.md 6.2)."""
    return round(float(roughness) ** 2, 6)


# --- shader nodes: {input name: (value, the bl_idname of the node linked into it or None)}, read by
# extract_blender.py; each conversion returns (bsdf or None, emitter or None) and calls
# warn(field, message) for every conversion and loss.


# the shader inputs whose Image Texture converts (docs/scene-format.md 6.7): a base colour
TEXTURED_INPUTS = ("Base Color", "Color")


class Inputs:
    """A node's inputs; ``get`` warns when the input is linked (a texture, a mix): its unlinked
    value is what is used, unless the caller took the input's image texture (``texture``)."""

    def __init__(self, values, warn, images=None):
        self.values, self.warn, self.images = values, warn, dict(images or {})
        self.taken = set()

    def texture(self, name):
        """The IR texture an Image Texture node linked into ``name`` converts to (extract_blender.py
        ``_image_texture``: file, colour_space, filter and the private _mean, _base_dir, _image), or
        None."""
        tex = self.images.get(name)
        if tex is not None:
            self.taken.add(name)
        return tex

    def get(self, name, default=None):
        if name not in self.values:
            return default
        value, linked = self.values[name]
        if linked and name not in self.taken:
            self.warn(f"inputs[{name}]", f"linked to a {linked} node (textures and node networks are not converted): "
                                          f"its unlinked value {fmt(value)} is used instead")
        return value


def fmt(v):
    """A number or colour for a message: 4 significant digits."""
    if isinstance(v, (tuple, list, np.ndarray)):
        return "(" + ", ".join(f"{float(x):.4g}" for x in v) + ")"
    return f"{float(v):.4g}" if isinstance(v, (int, float, np.floating)) else repr(v)


def colour_reflectance(rgb, field, warn, what="reflectance"):
    rgb = np.asarray(rgb, dtype=np.float64)[:3]
    if rgb.min() < 0 or rgb.max() > 1:
        warn(field, f"colour {fmt(rgb)} outside [0, 1] clipped (a {what} of at most 1)")
    spec, back = reflectance(rgb)
    if spec["type"] == "constant":
        warn(field, f"grey {fmt(rgb)} -> constant {what} {spec['value']:.4g} (exact)")
    else:
        off = float(np.abs(back - np.clip(rgb, 0, 1)).max())
        warn(field, f"colour {fmt(rgb)} uplifted to a smooth {what} spectrum by {UPLIFT_METHOD}; it renders under "
                    f"D65 as {fmt(back)} (largest channel difference {off:.3g})")
    return spec


def _roughness(rough, distribution, field, warn):
    if rough is None or rough <= 0:
        return None
    alpha = ggx_alpha(rough)
    dist = "beckmann" if distribution == "BECKMANN" else "ggx"
    note = ""
    if distribution == "MULTI_GGX":
        note = ("; Blender's Multiscatter GGX keeps the energy of multiple scattering between microfacets, the IR's "
                "GGX (single scattering) loses it: darker at high roughness")
    elif distribution not in (None, "GGX", "BECKMANN"):
        note = f"; distribution {distribution} rendered as GGX"
    warn(field, f"roughness {rough:.4g} -> {dist} alpha = roughness^2 = {alpha:.4g}{note}")
    return {"distribution": dist, "alpha": alpha}


def surface_emission(inp, colour_key, strength_key, warn):
    strength = float(inp.get(strength_key, 0.0) or 0.0)
    colour = np.asarray(inp.get(colour_key, (1, 1, 1)), dtype=np.float64)[:3]
    if strength < 0:
        warn(f"inputs[{strength_key}]", f"negative strength {strength:.4g}: Blender subtracts light, the IR's emission "
                                        "is >= 0: not emitted")
        return None
    if strength <= 0 or colour.max() <= 0:
        return None
    spec = emission(colour, strength)
    warn(f"inputs[{strength_key}]", f"emission colour {fmt(colour)} x strength {strength:.4g} -> an area emitter of "
                                    f"radiance strength x colour (Cycles' convention: strength 1 is radiance 1): "
                                    f"{emission_note(spec)}")
    return {"type": "area", "radiance": spec}


# inputs of the Principled BSDF that add a lobe the IR has not, and the value that turns it off
PRINCIPLED_LOBES = (("Coat Weight", 0.0, "a clear coat"), ("Sheen Weight", 0.0, "sheen"),
                    ("Subsurface Weight", 0.0, "subsurface scattering"), ("Anisotropic", 0.0, "anisotropic roughness"),
                    ("Thin Film Thickness", 0.0, "a thin film on a dielectric"), ("Alpha", 1.0, "transparency (alpha)"),
                    ("Diffuse Roughness", 0.0, "rough (Oren-Nayar-like) diffuse"))


def f0_from_ior(ior):
    """Normal-incidence reflectance ((n - 1) / (n + 1))^2 of a dielectric of relative index n."""
    return ((ior - 1.0) / (ior + 1.0)) ** 2


def ior_from_f0(f0):
    """The relative index whose normal-incidence reflectance is ``f0`` (< 1): (1 + sqrt f0) / (1 - sqrt f0)."""
    s = math.sqrt(min(max(f0, 0.0), 0.999999))
    return (1.0 + s) / (1.0 - s)


def specular_ior(ior, level):
    """The index of Principled's specular layer with Specular IOR Level ``level``: Cycles replaces
    the IOR by the one whose normal-incidence reflectance is 2 level F0(IOR) (level 0.5 keeps it;
    an IOR below 1 stays below 1). Blender manual, Principled BSDF, "Specular IOR Level"."""
    if abs(level - 0.5) < 1e-9 or ior <= 0:
        return ior
    eta = ior_from_f0(f0_from_ior(ior) * 2.0 * level)
    return 1.0 / eta if ior < 1.0 else eta


COATED_APPROXIMATION = (
    "Principled is not exactly that model: Blender layers the specular lobe over the diffuse base by albedo "
    "scaling (the base weighted by one minus the specular layer's directional albedo), the coat by the Fresnel "
    "transmittances in and out and the series of internal reflections (docs/scene-format.md 6.6); a smooth layer "
    "under a uniform sky gives F + rho (1 - F) in both, their angular shape under a light differs")


def coated(reflectance, ior, level, tint, rough, warn):
    """Principled's dielectric specular layer over its diffuse base -> the IR's coated_diffuse (the
    caller adds the roughness): a coat of the IOR Cycles renders (``specular_ior``), outside IOR 1.0
    as Blender's; the warnings say what is approximated."""
    eta = specular_ior(ior, level)
    level_note = "" if abs(level - 0.5) < 1e-9 else (
        f"; Specular IOR Level {level:.4g} scales its normal-incidence reflectance {f0_from_ior(ior):.4g} by "
        f"{2 * level:.4g}: a coat of IOR {eta:.6g}")
    warn("inputs[Specular IOR Level]",
         f"the dielectric specular layer (IOR {ior:.4g}, Specular IOR Level {level:.4g}, roughness {rough:.4g}) over "
         f"the base colour -> a coated diffuse (Mitsuba 3's {'rough' if rough > 0 else ''}plastic; outside IOR 1.0, "
         f"as Blender){level_note}; approximated: {COATED_APPROXIMATION}")
    tint = np.asarray(tint if tint is not None else (1, 1, 1), dtype=np.float64)[:3]
    if np.abs(tint - 1).max() > 1e-3:
        warn("inputs[Specular Tint]", f"Specular Tint {fmt(tint)} tints Blender's highlight at normal incidence; the "
                                      "coat is colourless: its highlight is rendered untinted")
    return {"type": "coated_diffuse", "reflectance": reflectance, "int_ior": round(eta, 6), "ext_ior": 1.0}


def textured_reflectance(inp, name, warn):
    """(reflectance spectrum, reflectance_texture or None) of a colour input: with an image texture
    linked into it, the texture (its file, colour space and filter) and its mean colour uplifted
    as the BSDF's reflectance; else the socket's colour."""
    tex = inp.texture(name)
    if tex is None:
        return colour_reflectance(inp.get(name, (0.8, 0.8, 0.8)), f"inputs[{name}]", warn), None
    mean = np.clip(np.asarray(tex["_mean"], dtype=np.float64), 0.0, 1.0)
    spec, _ = reflectance(mean)
    warn(f"inputs[{name}]", f"image texture {tex['_image']!r} ({tex['file']}, {tex['colour_space']}, "
                            f"{tex['filter']}) on the mesh's UVs: each texel's linear sRGB is uplifted by the renderer "
                            f"(Mitsuba: Jakob and Hanika's coefficients; pbrt-v4: its RGBAlbedoSpectrum); the "
                            f"reflectance recorded beside it is its mean colour {fmt(mean)}, uplifted by {UPLIFT_METHOD}")
    return spec, {k: v for k, v in tex.items() if not k.startswith("_")}


def principled(inp, distribution):
    """Principled BSDF -> (bsdf, emitter): metallic >= 0.5 a conductor, else transmission >= 0.5 a
    dielectric, else a coated diffuse (its specular layer over the base colour), or a diffuse where
    Specular IOR Level is 0."""
    warn = inp.warn
    metallic = float(inp.get("Metallic", 0.0))
    transmission = float(inp.get("Transmission Weight", 0.0))
    texture = None
    if metallic < 0.5 and transmission < 0.5:  # a diffuse base: its colour may be an image texture
        reflectance, texture = textured_reflectance(inp, "Base Color", warn)
    base = np.asarray(inp.get("Base Color", (0.8, 0.8, 0.8)), dtype=np.float64)[:3]
    rough = float(inp.get("Roughness", 0.5))
    for key, off, what in PRINCIPLED_LOBES:
        v = inp.get(key)
        if v is not None and abs(float(v) - off) > 1e-6:
            warn(f"inputs[{key}]", f"{key} {float(v):.4g}: {what} has no IR counterpart: not rendered")
    if inp.values.get("Normal", (None, None))[1]:
        warn("inputs[Normal]", f"a normal/bump map ({inp.values['Normal'][1]}) is not converted: the geometric normal is used")
    if 0 < metallic < 1:
        warn("inputs[Metallic]", f"metallic {metallic:.4g}: the IR does not mix metal and dielectric: taken as "
                                 f"{'1 (a conductor)' if metallic >= 0.5 else '0'}")
    if metallic >= 0.5:
        out, msg = conductor(base, inp.get("Specular Tint", (1, 1, 1))[:3])
        warn("inputs[Base Color]", msg)
    elif transmission >= 0.5:
        ior = float(inp.get("IOR", 1.5))
        out = {"type": "dielectric", "int_ior": round(ior, 6), "ext_ior": 1.0}
        warn("inputs[Transmission Weight]", f"transmission {transmission:.4g} -> a clear dielectric of IOR {ior:.4g} "
                                            "(outside: vacuum, IOR 1.0, as Blender)"
             + ("" if transmission >= 1 else "; the IR does not mix it with the diffuse base: taken as 1"))
        if np.abs(base - 1).max() > 1e-3:
            warn("inputs[Base Color]", f"base colour {fmt(base)} tints transmission in Blender; the IR's dielectric is "
                                       "clear: the tint is lost")
    else:
        if 0 < transmission:
            warn("inputs[Transmission Weight]", f"transmission {transmission:.4g} < 0.5: taken as 0 (a diffuse)")
        level = float(inp.get("Specular IOR Level", 0.5))
        if level > 0:
            out = coated(reflectance, float(inp.get("IOR", 1.5)), level, inp.get("Specular Tint", (1, 1, 1)), rough,
                         warn)
        else:
            out = {"type": "diffuse", "reflectance": reflectance}
            warn("inputs[Specular IOR Level]", "Specular IOR Level 0: no specular layer: a diffuse of the base colour")
        if texture is not None:
            out["reflectance_texture"] = texture
    if out["type"] != "diffuse":
        r = _roughness(rough, distribution, "inputs[Roughness]", warn)
        if r:
            out["roughness"] = r
    return out, surface_emission(inp, "Emission Color", "Emission Strength", warn)


def diffuse_node(inp, distribution):
    reflectance, texture = textured_reflectance(inp, "Color", inp.warn)
    out = {"type": "diffuse", "reflectance": reflectance}
    if texture is not None:
        out["reflectance_texture"] = texture
    if float(inp.get("Roughness", 0.0)) > 0:
        inp.warn("inputs[Roughness]", f"Oren-Nayar roughness {float(inp.get('Roughness')):.4g}: the IR's diffuse is Lambertian")
    return out, None


def glass_node(inp, distribution):
    ior = float(inp.get("IOR", 1.5))
    out = {"type": "dielectric", "int_ior": round(ior, 6), "ext_ior": 1.0}
    inp.warn("inputs[IOR]", f"a clear dielectric of IOR {ior:.4g} (outside: vacuum, IOR 1.0, as Blender)")
    colour = np.asarray(inp.get("Color", (1, 1, 1)), dtype=np.float64)[:3]
    if np.abs(colour - 1).max() > 1e-3:
        inp.warn("inputs[Color]", f"colour {fmt(colour)} tints the glass in Blender; the IR's dielectric is clear: lost")
    r = _roughness(float(inp.get("Roughness", 0.0)), distribution, "inputs[Roughness]", inp.warn)
    if r:
        out["roughness"] = r
    return out, None


def metal_node(inp, distribution, colour_key="Base Color", tint_key="Edge Tint"):
    out, msg = conductor(inp.get(colour_key, (0.8, 0.8, 0.8))[:3], (inp.get(tint_key, (1, 1, 1)) or (1, 1, 1))[:3])
    inp.warn(f"inputs[{colour_key}]", msg)
    r = _roughness(float(inp.get("Roughness", 0.0)), distribution, "inputs[Roughness]", inp.warn)
    if r:
        out["roughness"] = r
    return out, None


def glossy_node(inp, distribution):
    inp.warn("inputs[Color]", "Glossy BSDF (a tinted mirror without Fresnel) -> a conductor of that normal-incidence colour")
    return metal_node(inp, distribution, "Color", "(none)")


def emission_node(inp, distribution):
    return None, surface_emission(inp, "Color", "Strength", inp.warn)


# Blender shader node -> conversion; any other node at a material's Surface is substituted (a warning)
SURFACE_NODES = {"ShaderNodeBsdfPrincipled": principled, "ShaderNodeBsdfDiffuse": diffuse_node,
                 "ShaderNodeBsdfGlass": glass_node, "ShaderNodeBsdfMetallic": metal_node,
                 "ShaderNodeBsdfAnisotropic": glossy_node, "ShaderNodeBsdfGlossy": glossy_node,
                 "ShaderNodeEmission": emission_node}
