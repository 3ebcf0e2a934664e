"""Reference implementations of the appearance models of spectral_bench scenes, in numpy.

Self-contained: imports numpy and scipy only, so it can be copied out of the project and used
alone (the project's probes call it: batch/verdict/optics.py, airy.py; exporters/dispersion.py,
fluorescence.py). The C++17 translation is ``snippets/`` (header-only, no dependencies); both are
tested against published values in tests/probes/test_reference_code.py and against each other in
tests/probes/test_snippets.py. The scene format that uses these models: docs/scene-format.md.

Every function broadcasts over numpy arrays. Conventions:

- Local shading frame: the macro-surface normal is +z; directions are unit 3-vectors pointing
  away from the surface (both the view direction v and the light direction l).
- Wavelengths in nanometres; dispersion coefficients in micrometres (B dimensionless, C in um^2
  for Sellmeier; B in um^2 and C in um^4 for Cauchy), as in the glass catalogues.
- Complex indices n = eta + i k with k >= 0 and time dependence e^{-i w t} (Born and Wolf's, so a
  wave decays where Im(n) > 0). Amplitudes follow Born and Wolf's sign convention for r_p
  (r_p = -r_s at normal incidence). A renderer in the e^{+i w t} convention (Mitsuba 3: n = eta - i k)
  gets the complex conjugates of these amplitudes; reflectances are the same.
- Microfacet roughness alpha is the distribution's width (Walter et al. 2007): GGX and Beckmann
  with alpha, anisotropic forms with (alpha_x, alpha_y) along the frame's x and y axes.

Contents and sources (the formulas are written from these papers; no code is copied):

Microfacets
  ggx_d, beckmann_d (isotropic, of cos theta_m); ggx_d_aniso (of m)
      Walter, Marschner, Li, Torrance 2007, "Microfacet models for refraction through rough
      surfaces", EGSR, eq. 33 (GGX) and eq. 25 (Beckmann); Heitz 2014, "Understanding the
      masking-shadowing function in microfacet-based BRDFs", JCGT 3(2) (anisotropic GGX).
      Normalisation: the projected area integral of D(m) cos theta_m over the hemisphere is 1.
  ggx_lambda, beckmann_lambda, smith_g1, smith_g (separable and height-correlated)
      Heitz 2014 eq. 72 (GGX Lambda), eq. 69 (Beckmann Lambda, exact erf form), Smith's
      G1 = chi+(v.m) / (1 + Lambda(v)), the separable G1(i) G1(o) (Walter et al. 2007 eq. 23) and
      the height-correlated 1 / (1 + Lambda(i) + Lambda(o)) (Heitz 2014 eq. 99).
  ggx_sample_vndf, ggx_vndf_pdf, ggx_reflection_pdf
      Heitz 2018, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4): the algorithm of
      its section 2 (stretch, sample the projected hemisphere, unstretch) and the pdf
      D_v(m) = G1(v) max(0, v.m) D(m) / v_z (its eq. 1; Heitz and d'Eon 2014, eq. 2). The pdf of
      the reflected direction is D_v(m) / (4 v.m) (Walter et al. 2007 eq. 14).
Fresnel
  fresnel_amplitudes (complex r_s, r_p of any interface), fresnel_dielectric (R_s, R_p),
  fresnel_conductor (unpolarised) and fresnel_conductor_sp (R_s, R_p)
      Born and Wolf, Principles of Optics, 7th ed., 1.5.2 eq. 20-21 and 14.2; Hecht, Optics,
      5th ed., eq. 4.42-4.43.
  mueller_reflection (the Mueller matrix of a reflection with amplitudes r_s, r_p)
      Collett, "Field Guide to Polarization" (SPIE 2005), Mueller matrix of a reflection; in the
      (s, p) Stokes bases of the incident and reflected rays, S1 > 0 along s. The sign of the
      lower block is that of Mitsuba 3's mueller::specular_reflection (tested against it).
Thin film
  airy_amplitudes, airy_reflectance, airy_mueller, airy_incoherent_reflectance
      Born and Wolf 1.6.4 eq. 57-58; Hecht 9.7.1: r = (r12 + r23 e^{i phi}) / (1 + r12 r23 e^{i phi}),
      phi = 4 pi d n2 cos(theta2) / lambda; the incoherent sum R12 + T12^2 R23 / (1 - R12 R23).
Coated diffuse (a smooth dielectric coat over a Lambertian base: Mitsuba 3's ``plastic``)
  diffuse_fresnel_reflectance, coated_diffuse_brdf, coated_diffuse_uniform
      Weidlich and Wilkie 2007, "Arbitrarily layered micro-facet surfaces" (GRAPHITE), the
      smooth case as Mitsuba 3 writes it (docs: "Smooth plastic material (plastic)", its
      ``nonlinear`` false): specular F(mu_i) in the mirror direction plus the diffuse lobe
      rho / (1 - F_dr,int) (1 - F(mu_i)) (1 - F(mu_o)) / (pi eta^2), where F is the unpolarised
      Fresnel reflectance of the coat (Hecht eq. 4.42-4.43) and F_dr,int = 2 int_0^1 F(mu; 1/eta) mu
      dmu the coat's hemispherical (diffuse) reflectance seen from inside, total internal
      reflection included (here the integral itself; Mitsuba 3 uses the fit of Egan and Hilgeman
      1973). Under a uniform environment of radiance L the outgoing radiance is L (F(mu_o) +
      rho (1 - F(mu_o)) (1 - F_dr,ext) / (eta^2 (1 - F_dr,int))), and 1 - F_dr,ext = eta^2 (1 -
      F_dr,int) (the hemispherical transmittances of one interface from both sides: reciprocity with the
      n^2 law of radiance; checked numerically by tests/probes/test_coated.py), so the radiance is
      L (F(mu_o) + rho (1 - F(mu_o))).
Dispersion
  sellmeier, cauchy
      SCHOTT, "TIE-29: Refractive Index and Dispersion" (2016): n^2 = 1 + sum B_i l^2 / (l^2 - C_i);
      Cauchy: n = A + B / l^2 + C / l^4 (l in um).
Fluorescence
  art_fluorescence_bands
      ART 2.1.2's CONST_FLUORESCENT_COLOUR (ArCrosstalk500.c, cx500_dpv_init_x): a pyramid over the
      absorption x emission band rectangle, zero where l_o <= l_i and outside 300-830 nm.
"""
import numpy as np
from scipy.special import erf

