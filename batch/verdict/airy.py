"""Reflectance of a thin dielectric film on an absorbing base, in numpy: the ground truth of the
iridescence probe, written independently of the Mitsuba plugin (and in the other time convention,
so that a sign slip in either shows as a disagreement).

Three media: 1 the exterior (real n1), 2 the film (real n2, thickness d), 3 the base
(n3 = eta + i kappa, kappa >= 0). Time dependence e^{-i w t} (Born and Wolf's), so a wave e^{i k z}
decays where Im(n) > 0 and crossing the film twice multiplies the amplitude by e^{+i phi}.

- Fresnel amplitude coefficients (Born and Wolf, Principles of Optics, 7th ed., 1.5.2 eq. 20-21;
  Hecht, Optics, eq. 4.42-4.43), with q_j = n_j cos(theta_j):
      r_s(a,b) = (q_a - q_b) / (q_a + q_b),
      r_p(a,b) = (n_b^2 q_a - n_a^2 q_b) / (n_b^2 q_a + n_a^2 q_b),
  where n_j cos(theta_j) = sqrt(n_j^2 - n1^2 sin^2(theta_1)) with Im >= 0 (the wave that decays
  into the medium; Born and Wolf 14.2).
- Airy summation of the multiply reflected waves in the film (Born and Wolf 1.6.4 eq. 57-58;
  Hecht 9.7.1): r = (r12 + r23 e^{i phi}) / (1 + r12 r23 e^{i phi}), phi = 4 pi d q_2 / lambda,
  R = |r|^2 for s and p; unpolarised light reflects (R_s + R_p) / 2.
- Incoherent limit (a film much thicker than the coherence length, or any film averaged over a
  band wider than its fringes): intensities add, R = R12 + T12^2 R23 / (1 - R12 R23) with
  T12 = 1 - R12 for a lossless film (the geometric series of the internal reflections; Born and
  Wolf 1.6.4 before eq. 57, Hecht 9.7.1).
"""
import numpy as np


def normal_cos(n, n1_sin1):
    """n cos(theta) in a medium of (complex) index n for Snell's invariant n1 sin(theta_1):
    the root whose imaginary part is >= 0 (decaying, or real and positive)."""
    q = np.sqrt(np.asarray(n, dtype=np.complex128) ** 2 - np.asarray(n1_sin1, dtype=np.complex128) ** 2)
    return np.where(q.imag < 0, -q, q)


def fresnel(n_a, q_a, n_b, q_b):
    """(r_s, r_p) from medium a into medium b (Born and Wolf eq. 1.5.20-21)."""
    rs = (q_a - q_b) / (q_a + q_b)
    na2, nb2 = np.asarray(n_a, np.complex128) ** 2, np.asarray(n_b, np.complex128) ** 2
    rp = (nb2 * q_a - na2 * q_b) / (nb2 * q_a + na2 * q_b)
    return rs, rp


def _interfaces(cos1, n1, n2, n3):
    cos1 = np.clip(np.asarray(cos1, dtype=np.float64), 0.0, 1.0)
    n1_sin1 = n1 * np.sqrt(1.0 - cos1**2)
    q1, q2, q3 = (normal_cos(n, n1_sin1) for n in (n1, n2, n3))
    return q2, fresnel(n1, q1, n2, q2), fresnel(n2, q2, n3, q3)


def film_amplitudes(cos1, wavelength_nm, n1, n2, thickness_nm, n3):
    """Complex (r_s, r_p) of the film system (broadcasting over cos1 and wavelength)."""
    q2, (r12s, r12p), (r23s, r23p) = _interfaces(cos1, n1, n2, n3)
    e = np.exp(1j * 4.0 * np.pi * thickness_nm * q2 / np.asarray(wavelength_nm, dtype=np.float64))
    return tuple((r12 + r23 * e) / (1.0 + r12 * r23 * e) for r12, r23 in ((r12s, r23s), (r12p, r23p)))


def film_reflectance(cos1, wavelength_nm, n1, n2, thickness_nm, n3):
    """(R_s, R_p) of the film system: the coherent Airy sum."""
    rs, rp = film_amplitudes(cos1, wavelength_nm, n1, n2, thickness_nm, n3)
    return np.abs(rs) ** 2, np.abs(rp) ** 2


def unpolarized_reflectance(cos1, wavelength_nm, n1, n2, thickness_nm, n3):
    rs, rp = film_reflectance(cos1, wavelength_nm, n1, n2, thickness_nm, n3)
    return 0.5 * (rs + rp)


def incoherent_reflectance(cos1, n1, n2, n3):
    """(R_s, R_p) of a thick lossless film whose internal reflections add in intensity."""
    _q2, r12, r23 = _interfaces(cos1, n1, n2, n3)
    out = []
    for a, b in zip(r12, r23):
        r12i, r23i = np.abs(a) ** 2, np.abs(b) ** 2
        out.append(r12i + (1.0 - r12i) ** 2 * r23i / (1.0 - r12i * r23i))
    return tuple(out)


def bare_reflectance(cos1, n1, n3):
    """(R_s, R_p) of the bare base seen from medium 1."""
    cos1 = np.clip(np.asarray(cos1, dtype=np.float64), 0.0, 1.0)
    n1_sin1 = n1 * np.sqrt(1.0 - cos1**2)
    rs, rp = fresnel(n1, normal_cos(n1, n1_sin1), n3, normal_cos(n3, n1_sin1))
    return np.abs(rs) ** 2, np.abs(rp) ** 2
