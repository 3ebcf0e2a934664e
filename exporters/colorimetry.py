"""Spectra to colour, as a spectral renderer's film does it, in plain numpy (the ground truth of
the analytic probes): XYZ = integral of L(l) * [x_bar, y_bar, z_bar] / integral of y_bar (so a flat
spectrum of 1 has Y = 1, Mitsuba's convention), then linear sRGB (D65 white, no adaptation).
CIE 1931 2-degree CMFs, 360-830 nm at 1 nm, from colour-science (exporters/data/). CIELAB and
CIEDE2000 come from colour-science.

Observers: "cie1931" (the 1 nm table above) is the ground truth. Others describe how a renderer's
film deviates from it, for known deviations (batch/verdict/known.py): "mitsuba3" is Mitsuba 3's
film, the same table's 5 nm entries interpolated linearly and normalised by 1 / 106.7502
(mitsuba/core/spectrum.h, MI_CIE_Y_NORMALIZATION), measured in known_deviations.toml.
"cie1964" is the CIE 1964 10-degree observer (colour-science's CIE 015:2018 table, normalised like
the ground truth: a flat spectrum of 1 has Y = 1): a film integrating with it instead of 1931.
"""
from functools import lru_cache

import numpy as np

from . import spectra

GROUND_TRUTH = "cie1931"
OBSERVERS = ("cie1931", "mitsuba3", "art46", "cie1964")
# ART 2.1.2's film (-s46e): 46 bands of 10 nm from 320 nm, each the box average of the radiance
# over its band (ArSpectrum46.c; measured band by band), labelled by the band centres and read by
# the ART backend as a spectral EXR of box bands (batch/spectral_exr.py, box_weights)
ART_BANDS_NM = (320.0, 10.0, 46)


# Mitsuba 3.9.1's XYZ -> linear sRGB matrix (include/mitsuba/core/spectrum.h, xyz_to_srgb): six
# digits, not the IEC 61966-2-1 matrix derived from the primaries; for a D65 white it gives
# R, G, B +0.6e-5, -8.6e-5, +24.6e-5 relative (measured on renders: docs/findings.md, "Findings")
MITSUBA_XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                                [-0.969256, 1.875991, 0.041556],
                                [0.055648, -0.204043, 1.057311]])


@lru_cache(maxsize=None)
def observer(name=GROUND_TRUTH):
    """(wavelengths, x_bar, y_bar, z_bar, normalisation) on the 1 nm grid of 360-830 nm, such that
    xyz_to_srgb (the IEC 61966-2-1 matrix) of this observer's XYZ is the film's RGB: a film's own
    matrix is folded into its CMFs (which may then be negative; film() keeps the two apart)."""
    if name == "mitsuba3":
        wl, xb, yb, zb, norm, matrix = film(name)
        return (wl, *(np.linalg.solve(_srgb_matrix(), matrix) @ np.array([xb, yb, zb])), norm)
    wl, xb, yb, zb, norm, _matrix = film(name)
    return wl, xb, yb, zb, norm


@lru_cache(maxsize=None)
def film(name=GROUND_TRUTH):
    """(wavelengths, x_bar, y_bar, z_bar, normalisation, XYZ -> linear sRGB matrix) of an observer
    as a film applies it: non-negative CMFs (a film's sensor responses), then its matrix."""
    wl, xb, yb, zb = spectra.cie_1931_cmfs()
    if name == "cie1931":
        return wl, xb, yb, zb, float(np.trapz(yb, wl)), _srgb_matrix()
    if name == "mitsuba3":
        knots = (wl % 5) == 0
        cmfs = np.array([np.interp(wl, wl[knots], c[knots]) for c in (xb, yb, zb)])
        # Mitsuba's film then maps XYZ to sRGB with its own rounded matrix
        return (wl, *cmfs, 106.7502593994140625, MITSUBA_XYZ_TO_SRGB)
    if name == "art46":
        return (wl, *(_band_stairs(wl, c) for c in (xb, yb, zb)), float(np.trapz(yb, wl)), _srgb_matrix())
    if name == "cie1964":
        import colour
        cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"].copy().align(colour.SpectralShape(360, 830, 1))
        wl = np.asarray(cmfs.wavelengths, dtype=np.float64)
        xb, yb, zb = np.asarray(cmfs.values, dtype=np.float64).T
        return wl, xb, yb, zb, float(np.trapz(yb, wl)), _srgb_matrix()
    raise KeyError(f"unknown observer {name!r} (known: {', '.join(OBSERVERS)})")


def _band_stairs(wl, cmf):
    """A CMF as ART's band film is read, on the 1 nm grid. ART's film holds the box average of the
    radiance over each 10 nm band, and the reader weights band k by box_weights (batch/
    spectral_exr.py reads ART's bands as the boxes they measure, through their histospline). So the
    film sees the radiance through a stair: over band k, that weight over the band width; a
    band edge takes the mean of its two neighbours (half a band's value at the film's ends), zero
    outside the film, so that the trapezoid rule on the 1 nm grid integrates the stair as the step
    function it is."""
    start, width, count = ART_BANDS_NM
    centres = start + width * (np.arange(count) + 0.5)
    edges = np.stack([centres - width / 2, centres + width / 2], axis=-1)
    per_band = box_weights(edges, wl, np.asarray(cmf)[None, :], 1.0)[:, 0] / width  # norm 1: the bare integral
    pos = (wl - start) / width
    inside = (pos >= 0) & (pos <= count)
    band = np.clip(np.floor(pos).astype(int), 0, count - 1)
    out = np.where(inside, per_band[band], 0.0)
    edge = inside & (pos == np.round(pos))
    k = np.round(pos[edge]).astype(int)
    below = np.where(k >= 1, per_band[np.clip(k - 1, 0, count - 1)], 0.0)
    above = np.where(k < count, per_band[np.clip(k, 0, count - 1)], 0.0)
    out[edge] = 0.5 * (below + above)
    return out