__all__ = [
    "ggx_d", "beckmann_d", "microfacet_d", "ggx_d_aniso", "ggx_lambda", "beckmann_lambda", "smith_lambda",
    "ggx_lambda_aniso", "smith_g1", "smith_g", "ggx_sample_vndf", "ggx_vndf_pdf", "ggx_reflection_pdf",
    "reflect", "fresnel_amplitudes", "fresnel_dielectric", "fresnel_conductor", "fresnel_conductor_sp",
    "mueller_reflection", "airy_amplitudes", "airy_sum", "airy_reflectance", "airy_mueller",
    "airy_incoherent_reflectance", "diffuse_fresnel_reflectance", "coated_diffuse_brdf", "coated_diffuse_uniform",
    "sellmeier", "cauchy", "art_fluorescence_bands", "FLUORESCENCE_DOMAIN_NM",
]


# -- microfacet distributions ----------------------------------------------------------------------
def ggx_d(cos_m, alpha):
    """GGX (Trowbridge-Reitz) D(m) for a microfacet normal at cos_m from the macro normal
    (Walter et al. 2007 eq. 33, written in cos^2: alpha^2 / (pi (cos^2 (alpha^2 - 1) + 1)^2));
    0 for cos_m <= 0."""
    c2 = np.clip(cos_m, 0.0, 1.0) ** 2
    a2 = alpha * alpha
    return np.where(c2 > 0, a2 / (np.pi * (c2 * (a2 - 1.0) + 1.0) ** 2), 0.0)


