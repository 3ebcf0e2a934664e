"""Spectra to colour, as a spectral renderer's film does it, in plain numpy (the ground truth of
the analytic probes): XYZ = integral of L(l) * [x_bar, y_bar, z_bar] / integral of y_bar (so a flat
spectrum of 1 has Y = 1, Mitsuba's convention), then linear sRGB (D65 white, no adaptation).
CIE 1931 2-degree CMFs, 360-830 nm at 1 nm, from colour-science (exporters/data/). CIELAB and
CIEDE2000 come from colour-science.
"""
import numpy as np

from . import spectra


def xyz(values_at_cmf_wavelengths):
    wl, xb, yb, zb = spectra.cie_1931_cmfs()
    v = np.asarray(values_at_cmf_wavelengths, dtype=np.float64)
    norm = np.trapz(yb, wl)
    return np.array([np.trapz(v * xb, wl), np.trapz(v * yb, wl), np.trapz(v * zb, wl)]) / norm


def spectrum_xyz(spec, scale_fn=None):
    """XYZ of an IR spectrum (optionally multiplied by scale_fn(wavelengths))."""
    wl = spectra.cie_1931_cmfs()[0]
    v = spectra.evaluate(spec, wl)
    if scale_fn is not None:
        v = v * scale_fn(wl)
    return xyz(v)


def _colour():
    import colour  # colour-science; imported lazily (heavy)
    return colour


def xyz_to_srgb(x):
    m = _colour().RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB
    return np.asarray(x, dtype=np.float64) @ np.asarray(m).T


def srgb_to_xyz(rgb):
    m = _colour().RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(m).T


def lab(x, white_xyz):
    """CIELAB of XYZ relative to the white's XYZ (both in the same absolute scale)."""
    c = _colour()
    white = np.asarray(white_xyz, dtype=np.float64)
    return c.XYZ_to_Lab(np.asarray(x) / white[1], c.XYZ_to_xy(white))


def delta_e_2000(lab1, lab2):
    return float(_colour().delta_E(lab1, lab2, method="CIE 2000"))
