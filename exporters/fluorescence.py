"""Fluorescence of the scene IR: a Lambertian surface that re-radiates light at longer
wavelengths. The one place that turns the IR's description into numbers: the Mitsuba writer
(the table its plugins read), the validation and the analytic probe all use this module.

A diffuse BSDF may carry ``"fluorescence"``. The surface then scatters (Mojzik, Fichet and
Wilkie 2018, "Handling fluorescence in a uni-directional spectral path tracer", CGF 37(4), eq. 2
with a bispectral Lambertian BRRDF):

    L_o(l_o) = rho(l_o) L_i(l_o) + integral over l_i of P(l_i, l_o) L_i(l_i) dl_i

per direction, with the cosine-weighted hemisphere of the diffuse BSDF around it: ``reflectance``
is the elastic part rho (the diagonal of a Donaldson matrix), P the re-radiation, in 1/nm: the
spectral radiance re-emitted at l_o per unit spectral radiance arriving at l_i, per nanometre of
excitation. P is zero wherever l_o <= l_i (Stokes shift: no anti-Stokes emission) and outside
DOMAIN (300-830 nm on both axes; ART's re-radiation table starts at 300 nm).

Two forms:
- bands (exactly what ART 2.1.2's CONST_FLUORESCENT_COLOUR(base, strength, PNT2D(a, e),
  VEC2D(wa, we)) takes; read from ART's ArCrosstalk500.c, cx500_dpv_init_x):
      {"type": "bands", "absorption_peak": a, "absorption_width": wa,
       "emission_peak": e, "emission_width": we, "strength": s}
  P(l_i, l_o) = s * max(0, min(1 - |l_i - a| / wa, 1 - |l_o - e| / we)): a pyramid whose
  base is the rectangle a +- wa by e +- we (the widths are half the base, in nm), peak s in 1/nm;
  its sections are triangles (Kasha's rule holds only approximately: the emission profile
  narrows towards the absorption band's edges, as in ART).
- matrix (a Donaldson matrix without its diagonal):
      {"type": "matrix", "wavelengths": [w_0 ... w_n-1], "matrix": [[P(w_i, w_o) ...] ...]}
  matrix[i][o] = P(w_i, w_o) in 1/nm (a matrix measured per band of width dw is divided by dw),
  bilinear between grid points, zero outside the grid. Entries with w_o < w_i must be 0
  (anti-Stokes is refused); the diagonal belongs to ``reflectance``, so it must be 0 too.

Quantum yield: photons re-emitted per photon absorbed at l_i, where everything that is not
reflected elastically counts as absorbed: QY(l_i) = integral P(l_i, l_o) (l_o / l_i) dl_o /
(1 - rho(l_i)) (radiance is energy; a photon at l carries hc/l). Validation refuses QY > 1 at any
l_i; then rho(l_i) + integral P(l_i, l_o) dl_o <= 1, so no wavelength gains energy.

Renderers use a tabulation (``table``): P at the centres of 1 nm cells centred on whole
nanometres, constant over each cell. That is ART's own discretisation of the bands (a 1 nm grid
from 300 nm, cx500_dd_value rounds the wavelength); the probe integrates P itself on a finer grid.
Mitsuba samples camera wavelengths over 360-830 nm only, but the excitation wavelength is drawn
from the table, down to 300 nm: the writer tabulates every spectrum of a fluorescent scene from
300 nm (see FLUORESCENT_SPECTRA_FROM), so UV light between 300 and 360 nm does excite.
"""
import math

import numpy as np

from ..reference_code import appearance

DOMAIN = appearance.FLUORESCENCE_DOMAIN_NM  # (300, 830) nm, both axes of P
STEP = 1.0  # nm, the renderers' cells
FLUORESCENT_SPECTRA_FROM = DOMAIN[0]  # writers tabulate spectra of fluorescent scenes from here
BAND_KEYS = ("absorption_peak", "absorption_width", "emission_peak", "emission_width", "strength")
QY_SLACK = 1e-6  # quadrature rounding allowed above a quantum yield of 1


def grid():
    """Cell centres of the renderers' tabulation, 300..830 nm."""
    return np.arange(DOMAIN[0], DOMAIN[1] + 0.5 * STEP, STEP)