def beckmann_d(cos_m, alpha):
    """Beckmann D(m) = exp(-tan^2 / alpha^2) / (pi alpha^2 cos^4) (Walter et al. 2007 eq. 25);
    0 for cos_m <= 0."""
    c2 = np.clip(cos_m, 0.0, 1.0) ** 2
    a2 = alpha * alpha
    tan2 = (1.0 - c2) / np.maximum(c2, 1e-300)
    return np.where(c2 > 0, np.exp(-tan2 / a2) / (np.pi * a2 * np.maximum(c2, 1e-300) ** 2), 0.0)


_D = {"ggx": ggx_d, "beckmann": beckmann_d}


def microfacet_d(kind, cos_m, alpha):
    """D(m) of distribution ``kind`` ("ggx" or "beckmann")."""
    if kind not in _D:
        raise ValueError(f"unknown microfacet distribution {kind!r}")
    return _D[kind](cos_m, alpha)


def ggx_d_aniso(m, alpha_x, alpha_y):
    """Anisotropic GGX D(m) of unit normals m (..., 3) (Heitz 2014, anisotropic GGX):
    1 / (pi ax ay (x^2/ax^2 + y^2/ay^2 + z^2)^2) for m_z > 0, else 0."""
    m = np.asarray(m, dtype=np.float64)
    x, y, z = m[..., 0], m[..., 1], m[..., 2]
    q = (x / alpha_x) ** 2 + (y / alpha_y) ** 2 + z * z
    return np.where(z > 0, 1.0 / (np.pi * alpha_x * alpha_y * q * q), 0.0)


# -- Smith masking -----------------------------------------------------------------------------------
def ggx_lambda(cos_v, alpha):
    """Smith's Lambda of GGX, (-1 + sqrt(1 + alpha^2 tan^2 theta_v)) / 2 (Heitz 2014 eq. 72)."""
    c = np.clip(cos_v, 1e-12, 1.0)
    tan = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    return (-1.0 + np.sqrt(1.0 + (alpha * tan) ** 2)) / 2.0


def beckmann_lambda(cos_v, alpha):
    """Smith's Lambda of Beckmann, (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)) with
    a = 1 / (alpha tan theta_v) (Heitz 2014 eq. 69, the exact form)."""
    c = np.clip(cos_v, 1e-12, 1.0)
    tan = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    a = 1.0 / np.maximum(alpha * tan, 1e-300)
    with np.errstate(over="ignore"):  # tan = 0 (the normal): a is huge and Lambda is 0 (selected below)
        return np.where(tan > 0, (erf(a) - 1.0) / 2.0 + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi)), 0.0)


_LAMBDA = {"ggx": ggx_lambda, "beckmann": beckmann_lambda}


def smith_lambda(kind, cos_v, alpha):
    """Lambda(v) of distribution ``kind`` for a direction at cos_v from the macro normal."""
    if kind not in _LAMBDA:
        raise ValueError(f"unknown microfacet distribution {kind!r}")
    return _LAMBDA[kind](cos_v, alpha)


def ggx_lambda_aniso(v, alpha_x, alpha_y):
    """Lambda of anisotropic GGX for unit directions v (..., 3): the isotropic form with the
    projected roughness alpha_v = sqrt(ax^2 cos^2 phi + ay^2 sin^2 phi) (Heitz 2014, anisotropic
    distributions: Lambda depends on the roughness projected on the direction's azimuth)."""
    v = np.asarray(v, dtype=np.float64)
    z2 = np.maximum(v[..., 2], 1e-12) ** 2
    a2tan2 = ((alpha_x * v[..., 0]) ** 2 + (alpha_y * v[..., 1]) ** 2) / z2
    return (-1.0 + np.sqrt(1.0 + a2tan2)) / 2.0


