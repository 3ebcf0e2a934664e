// spectral_bench reference code: Fresnel amplitudes and reflectances (dielectric and conductor),
// the Mueller matrix of a reflection, and the Airy thin-film reflectance. Header-only C++17, no
// dependencies. The numpy original, same names and conventions: reference_code/appearance.py
// (tests/test_snippets.py checks this header against it to 1e-6).
//
// Conventions: complex indices n = eta + i k (k >= 0) and time dependence e^{-i w t} (Born and
// Wolf's), r_p with Born and Wolf's sign (r_p = -r_s at normal incidence). A renderer in the
// e^{+i w t} convention (Mitsuba 3) gets the complex conjugates; reflectances are the same.
//
// Sources (formulas written from the books):
//   Born and Wolf, Principles of Optics, 7th ed.: 1.5.2 eq. 20-21 (amplitudes), 14.2 (absorbing
//     media), 1.6.4 eq. 57-58 (the Airy sum of a film); Hecht, Optics, 5th ed., 4.6 and 9.7.
//   Collett, "Field Guide to Polarization" (SPIE 2005): the Mueller matrix of a reflection, in
//     the (s, p) bases of the incident and reflected rays; its sign is Mitsuba 3's
//     mueller::specular_reflection.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <utility>

namespace sbref {

using Complex = std::complex<double>;
using Mueller = std::array<double, 16>;  // row-major 4 x 4

constexpr double kPiF = 3.14159265358979323846;

// n cos(theta) in a medium of index n for Snell's invariant n1 sin(theta_1): the root with Im >= 0.
inline Complex normal_cos(Complex n, double n1_sin1) {
    Complex q = std::sqrt(n * n - Complex(n1_sin1 * n1_sin1, 0));
    return q.imag() < 0 ? -q : q;
}

// (r_s, r_p) from medium a into medium b, with q = n cos(theta) in each.
inline std::pair<Complex, Complex> amplitudes(Complex n_a, Complex q_a, Complex n_b, Complex q_b) {
    Complex rs = (q_a - q_b) / (q_a + q_b);
    Complex na2 = n_a * n_a, nb2 = n_b * n_b;
    Complex rp = (nb2 * q_a - na2 * q_b) / (nb2 * q_a + na2 * q_b);
    return {rs, rp};
}

// Complex (r_s, r_p) of light in medium n1 (real) meeting medium n2 (real or eta + i k) at cos_i.
inline std::pair<Complex, Complex> fresnel_amplitudes(double cos_i, double n1, Complex n2) {
    cos_i = std::clamp(cos_i, 0.0, 1.0);
    double n1_sin1 = n1 * std::sqrt(1 - cos_i * cos_i);
    return amplitudes(Complex(n1, 0), normal_cos(Complex(n1, 0), n1_sin1), n2, normal_cos(n2, n1_sin1));
}

// (R_s, R_p) of a smooth dielectric for light from outside, eta = n_inside / n_outside; 1 beyond
// the critical angle.
inline std::pair<double, double> fresnel_dielectric(double cos_i, double eta) {
    cos_i = std::clamp(cos_i, 0.0, 1.0);
    double sin_t2 = (1 - cos_i * cos_i) / (eta * eta);
    if (sin_t2 >= 1) return {1.0, 1.0};
    double cos_t = std::sqrt(std::clamp(1 - sin_t2, 0.0, 1.0));
    double rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    double rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return {rs * rs, rp * rp};
}

// (R_s, R_p) of a conductor of relative complex index eta + i k.
inline std::pair<double, double> fresnel_conductor_sp(double cos_i, double eta, double k) {
    Complex n(eta, k), c(std::clamp(cos_i, 0.0, 1.0), 0);
    Complex cos_t = std::sqrt(1.0 - (1.0 - c * c) / (n * n));
    Complex rs = (c - n * cos_t) / (c + n * cos_t);
    Complex rp = (n * c - cos_t) / (n * c + cos_t);
    return {std::norm(rs), std::norm(rp)};
}

// Unpolarised reflectance (R_s + R_p) / 2 of a conductor.
inline double fresnel_conductor(double cos_i, double eta, double k) {
    auto [rs, rp] = fresnel_conductor_sp(cos_i, eta, k);
    return 0.5 * (rs + rp);
}

// Mueller matrix [[A, B, 0, 0], [B, A, 0, 0], [0, 0, C, S], [0, 0, -S, C]] of a reflection with
// amplitudes r_s, r_p (this header's convention): A, B = (|r_s|^2 +- |r_p|^2) / 2, C + iS = conj(r_s) r_p.
inline Mueller mueller_reflection(Complex r_s, Complex r_p) {
    double a = 0.5 * (std::norm(r_s) + std::norm(r_p)), b = 0.5 * (std::norm(r_s) - std::norm(r_p));
    Complex cs = std::conj(r_s) * r_p;
    return {a, b, 0, 0, b, a, 0, 0, 0, 0, cs.real(), cs.imag(), 0, 0, -cs.imag(), cs.real()};
}

// Complex (r_s, r_p) of a film (real index n2, thickness d nm) between an exterior n1 (real) and a
// base n3 = eta + i k, at cos1 in the exterior and wavelength l (nm):
// r = (r12 + r23 e^{i phi}) / (1 + r12 r23 e^{i phi}), phi = 4 pi d n2 cos(theta_2) / l.
inline std::pair<Complex, Complex> airy_amplitudes(double cos1, double wavelength_nm, double n1, double n2,
                                                   double thickness_nm, Complex n3) {
    cos1 = std::clamp(cos1, 0.0, 1.0);
    double n1_sin1 = n1 * std::sqrt(1 - cos1 * cos1);
    Complex c1(n1, 0), c2(n2, 0);
    Complex q1 = normal_cos(c1, n1_sin1), q2 = normal_cos(c2, n1_sin1), q3 = normal_cos(n3, n1_sin1);
    auto [r12s, r12p] = amplitudes(c1, q1, c2, q2);
    auto [r23s, r23p] = amplitudes(c2, q2, n3, q3);
    Complex e = std::exp(Complex(0, 4 * kPiF * thickness_nm / wavelength_nm) * q2);
    return {(r12s + r23s * e) / (1.0 + r12s * r23s * e), (r12p + r23p * e) / (1.0 + r12p * r23p * e)};
}

// (R_s, R_p) of the film system.
inline std::pair<double, double> airy_reflectance(double cos1, double wavelength_nm, double n1, double n2,
                                                  double thickness_nm, Complex n3) {
    auto [rs, rp] = airy_amplitudes(cos1, wavelength_nm, n1, n2, thickness_nm, n3);
    return {std::norm(rs), std::norm(rp)};
}

// Mueller matrix of the film system's reflection.
inline Mueller airy_mueller(double cos1, double wavelength_nm, double n1, double n2, double thickness_nm, Complex n3) {
    auto [rs, rp] = airy_amplitudes(cos1, wavelength_nm, n1, n2, thickness_nm, n3);
    return mueller_reflection(rs, rp);
}

}  // namespace sbref
