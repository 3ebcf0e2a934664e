"""The one rule by which the RGB backends (Cycles, LuxCore) reduce the IR's spectra to RGB.

Every value is linear sRGB (Rec. 709 primaries, D65 white), the colour space of the Mitsuba film
the references are rendered with, and of Blender's default scene-linear space.

- **Emitted radiance** (area lights, the uniform environment) keeps its absolute units:
  rgb(L) = M * XYZ(L), XYZ(L) = integral L(l) [x_bar, y_bar, z_bar](l) dl / integral y_bar dl,
  i.e. exactly what a spectral film records for that spectrum seen directly (colorimetry.py; a
  flat spectrum 1 has Y = 1). M is sRGB's XYZ -> RGB matrix. Negative components (a spectrum
  outside the sRGB gamut) are clipped to 0 and reported.
- **Reflectance** rho(l) (diffuse albedo) is reduced as seen under the sRGB white, CIE D65,
  divided by that white:  rgb(rho) = rgb(rho * D65) / rgb(D65)  (component-wise), so a perfect
  white is (1, 1, 1). Components are clipped to [0, 1] (an albedo an RGB renderer can use) and
  the clipping is reported. D65 is used whatever the scene's light: a production RGB pipeline
  has one fixed colour space (sRGB textures are reflectances under D65), and adapting the
  reduction to a scene's illuminant would be undefined with several lights and would hide the
  very error this backend pair measures.
- **Conductors** (eta, k spectra, or a named table: Mitsuba 3's own ``data/ior/<name>.{eta,k}.spd``
  files shipped in the mitsuba package, read here, so both sides use the same data) are reduced
  through what is observed, the Fresnel reflectance: per channel c, (eta_c, k_c) minimise
  sum_theta w(theta) [F(eta_c, k_c, theta) - rgb_c(F(eta(l), k(l), theta))]^2 over incidence
  angles 0..89.5 degrees, with w = cos(theta) sin(theta) (the weight of each angle in a
  hemispherical albedo), where rgb(F(theta)) is the reflectance rule above applied to the
  spectral unpolarised Fresnel reflectance at that angle. Evaluating eta and k at one
  "representative" wavelength per channel was rejected: copper's eta and k change fastest inside
  the green channel (its absorption edge near 570 nm), so a single wavelength misrepresents the
  channel's reflectance; fitting the reduced reflectance curve reproduces, by construction, the
  single-bounce colour under D65 at every angle, up to the fit's residual (reported per object).

Expected error. The rule is exact (up to float rounding) for one diffuse or conductor reflection
of light whose spectrum is D65 (any scale): the renderer multiplies rgb(L) = s (1, 1, 1) by
rgb(rho), which is rgb(rho * L) by construction. Everywhere else an RGB renderer computes
rgb(L) * rgb(rho) where the truth is rgb(L * rho): the error depends on how far L is from D65
and on how the spectra vary inside each channel. ``predicted_error`` computes it for a single
reflection (no renderer involved); for the ColorChecker under D50 it is 0.02..2.6 dE00 per patch,
0.75 on average (orange 2.57, orange-yellow 2.43; benchmarks/RGB.md, tests/backends/test_rgb_backends.py).
Multiple bounces compound it. Gamut clipping adds error for out-of-gamut reflectances: the
ColorChecker cyan patch is R = -0.033 in sRGB under D65, clipped to 0, 2.43 dE00 even under D65.
"""
from functools import lru_cache

import numpy as np

from . import colorimetry, spectra

REFERENCE_WHITE = {"type": "named", "name": "cie_d65", "scale": 1.0}
FIT_ANGLES_DEG = np.linspace(0.0, 89.5, 180)


class ReductionError(ValueError):
    """A spectrum that cannot be reduced; ``field`` names the IR field."""

    def __init__(self, field, message):
        super().__init__(message)
        self.field = field


def _srgb_of(values_at_cmf_wavelengths):
    return colorimetry.xyz_to_srgb(colorimetry.xyz(values_at_cmf_wavelengths))


@lru_cache(maxsize=1)
def _white():
    wl = spectra.cie_1931_cmfs()[0]
    d65 = spectra.evaluate(REFERENCE_WHITE, wl)
    return d65, _srgb_of(d65)


def emission_rgb(spec):
    """(linear sRGB of an absolute radiance spectrum, note or None)."""
    rgb = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(spec))
    if (rgb < 0).any():
        return np.maximum(rgb, 0.0), f"out of the sRGB gamut: {np.round(rgb, 5).tolist()} clipped at 0"
    return rgb, None


def reflectance_rgb_of_values(values):
    """Reflectance rule on values sampled at the CMF wavelengths (unclipped)."""
    d65, white = _white()
    return _srgb_of(np.asarray(values, dtype=np.float64) * d65) / white


