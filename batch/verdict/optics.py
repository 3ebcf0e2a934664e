"""Closed-form optics for the probes, in numpy, written from the papers (no renderer involved).

- Fresnel reflectance of a smooth dielectric (s, p) and of a conductor with complex IOR n + ik,
  unpolarised (Born & Wolf, Principles of Optics, 7th ed., sec. 1.5.2 and 14.2; Hecht, Optics,
  5th ed., eq. 4.42-4.43).
- Microfacet distributions and Smith masking (Walter, Marschner, Li, Torrance 2007, "Microfacet
  models for refraction through rough surfaces", EGSR): GGX D (eq. 33), Beckmann D (eq. 25);
  Smith's Lambda for GGX (Heitz 2014, "Understanding the masking-shadowing function in
  microfacet-based BRDFs", JCGT 3(2), eq. 72) and Beckmann (eq. 69, exact erf form);
  G1 = 1 / (1 + Lambda) (Walter eq. 34 for GGX). Two shadowing-masking forms: the separable
  G1(i) G1(o) (Walter eq. 23 with Smith's G1; what Mitsuba 3 uses, mitsuba/render/microfacet.h
  MicrofacetDistribution::G) and the height-correlated 1 / (1 + Lambda(i) + Lambda(o)) (Heitz
  2014 eq. 99), which a renderer may use instead.
"""
import numpy as np
from scipy.special import erf


def fresnel_dielectric(cos_i, eta):
    """(Rs, Rp) for light from outside (eta = n_inside / n_outside)."""
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin_t2 = (1 - cos_i**2) / eta**2
    cos_t = np.sqrt(np.clip(1 - sin_t2, 0.0, 1.0))
    rs = ((cos_i - eta * cos_t) / (cos_i + eta * cos_t)) ** 2
    rp = ((eta * cos_i - cos_t) / (eta * cos_i + cos_t)) ** 2
    return np.where(sin_t2 >= 1, 1.0, rs), np.where(sin_t2 >= 1, 1.0, rp)


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised reflectance (Rs + Rp) / 2 of a conductor of relative complex IOR eta + i k."""
    n = np.asarray(eta, dtype=np.float64) + 1j * np.asarray(k, dtype=np.float64)
    c = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0).astype(np.complex128)
    cos_t = np.sqrt(1.0 - (1.0 - c**2) / n**2)
    rs = (c - n * cos_t) / (c + n * cos_t)
    rp = (n * c - cos_t) / (n * c + cos_t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def distribution(kind, cos_m, alpha):
    """Microfacet normal distribution D(m) for a normal at cos_m from the macro normal."""
    c2 = np.clip(cos_m, 0.0, 1.0) ** 2
    a2 = alpha * alpha
    if kind == "ggx":
        return np.where(c2 > 0, a2 / (np.pi * (c2 * (a2 - 1.0) + 1.0) ** 2), 0.0)
    if kind == "beckmann":
        tan2 = (1.0 - c2) / np.maximum(c2, 1e-300)
        return np.where(c2 > 0, np.exp(-tan2 / a2) / (np.pi * a2 * np.maximum(c2, 1e-300) ** 2), 0.0)
    raise ValueError(f"unknown microfacet distribution {kind!r}")


def smith_lambda(kind, cos_v, alpha):
    """Smith's Lambda of a direction at cos_v from the macro normal."""
    c = np.clip(cos_v, 1e-12, 1.0)
    tan = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    if kind == "ggx":
        return (-1.0 + np.sqrt(1.0 + (alpha * tan) ** 2)) / 2.0
    if kind == "beckmann":
        a = 1.0 / np.maximum(alpha * tan, 1e-300)
        return np.where(tan > 0, (erf(a) - 1.0) / 2.0 + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi)), 0.0)
    raise ValueError(f"unknown microfacet distribution {kind!r}")


def shadowing(kind, cos_i, cos_o, alpha, form="separable"):
    """Smith shadowing-masking G(i, o) for directions on the normal's side of every microfacet
    involved (the reflection configurations the probes integrate)."""
    li, lo = smith_lambda(kind, cos_i, alpha), smith_lambda(kind, cos_o, alpha)
    if form == "separable":
        return 1.0 / ((1.0 + li) * (1.0 + lo))
    if form == "height-correlated":
        return 1.0 / (1.0 + li + lo)
    raise ValueError(f"unknown shadowing form {form!r}")