def reradiation(fl, l_i, l_o):
    """P(l_i, l_o) in 1/nm (numpy broadcasting over l_i and l_o)."""
    l_i = np.asarray(l_i, dtype=np.float64)
    l_o = np.asarray(l_o, dtype=np.float64)
    if fl["type"] == "bands":  # the reference implementation (its domain is DOMAIN)
        return appearance.art_fluorescence_bands(l_i, l_o, *(fl[key] for key in BAND_KEYS))
    w = np.asarray(fl["wavelengths"], dtype=np.float64)
    m = np.asarray(fl["matrix"], dtype=np.float64)
    p = _bilinear(w, m, l_i, l_o)
    inside = (l_i >= DOMAIN[0]) & (l_i <= DOMAIN[1]) & (l_o >= DOMAIN[0]) & (l_o <= DOMAIN[1])
    return np.where((l_o > l_i) & inside, p, 0.0)


def _bilinear(w, m, l_i, l_o):
    l_i, l_o = np.broadcast_arrays(l_i, l_o)
    if len(w) == 1:
        return np.where((l_i == w[0]) & (l_o == w[0]), m[0, 0], 0.0)
    fi = np.interp(l_i, w, np.arange(len(w)), left=np.nan, right=np.nan)
    fo = np.interp(l_o, w, np.arange(len(w)), left=np.nan, right=np.nan)
    out = ~(np.isfinite(fi) & np.isfinite(fo))
    fi, fo = np.nan_to_num(fi), np.nan_to_num(fo)
    i0 = np.clip(np.floor(fi).astype(int), 0, len(w) - 2)
    o0 = np.clip(np.floor(fo).astype(int), 0, len(w) - 2)
    ti, to = fi - i0, fo - o0
    v = ((1 - ti) * (1 - to) * m[i0, o0] + ti * (1 - to) * m[i0 + 1, o0]
         + (1 - ti) * to * m[i0, o0 + 1] + ti * to * m[i0 + 1, o0 + 1])
    return np.where(out, 0.0, v)


def table(fl):
    """(wavelengths, M): the renderers' tabulation, M[i, o] = P(w_i, w_o) on grid() (1/nm)."""
    w = grid()
    return w, reradiation(fl, w[:, None], w[None, :])


def support(fl):
    """(rows, cols): index ranges of the non-zero block of table(fl) (empty ranges when P = 0)."""
    w, m = table(fl)
    rows, cols = np.nonzero(m.any(axis=1))[0], np.nonzero(m.any(axis=0))[0]
    if rows.size == 0:
        return range(0), range(0)
    return range(rows[0], rows[-1] + 1), range(cols[0], cols[-1] + 1)


def _fine(lo=DOMAIN[0], hi=DOMAIN[1], step=0.05):
    return np.arange(lo, hi + 0.5 * step, step)


def emitted(fl, radiance, l_o, step=0.05):
    """integral of P(l_i, l_o) L(l_i) dl_i at each l_o (trapezoid on a ``step`` nm grid; P and
    the IR's spectra are piecewise linear, so the rule's own error is far below any render's
    noise). ``radiance(wavelengths)`` is the incident spectral radiance."""
    return emitted_each(fl, [radiance], l_o, step)[0]


def emitted_each(fl, radiances, l_o, step=0.05):
    """``emitted`` for each of several incident spectra ``radiances``, P tabulated once for all:
    the same numbers as one ``emitted`` call each (issue 45 item 1: the sphere-on-floor probe
    integrates a dozen spectra against one P, whose table was most of each call)."""
    l_i = _fine(step=step)
    l_o = np.atleast_1d(np.asarray(l_o, dtype=np.float64))
    lights = [np.asarray(radiance(l_i), dtype=np.float64) for radiance in radiances]
    outs = [np.empty(l_o.shape) for _ in lights]
    for k in range(0, l_o.size, 64):  # chunks keep the P block small
        p = reradiation(fl, l_i[None, :], l_o[k:k + 64, None])
        for L, out in zip(lights, outs):
            out[k:k + 64] = np.trapz(p * L[None, :], l_i, axis=1)
    return outs