def smith_g1(kind, cos_v, alpha):
    """Smith's G1(v) = 1 / (1 + Lambda(v)) for a direction above the microfacet (v.m > 0) (Heitz 2014;
    Walter et al. 2007 eq. 34 for GGX)."""
    return 1.0 / (1.0 + smith_lambda(kind, cos_v, alpha))


def smith_g(kind, cos_i, cos_o, alpha, form="separable"):
    """Smith shadowing-masking G2(i, o) for directions above every microfacet involved:
    "separable" G1(i) G1(o) (Walter et al. 2007 eq. 23; Mitsuba 3's MicrofacetDistribution::G) or
    "height-correlated" 1 / (1 + Lambda(i) + Lambda(o)) (Heitz 2014 eq. 99)."""
    li, lo = smith_lambda(kind, cos_i, alpha), smith_lambda(kind, cos_o, alpha)
    if form == "separable":
        return 1.0 / ((1.0 + li) * (1.0 + lo))
    if form == "height-correlated":
        return 1.0 / (1.0 + li + lo)
    raise ValueError(f"unknown shadowing form {form!r}")


# -- visible-normal sampling (Heitz 2018) ----------------------------------------------------------------
def _normalize(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def ggx_sample_vndf(v, alpha_x, alpha_y, u1, u2):
    """A microfacet normal m (..., 3) distributed as the GGX visible normals D_v(m) of direction v
    (unit, v_z > 0), from two uniform numbers u1, u2 in [0, 1) (Heitz 2018, section 2):
    stretch v to the unit-roughness configuration, sample the visible half of the unit
    hemisphere (a disk point whose second coordinate is warped towards the visible part),
    reproject it onto the hemisphere and unstretch the normal."""
    v = np.asarray(v, dtype=np.float64)
    u1, u2 = np.asarray(u1, dtype=np.float64), np.asarray(u2, dtype=np.float64)
    vh = _normalize(np.stack(np.broadcast_arrays(alpha_x * v[..., 0], alpha_y * v[..., 1], v[..., 2]), axis=-1))
    lensq = vh[..., 0] ** 2 + vh[..., 1] ** 2
    inv = np.where(lensq > 0, 1.0 / np.sqrt(np.maximum(lensq, 1e-300)), 0.0)
    t1 = np.stack([np.where(lensq > 0, -vh[..., 1] * inv, 1.0), np.where(lensq > 0, vh[..., 0] * inv, 0.0),
                   np.zeros_like(lensq)], axis=-1)
    t2 = np.cross(vh, t1)
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + vh[..., 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    p3 = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
    nh = p1[..., None] * t1 + p2[..., None] * t2 + p3[..., None] * vh
    m = np.stack(np.broadcast_arrays(alpha_x * nh[..., 0], alpha_y * nh[..., 1], np.maximum(nh[..., 2], 0.0)), axis=-1)
    return _normalize(m)


def ggx_vndf_pdf(v, m, alpha_x, alpha_y):
    """Density of ggx_sample_vndf over the solid angle of m: D_v(m) = G1(v) max(0, v.m) D(m) / v_z
    (Heitz 2018 eq. 1, with Smith's G1 = 1 / (1 + Lambda(v)))."""
    v, m = np.asarray(v, dtype=np.float64), np.asarray(m, dtype=np.float64)
    vm = np.sum(v * m, axis=-1)
    g1 = 1.0 / (1.0 + ggx_lambda_aniso(v, alpha_x, alpha_y))
    return np.where(v[..., 2] > 0, g1 * np.maximum(vm, 0.0) * ggx_d_aniso(m, alpha_x, alpha_y)
                    / np.maximum(v[..., 2], 1e-300), 0.0)


def reflect(v, m):
    """The mirror direction of v about the unit normal m: 2 (v.m) m - v."""
    v, m = np.asarray(v, dtype=np.float64), np.asarray(m, dtype=np.float64)
    return 2.0 * np.sum(v * m, axis=-1, keepdims=True) * m - v


def ggx_reflection_pdf(v, l, alpha_x, alpha_y):
    """Density over the solid angle of l of reflecting v about a VNDF-sampled normal:
    D_v(h) / (4 v.h) with h the half vector (Walter et al. 2007 eq. 14; Heitz 2018 eq. 17)."""
    v, l = np.asarray(v, dtype=np.float64), np.asarray(l, dtype=np.float64)
    h = _normalize(v + l)
    vh = np.sum(v * h, axis=-1)
    return np.where((vh > 0) & (l[..., 2] > 0), ggx_vndf_pdf(v, h, alpha_x, alpha_y) / (4.0 * np.maximum(vh, 1e-300)), 0.0)


# -- Fresnel ---------------------------------------------------------------------------------------
def _normal_cos(n, n1_sin1):
    """n cos(theta) in a medium of (complex) index n for Snell's invariant n1 sin(theta_1): the
    root with Im >= 0 (the wave that decays into the medium; Born and Wolf 14.2)."""
    q = np.sqrt(np.asarray(n, dtype=np.complex128) ** 2 - np.asarray(n1_sin1, dtype=np.complex128) ** 2)
    return np.where(q.imag < 0, -q, q)


def _amplitudes(n_a, q_a, n_b, q_b):
    """(r_s, r_p) from medium a into medium b with q = n cos(theta) (Born and Wolf eq. 1.5.20-21)."""
    rs = (q_a - q_b) / (q_a + q_b)
    na2, nb2 = np.asarray(n_a, np.complex128) ** 2, np.asarray(n_b, np.complex128) ** 2
    rp = (nb2 * q_a - na2 * q_b) / (nb2 * q_a + na2 * q_b)
    return rs, rp


def fresnel_amplitudes(cos_i, n1, n2):
    """Complex amplitude reflection coefficients (r_s, r_p) of light in medium n1 (real) meeting
    medium n2 (real, or complex eta + i k) at cos_i: r_s = (q1 - q2) / (q1 + q2),
    r_p = (n2^2 q1 - n1^2 q2) / (n2^2 q1 + n1^2 q2), q_j = n_j cos(theta_j) (Born and Wolf 1.5.2
    eq. 20-21). Beyond the critical angle |r| = 1 with a phase (total internal reflection)."""
    cos_i = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0)
    n1_sin1 = n1 * np.sqrt(1.0 - cos_i**2)
    return _amplitudes(n1, _normal_cos(n1, n1_sin1), n2, _normal_cos(n2, n1_sin1))


def fresnel_dielectric(cos_i, eta):
    """(R_s, R_p) of a smooth dielectric interface for light from outside at cos_i, eta =
    n_inside / n_outside (Hecht eq. 4.42-4.43); 1 beyond the critical angle (eta < 1)."""
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin_t2 = (1 - cos_i**2) / eta**2
    cos_t = np.sqrt(np.clip(1 - sin_t2, 0.0, 1.0))
    rs = ((cos_i - eta * cos_t) / (cos_i + eta * cos_t)) ** 2
    rp = ((eta * cos_i - cos_t) / (eta * cos_i + cos_t)) ** 2
    return np.where(sin_t2 >= 1, 1.0, rs), np.where(sin_t2 >= 1, 1.0, rp)


def fresnel_conductor_sp(cos_i, eta, k):
    """(R_s, R_p) of a conductor of relative complex index eta + i k (Born and Wolf 14.2)."""
    n = np.asarray(eta, dtype=np.float64) + 1j * np.asarray(k, dtype=np.float64)
    c = np.clip(np.asarray(cos_i, dtype=np.float64), 0.0, 1.0).astype(np.complex128)
    cos_t = np.sqrt(1.0 - (1.0 - c**2) / n**2)
    rs = (c - n * cos_t) / (c + n * cos_t)
    rp = (n * c - cos_t) / (n * c + cos_t)
    return np.abs(rs) ** 2, np.abs(rp) ** 2


def fresnel_conductor(cos_i, eta, k):
    """Unpolarised reflectance (R_s + R_p) / 2 of a conductor of relative complex index eta + i k."""
    rs, rp = fresnel_conductor_sp(cos_i, eta, k)
    return 0.5 * (rs + rp)


def mueller_reflection(r_s, r_p):
    """The 4 x 4 Mueller matrix (..., 4, 4) of a reflection with complex amplitudes r_s, r_p (this
    module's convention: Born and Wolf's, e^{-i w t}), in the (s, p) Stokes bases of the incident
    and the reflected ray (S1 > 0 along s; Collett 2005):
        [[A, B, 0, 0], [B, A, 0, 0], [0, 0, C, S], [0, 0, -S, C]],
        A = (|r_s|^2 + |r_p|^2) / 2, B = (|r_s|^2 - |r_p|^2) / 2, C + i S = conj(r_s) r_p,
    which is Mitsuba 3's mueller::specular_reflection (its amplitudes, in e^{+i w t}, are the
    conjugates of these: C + i S = r_s conj(r_p) there). A smooth mirror at normal incidence gives
    R diag(1, 1, -1, -1): the handedness of circular polarisation flips on reflection."""
    r_s, r_p = np.asarray(r_s, np.complex128), np.asarray(r_p, np.complex128)
    a = 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)
    b = 0.5 * (np.abs(r_s) ** 2 - np.abs(r_p) ** 2)
    cs = np.conj(r_s) * r_p
    out = np.zeros(np.broadcast(r_s, r_p).shape + (4, 4))
    out[..., 0, 0] = out[..., 1, 1] = a
    out[..., 0, 1] = out[..., 1, 0] = b
    out[..., 2, 2] = out[..., 3, 3] = cs.real
    out[..., 2, 3], out[..., 3, 2] = cs.imag, -cs.imag
    return out