def reflectance_rgb(spec):
    """(RGB albedo of a reflectance spectrum in [0, 1], note or None)."""
    wl = spectra.cie_1931_cmfs()[0]
    rgb = reflectance_rgb_of_values(spectra.evaluate(spec, wl))
    clipped = np.clip(rgb, 0.0, 1.0)
    if np.any(clipped != rgb):
        return clipped, f"out of [0, 1] in sRGB: {np.round(rgb, 5).tolist()} clipped"
    return rgb, None


def fresnel_conductor(cos_theta, eta, k):
    """Unpolarised Fresnel reflectance of a conductor eta + i k (exact, complex arithmetic)."""
    c = np.asarray(cos_theta, dtype=np.float64)
    n = np.asarray(eta, dtype=np.float64) + 1j * np.asarray(k, dtype=np.float64)
    cos_t = np.sqrt(1.0 - (1.0 - c**2) / n**2 + 0j)
    rs = (c - n * cos_t) / (c + n * cos_t)
    rp = (n * c - cos_t) / (n * c + cos_t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def conductor_spectra(bsdf):
    """(eta(l), k(l)) at the CMF wavelengths of an IR conductor (named or explicit)."""
    wl = spectra.cie_1931_cmfs()[0]
    if "material" in bsdf:
        name = bsdf["material"]
        if name not in spectra.NAMED_CONDUCTORS:
            raise ReductionError("bsdf.material", f"unknown named conductor {name!r}")
        # Mitsuba's own tables (exporters/data/conductors.json), interpolated linearly as Mitsuba does
        return tuple(spectra.evaluate(s, wl) for s in spectra.named_conductor(name))
    return spectra.evaluate(bsdf["eta"], wl), spectra.evaluate(bsdf["k"], wl)


def conductor_rgb(bsdf):
    """(eta_rgb, k_rgb, info) of an IR conductor by the Fresnel-reflectance fit (see above);
    info: the fitted and target RGB reflectance at normal incidence and the fit's largest
    absolute reflectance residual over all angles."""
    from scipy.optimize import least_squares
    eta, k = conductor_spectra(bsdf)
    cos = np.cos(np.radians(FIT_ANGLES_DEG))
    weight = np.sqrt(cos * np.sqrt(1.0 - cos**2) + 1e-3)
    target = np.array([reflectance_rgb_of_values(fresnel_conductor(c, eta, k)) for c in cos])  # angles x 3
    clipped = bool(np.any((target < 0.0) | (target > 1.0)))
    target = np.clip(target, 0.0, 1.0)
    wl = spectra.cie_1931_cmfs()[0]
    centre = (610.0, 550.0, 465.0)  # starting points only
    eta_rgb, k_rgb, worst = [], [], 0.0
    for ch in range(3):
        x0 = np.log([np.interp(centre[ch], wl, eta), max(np.interp(centre[ch], wl, k), 1e-3)])
        res = least_squares(lambda p: weight * (fresnel_conductor(cos, *np.exp(p)) - target[:, ch]), x0,
                            method="lm", xtol=1e-12, ftol=1e-12)
        e, kk = np.exp(res.x)
        eta_rgb.append(float(e))
        k_rgb.append(float(kk))
        worst = max(worst, float(np.max(np.abs(fresnel_conductor(cos, e, kk) - target[:, ch]))))
    info = {"reflectance_at_normal_incidence": target[0].round(6).tolist(),
            "fit_max_abs_residual": round(worst, 6)}
    if clipped:
        info["note"] = "the reduced reflectance leaves [0, 1] in sRGB at some angles: clipped before the fit"
    return np.array(eta_rgb), np.array(k_rgb), info


def predicted_error(reflectance, illuminant):
    """Single reflection of ``illuminant`` (radiance spectrum) off a Lambertian ``reflectance``:
    (truth rgb(rho * L), what the RGB rule renders rgb(rho) * rgb(L), CIEDE2000 between them with
    the illuminant as white). No renderer involved."""
    wl = spectra.cie_1931_cmfs()[0]
    light = spectra.evaluate(illuminant, wl)
    truth_xyz = colorimetry.xyz(spectra.evaluate(reflectance, wl) * light)
    rgb_rule = reflectance_rgb(reflectance)[0] * emission_rgb(illuminant)[0]
    white = colorimetry.xyz(light)
    de = colorimetry.delta_e_2000(colorimetry.lab(truth_xyz, white),
                                  colorimetry.lab(colorimetry.srgb_to_xyz(rgb_rule), white))
    return colorimetry.xyz_to_srgb(truth_xyz), rgb_rule, de