def quantum_yield(fl, reflectance):
    """(largest QY over l_i, the l_i where it occurs): photons re-emitted per photon absorbed.
    ``reflectance(wavelengths)`` is rho."""
    l_i = grid()
    l_o = _fine(step=0.25)
    p = reradiation(fl, l_i[:, None], l_o[None, :])
    photons = np.trapz(p * (l_o[None, :] / l_i[:, None]), l_o, axis=1)
    absorbed = 1.0 - np.asarray(reflectance(l_i), dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        qy = np.where(photons > 0, photons / np.maximum(absorbed, 0.0), 0.0)
    qy = np.where((photons > 0) & (absorbed <= 0), np.inf, qy)
    k = int(np.argmax(qy))
    return float(qy[k]), float(l_i[k])


def _finite(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def problems(fl, reflectance, where="fluorescence"):
    """Yield (field, message) problems of one ``fluorescence`` object (shape already checked by
    the schema); ``reflectance(wavelengths)`` evaluates the BSDF's elastic reflectance."""
    lo, hi = DOMAIN
    if fl["type"] == "bands":
        bad = False
        for key in BAND_KEYS:
            v = fl[key]
            if not _finite(v):
                yield f"{where}.{key}", f"must be a finite number, got {v!r}"
                bad = True
            elif key.endswith("width") and v <= 0:
                yield f"{where}.{key}", f"must be > 0 nm (half the band's base), got {v}"
                bad = True
            elif key == "strength" and v < 0:
                yield f"{where}.{key}", f"must be >= 0 (peak of P in 1/nm), got {v}"
                bad = True
        if bad:
            return
        if fl["emission_peak"] <= fl["absorption_peak"]:
            yield (f"{where}.emission_peak", f"emission at {fl['emission_peak']:g} nm is not at a longer wavelength "
                   f"than absorption at {fl['absorption_peak']:g} nm (anti-Stokes emission is not modelled)")
            return
        for band in ("absorption", "emission"):
            p, w = fl[f"{band}_peak"], fl[f"{band}_width"]
            if p - w < lo or p + w > hi:
                yield (f"{where}.{band}_width", f"the {band} band {p - w:g}-{p + w:g} nm leaves the re-radiation's "
                       f"domain {lo:g}-{hi:g} nm (ART's table starts at 300 nm; Mitsuba's camera sees 360-830 nm)")
                return
    else:
        w, m = fl["wavelengths"], fl["matrix"]
        if len(m) != len(w) or any(len(row) != len(w) for row in m):
            yield f"{where}.matrix", f"must be {len(w)} x {len(w)} (one row and column per wavelength)"
            return
        for i, x in enumerate(w):
            if not _finite(x) or not lo <= x <= hi:
                yield f"{where}.wavelengths[{i}]", f"must be a wavelength in {lo:g}-{hi:g} nm, got {x!r}"
                return
        if any(b <= a for a, b in zip(w, w[1:])):
            yield f"{where}.wavelengths", "must be strictly increasing"
            return
        for i, row in enumerate(m):
            for o, v in enumerate(row):
                if not _finite(v) or v < 0:
                    yield f"{where}.matrix[{i}][{o}]", f"must be a finite number >= 0 (1/nm), got {v!r}"
                    return
                if v > 0 and w[o] < w[i]:
                    yield (f"{where}.matrix[{i}][{o}]", f"re-radiation from {w[i]:g} nm to the shorter {w[o]:g} nm "
                           "(emission at a shorter wavelength than absorption is not modelled)")
                    return
                if v > 0 and o == i:
                    yield (f"{where}.matrix[{i}][{o}]", "the diagonal is the elastic reflectance: give it as the "
                           "BSDF's reflectance and leave the matrix's diagonal 0")
                    return
    qy, at = quantum_yield(fl, reflectance)
    if qy > 1.0 + QY_SLACK:
        field = f"{where}.strength" if fl["type"] == "bands" else f"{where}.matrix"
        yield (field, f"quantum yield {qy:.3g} at {at:g} nm excitation: more photons re-emitted than absorbed "
                      f"(QY = integral P(l_i, l_o) l_o / l_i dl_o / (1 - reflectance(l_i)) must be <= 1)")


def write_table(fl, path):
    """The re-radiation table the Mitsuba plugins read (sb_fluorescent_diffuse): the non-zero block
    of table(fl), rows excitation, columns emission, P in 1/nm."""
    w, m = table(fl)
    rows, cols = support(fl)
    lines = ["# spectral_bench re-radiation table: P(l_i, l_o) in 1/nm (exporters/fluorescence.py);",
             "# rows: excitation cells, columns: emission cells; each cell is STEP nm wide, centred on its",
             "# wavelength; P is constant over a cell and 0 outside the block.",
             f"excitation {w[rows.start] if rows else 0.0:g} {STEP:g} {len(rows)}",
             f"emission {w[cols.start] if cols else 0.0:g} {STEP:g} {len(cols)}"]
    block = m[rows.start:rows.stop, cols.start:cols.stop] if rows else np.zeros((0, 0))
    lines += [" ".join(f"{v:.6g}" for v in row) for row in block]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path