def hat_weights(band_wl, wl, cmfs, norm):
    """Weights W (N x K) that integrate a spectrum known at the N wavelengths ``band_wl``
    (ascending, nm) against K colour-matching functions ``cmfs`` (K x M, tabulated at ``wl``):
    the spectrum is the piecewise-linear interpolation of its samples, zero outside
    [band_wl[0], band_wl[-1]], i.e. the sum of sample k times its hat function h_k (1 at
    band_wl[k], 0 at the neighbouring wavelengths); W[k] = trapz(h_k * cmf, wl) / norm. So the
    XYZ of samples s is s @ W, exactly what xyz() gives for the interpolated spectrum evaluated on
    the CMFs' grid (the trapezoid rule on that grid, normalised as xyz() is)."""
    band_wl = np.asarray(band_wl, dtype=np.float64)
    hats = np.array([np.interp(wl, band_wl, row, left=0.0, right=0.0) for row in np.eye(band_wl.size)])
    return np.trapz(hats[:, None, :] * np.asarray(cmfs, dtype=np.float64)[None, :, :], wl, axis=-1) / norm


def box_weights(edges, wl, cmfs, norm, grid_nm=0.05):
    """Weights W (N x K) that integrate a spectrum known as its means over N bands ``edges``
    ([(lo, hi)], nm, ascending) against K colour-matching functions ``cmfs`` (K x M, tabulated at
    ``wl``), divided by the normalisation: a box-band film's channels s give XYZ = s @ W.

    Where the bands tile an interval (each band's hi is the next one's lo), the spectrum is the
    histospline of the means (Boneva, Kendall and Stefanov, "Spline transformations", J. R. Stat.
    Soc. B 33, 1971): the derivative of the cubic spline (not-a-knot ends) through the cumulative
    integral at the band edges, which keeps every band's mean exactly and reproduces spectra that
    are quadratic over a few bands; read as constant over each band instead, 5 nm bands of the
    ColorChecker under D65 read 0.06 % bright in G and 0.1 % in B (up to 2.4 % on a patch), with
    the histospline 0.004 % and 0.008 %. Otherwise (gaps or overlaps) each band is read as
    constant. The CMFs are interpolated linearly on a ``grid_nm`` grid (trapezoid rule)."""
    from scipy.interpolate import CubicSpline
    edges = np.asarray(edges, dtype=np.float64)
    wl = np.asarray(wl, dtype=np.float64)
    cmfs = np.atleast_2d(np.asarray(cmfs, dtype=np.float64))
    n = len(edges)
    x = np.arange(edges[0, 0], edges[-1, 1] + grid_nm / 2, grid_nm)
    cm = np.array([np.interp(x, wl, c, left=0.0, right=0.0) for c in cmfs])  # K x X
    tiled = n >= 4 and np.allclose(edges[1:, 0], edges[:-1, 1]) and np.all(edges[:, 1] > edges[:, 0])
    if tiled:
        knots = np.r_[edges[:, 0], edges[-1, 1]]
        # the spline of the cumulative integral is linear in it: one spline per band's unit mean
        cumulative = np.vstack([np.zeros(n), np.tril(np.ones((n, n))) * np.diff(knots)]).T  # N x (N + 1)
        spectra_ = CubicSpline(knots, cumulative.T, bc_type="not-a-knot")(x, 1)  # X x N
        return np.trapz(spectra_.T[:, None, :] * cm[None, :, :], x, axis=-1) / norm
    out = np.zeros((n, cmfs.shape[0]))
    for k, (lo, hi) in enumerate(edges):
        inside = (x >= lo) & (x <= hi)
        if inside.sum() >= 2:
            out[k] = np.trapz(cm[:, inside], x[inside], axis=-1)
    return out / norm


def xyz(values_at_cmf_wavelengths, obs=GROUND_TRUTH):
    wl, xb, yb, zb, norm = observer(obs)
    v = np.asarray(values_at_cmf_wavelengths, dtype=np.float64)
    return np.array([np.trapz(v * xb, wl), np.trapz(v * yb, wl), np.trapz(v * zb, wl)]) / norm


def xyz_rows(values_at_cmf_wavelengths, obs=GROUND_TRUTH):
    """``xyz`` of every row of an N x wavelengths array at once (N x 3): the same trapezoid rule
    along the last axis, the same numbers as calling ``xyz`` per row (checked bit for bit in
    tests/jobs/test_fixed_cost.py), without a Python call per row (a probe's colour table has hundreds)."""
    wl, xb, yb, zb, norm = observer(obs)
    v = np.asarray(values_at_cmf_wavelengths, dtype=np.float64)
    return np.stack([np.trapz(v * xb, wl, axis=-1), np.trapz(v * yb, wl, axis=-1), np.trapz(v * zb, wl, axis=-1)],
                    axis=-1) / norm


def spectrum_xyz(spec, scale_fn=None, obs=GROUND_TRUTH):
    """XYZ of an IR spectrum (optionally multiplied by scale_fn(wavelengths))."""
    wl = spectra.cie_1931_cmfs()[0]
    v = spectra.evaluate(spec, wl)
    if scale_fn is not None:
        v = v * scale_fn(wl)
    return xyz(v, obs)


def _colour():
    import colour  # colour-science; imported lazily (heavy)
    return colour


def _srgb_matrix():
    return np.asarray(_colour().RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)


def xyz_to_srgb(x):
    return np.asarray(x, dtype=np.float64) @ _srgb_matrix().T


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
