"""Reflectance of a thin dielectric film on an absorbing base, in numpy: the ground truth of the
iridescence probe, written independently of the Mitsuba plugin (and in the other time convention,
so that a sign slip in either shows as a disagreement). The implementation is the reference
module's (reference_code/appearance.py, tested against published values); this module keeps the
names the probes and tests use.

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

from ...reference_code import appearance

normal_cos = appearance._normal_cos  # n cos(theta) with Im >= 0 (the decaying wave)
fresnel = appearance._amplitudes  # (r_s, r_p) from medium a into medium b given q = n cos(theta)
film_amplitudes = appearance.airy_amplitudes  # complex (r_s, r_p) of the film system
film_reflectance = appearance.airy_reflectance  # (R_s, R_p): the coherent Airy sum
incoherent_reflectance = appearance.airy_incoherent_reflectance  # thick lossless film, intensities add
film_interfaces = appearance._film_interfaces  # (q2, r12 (s, p), r23 (s, p)): the film system but its thickness
airy_sum = appearance.airy_sum  # film_amplitudes from film_interfaces and the thickness


def unpolarized_reflectance(cos1, wavelength_nm, n1, n2, thickness_nm, n3):
    rs, rp = film_reflectance(cos1, wavelength_nm, n1, n2, thickness_nm, n3)
    return 0.5 * (rs + rp)


def bare_reflectance(cos1, n1, n3):
    """(R_s, R_p) of the bare base seen from medium 1."""
    rs, rp = appearance.fresnel_amplitudes(cos1, n1, n3)
    return np.abs(rs) ** 2, np.abs(rp) ** 2