# -- thin film (Airy) ------------------------------------------------------------------------------
def _film_interfaces(cos1, n1, n2, n3):
    cos1 = np.clip(np.asarray(cos1, dtype=np.float64), 0.0, 1.0)
    n1_sin1 = n1 * np.sqrt(1.0 - cos1**2)
    q1, q2, q3 = (_normal_cos(n, n1_sin1) for n in (n1, n2, n3))
    return q2, _amplitudes(n1, q1, n2, q2), _amplitudes(n2, q2, n3, q3)


def airy_amplitudes(cos1, wavelength_nm, n1, n2, thickness_nm, n3):
    """Complex (r_s, r_p) of a film of real index n2 and thickness d (nm) between an exterior of
    real index n1 and a base n3 = eta + i k, for light at cos1 in the exterior: the Airy sum
    r = (r12 + r23 e^{i phi}) / (1 + r12 r23 e^{i phi}), phi = 4 pi d n2 cos(theta2) / lambda
    (Born and Wolf 1.6.4 eq. 57-58)."""
    return airy_sum(_film_interfaces(cos1, n1, n2, n3), wavelength_nm, thickness_nm)


def airy_sum(interfaces, wavelength_nm, thickness_nm):
    """airy_amplitudes from the film's interfaces (q2, (r12_s, r12_p), (r23_s, r23_p)) as
    ``_film_interfaces`` gives them: the only part that depends on the thickness, so that a fit
    over it computes the interfaces once."""
    q2, (r12s, r12p), (r23s, r23p) = interfaces
    e = np.exp(1j * 4.0 * np.pi * thickness_nm * q2 / np.asarray(wavelength_nm, dtype=np.float64))
    return tuple((r12 + r23 * e) / (1.0 + r12 * r23 * e) for r12, r23 in ((r12s, r23s), (r12p, r23p)))


def airy_reflectance(cos1, wavelength_nm, n1, n2, thickness_nm, n3):
    """(R_s, R_p) = (|r_s|^2, |r_p|^2) of the film system (coherent Airy sum)."""
    rs, rp = airy_amplitudes(cos1, wavelength_nm, n1, n2, thickness_nm, n3)
    return np.abs(rs) ** 2, np.abs(rp) ** 2


def airy_mueller(cos1, wavelength_nm, n1, n2, thickness_nm, n3):
    """Mueller matrix of the film system's reflection (mueller_reflection of airy_amplitudes)."""
    return mueller_reflection(*airy_amplitudes(cos1, wavelength_nm, n1, n2, thickness_nm, n3))


def airy_incoherent_reflectance(cos1, n1, n2, n3):
    """(R_s, R_p) of a thick lossless film whose internal reflections add in intensity:
    R12 + T12^2 R23 / (1 - R12 R23), T12 = 1 - R12 (Born and Wolf 1.6.4; Hecht 9.7.1)."""
    _q2, r12, r23 = _film_interfaces(cos1, n1, n2, n3)
    out = []
    for a, b in zip(r12, r23):
        r12i, r23i = np.abs(a) ** 2, np.abs(b) ** 2
        out.append(r12i + (1.0 - r12i) ** 2 * r23i / (1.0 - r12i * r23i))
    return tuple(out)



# -- coated diffuse (Mitsuba 3's smooth plastic, nonlinear false) ----------------------------------
def fresnel_unpolarized(cos_i, eta):
    """(R_s + R_p) / 2 of a smooth dielectric for light from outside, eta = n_inside / n_outside."""
    rs, rp = fresnel_dielectric(cos_i, eta)
    return 0.5 * (rs + rp)


_FDR = {}  # diffuse_fresnel_reflectance's values by eta (each a quadrature)


def diffuse_fresnel_reflectance(eta):
    """F_dr = 2 int_0^1 F(mu; eta) mu dmu: the hemispherical reflectance of a smooth interface
    under uniform (diffuse) incidence from the side where eta = n_other / n_this (eta < 1: from
    inside a coat of index 1 / eta, total internal reflection beyond the critical angle
    included). Adaptive quadrature (scipy.integrate.quad) split at the critical angle, where F
    has a square-root edge; accurate to ~1e-12."""
    eta = float(eta)
    if eta not in _FDR:
        _FDR[eta] = _diffuse_fresnel_reflectance(eta)
    return _FDR[eta]


def _diffuse_fresnel_reflectance(eta):
    from scipy.integrate import quad
    if eta < 1.0:
        mu_c = np.sqrt(1.0 - eta * eta)  # below mu_c: total internal reflection, F = 1
        rest = quad(lambda mu: float(fresnel_unpolarized(mu, eta)) * mu, mu_c, 1.0, epsabs=1e-13, epsrel=1e-13,
                    limit=200)[0]
        return float(mu_c * mu_c + 2.0 * rest)
    return float(2.0 * quad(lambda mu: float(fresnel_unpolarized(mu, eta)) * mu, 0.0, 1.0, epsabs=1e-13,
                            epsrel=1e-13, limit=200)[0])


def coated_diffuse_brdf(cos_i, cos_o, rho, eta):
    """The diffuse lobe of a smooth coat of relative index eta over a Lambertian base of albedo
    rho, per steradian (Mitsuba 3's plastic with nonlinear false; module docstring):
    rho / (1 - F_dr,int) (1 - F(cos_i)) (1 - F(cos_o)) / (pi eta^2); 0 below the horizon. The
    specular lobe is F(cos_i) in the mirror direction (a delta, not included)."""
    ci, co = np.asarray(cos_i, dtype=np.float64), np.asarray(cos_o, dtype=np.float64)
    fdr_int = diffuse_fresnel_reflectance(1.0 / eta)
    value = (np.asarray(rho, dtype=np.float64) / (1.0 - fdr_int) * (1.0 - fresnel_unpolarized(ci, eta))
             * (1.0 - fresnel_unpolarized(co, eta)) / (np.pi * eta * eta))
    return np.where((ci > 0) & (co > 0), value, 0.0)


def coated_diffuse_uniform(cos_o, rho, eta):
    """Outgoing radiance over L of the smooth coated diffuse under a uniform environment of radiance
    L (nothing else in view of the surface): F(mu_o) + rho (1 - F(mu_o)) (1 - F_dr,ext) /
    (eta^2 (1 - F_dr,int)), which is F(mu_o) + rho (1 - F(mu_o)) as 1 - F_dr,ext = eta^2 (1 - F_dr,int)
    (the ratio is computed, not assumed: tests/probes/test_coated.py checks it is 1)."""
    f = fresnel_unpolarized(np.asarray(cos_o, dtype=np.float64), eta)
    ratio = (1.0 - diffuse_fresnel_reflectance(eta)) / (eta * eta * (1.0 - diffuse_fresnel_reflectance(1.0 / eta)))
    return f + np.asarray(rho, dtype=np.float64) * (1.0 - f) * ratio


# -- dispersion ------------------------------------------------------------------------------------
def sellmeier(wavelength_nm, B, C):
    """n(lambda) of a Sellmeier glass: n^2 = 1 + sum_i B_i l^2 / (l^2 - C_i), l in um, C_i in um^2
    (SCHOTT TIE-29). NaN where n^2 < 0 (inside an absorption band)."""
    l2 = (np.asarray(wavelength_nm, dtype=np.float64) * 1e-3) ** 2
    n2 = 1.0 + sum(float(b) * l2 / (l2 - float(c)) for b, c in zip(B, C))
    with np.errstate(invalid="ignore"):
        return np.sqrt(n2)


def cauchy(wavelength_nm, A, B=0.0, C=0.0):
    """n(lambda) = A + B / l^2 + C / l^4, l in um (B in um^2, C in um^4)."""
    l2 = (np.asarray(wavelength_nm, dtype=np.float64) * 1e-3) ** 2
    return float(A) + float(B) / l2 + float(C) / l2 ** 2


# -- fluorescence ----------------------------------------------------------------------------------
FLUORESCENCE_DOMAIN_NM = (300.0, 830.0)  # both axes of ART's re-radiation table


def art_fluorescence_bands(l_i, l_o, absorption_peak, absorption_width, emission_peak, emission_width, strength):
    """Re-radiation P(l_i, l_o) in 1/nm of ART's CONST_FLUORESCENT_COLOUR: the pyramid
    strength * max(0, min(1 - |l_i - a| / wa, 1 - |l_o - e| / we)) over the rectangle a +- wa by
    e +- we (widths are half the base), zero where l_o <= l_i (no anti-Stokes emission) and
    outside FLUORESCENCE_DOMAIN_NM on either axis. A fluorescent Lambertian surface scatters
    L_o(l_o) = rho(l_o) L_i(l_o) + integral P(l_i, l_o) L_i(l_i) dl_i (Mojzik, Fichet and Wilkie
    2018, CGF 37(4), eq. 2)."""
    l_i = np.asarray(l_i, dtype=np.float64)
    l_o = np.asarray(l_o, dtype=np.float64)
    fx = 1.0 - np.abs(l_i - absorption_peak) / absorption_width
    fy = 1.0 - np.abs(l_o - emission_peak) / emission_width
    p = strength * np.maximum(0.0, np.minimum(fx, fy))
    lo, hi = FLUORESCENCE_DOMAIN_NM
    inside = (l_i >= lo) & (l_i <= hi) & (l_o >= lo) & (l_o <= hi)
    return np.where((l_o > l_i) & inside, p, 0.0)
