// spectral_bench reference code: microfacet distributions, Smith masking and GGX visible-normal
// sampling. Header-only C++17, no dependencies. The numpy original, with the same names and
// conventions, is reference_code/appearance.py; tests/test_snippets.py compiles this header and
// checks it against that module (to 1e-6) and its sampler with a chi-square test.
//
// Conventions: local shading frame with the macro normal +z; directions are unit vectors pointing
// away from the surface; alpha is the distribution's width (Walter et al. 2007), anisotropic
// (alpha_x, alpha_y) along the frame's x and y axes.
//
// Sources (formulas written from the papers):
//   Walter, Marschner, Li, Torrance 2007, "Microfacet models for refraction through rough
//     surfaces", EGSR: GGX D (eq. 33), Beckmann D (eq. 25), separable G (eq. 23), the reflection
//     Jacobian 1 / (4 v.h) (eq. 14).
//   Heitz 2014, "Understanding the masking-shadowing function in microfacet-based BRDFs",
//     JCGT 3(2): Smith Lambda of GGX (eq. 72) and Beckmann (eq. 69), height-correlated G (eq. 99).
//   Heitz 2018, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4): the sampling
//     algorithm (section 2) and the pdf D_v(m) = G1(v) max(0, v.m) D(m) / v_z (eq. 1).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

namespace sbref {

using Real = double;
using Vec3 = std::array<Real, 3>;

constexpr Real kPi = 3.14159265358979323846;

inline Real dot(const Vec3 &a, const Vec3 &b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline Vec3 cross(const Vec3 &a, const Vec3 &b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline Vec3 normalize(const Vec3 &a) {
    Real inv = 1 / std::sqrt(dot(a, a));
    return {a[0] * inv, a[1] * inv, a[2] * inv};
}

// -- distributions -------------------------------------------------------------------------------
// GGX D(m) of a normal at cos_m from the macro normal: alpha^2 / (pi (cos^2 (alpha^2 - 1) + 1)^2).
inline Real ggx_d(Real cos_m, Real alpha) {
    Real c2 = std::clamp(cos_m, Real(0), Real(1));
    c2 *= c2;
    if (c2 <= 0) return 0;
    Real a2 = alpha * alpha, q = c2 * (a2 - 1) + 1;
    return a2 / (kPi * q * q);
}

// Beckmann D(m): exp(-tan^2 / alpha^2) / (pi alpha^2 cos^4).
inline Real beckmann_d(Real cos_m, Real alpha) {
    Real c2 = std::clamp(cos_m, Real(0), Real(1));
    c2 *= c2;
    if (c2 <= 0) return 0;
    Real a2 = alpha * alpha, tan2 = (1 - c2) / c2;
    return std::exp(-tan2 / a2) / (kPi * a2 * c2 * c2);
}

// Anisotropic GGX D(m) of a unit normal m: 1 / (pi ax ay (x^2/ax^2 + y^2/ay^2 + z^2)^2), 0 below.
inline Real ggx_d_aniso(const Vec3 &m, Real ax, Real ay) {
    if (m[2] <= 0) return 0;
    Real x = m[0] / ax, y = m[1] / ay, q = x * x + y * y + m[2] * m[2];
    return 1 / (kPi * ax * ay * q * q);
}

// -- Smith masking -------------------------------------------------------------------------------
inline Real tan_of(Real cos_v) {
    Real c = std::clamp(cos_v, Real(1e-12), Real(1));
    return std::sqrt(std::max(Real(1) - c * c, Real(0))) / c;
}

// GGX Lambda: (-1 + sqrt(1 + alpha^2 tan^2)) / 2.
inline Real ggx_lambda(Real cos_v, Real alpha) {
    Real at = alpha * tan_of(cos_v);
    return (-1 + std::sqrt(1 + at * at)) / 2;
}

// Beckmann Lambda, exact: (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)), a = 1 / (alpha tan).
inline Real beckmann_lambda(Real cos_v, Real alpha) {
    Real t = tan_of(cos_v);
    if (t <= 0) return 0;
    Real a = 1 / std::max(alpha * t, Real(1e-300));
    return (std::erf(a) - 1) / 2 + std::exp(-a * a) / (2 * a * std::sqrt(kPi));
}

// Anisotropic GGX Lambda with the projected roughness sqrt(ax^2 cos^2 phi + ay^2 sin^2 phi).
inline Real ggx_lambda_aniso(const Vec3 &v, Real ax, Real ay) {
    Real z = std::max(v[2], Real(1e-12));
    Real a2tan2 = ((ax * v[0]) * (ax * v[0]) + (ay * v[1]) * (ay * v[1])) / (z * z);
    return (-1 + std::sqrt(1 + a2tan2)) / 2;
}

enum class Distribution { GGX, Beckmann };
enum class Shadowing { Separable, HeightCorrelated };

inline Real microfacet_d(Distribution kind, Real cos_m, Real alpha) {
    return kind == Distribution::GGX ? ggx_d(cos_m, alpha) : beckmann_d(cos_m, alpha);
}
inline Real smith_lambda(Distribution kind, Real cos_v, Real alpha) {
    return kind == Distribution::GGX ? ggx_lambda(cos_v, alpha) : beckmann_lambda(cos_v, alpha);
}
// Smith G1(v) = 1 / (1 + Lambda(v)) for v above the microfacet.
inline Real smith_g1(Distribution kind, Real cos_v, Real alpha) { return 1 / (1 + smith_lambda(kind, cos_v, alpha)); }
// G2(i, o): separable G1(i) G1(o) (Mitsuba 3's) or height-correlated 1 / (1 + Lambda(i) + Lambda(o)).
inline Real smith_g(Distribution kind, Real cos_i, Real cos_o, Real alpha, Shadowing form) {
    Real li = smith_lambda(kind, cos_i, alpha), lo = smith_lambda(kind, cos_o, alpha);
    return form == Shadowing::Separable ? 1 / ((1 + li) * (1 + lo)) : 1 / (1 + li + lo);
}

// -- GGX visible normals (Heitz 2018) -----------------------------------------------------------------
// A normal distributed as D_v(m) for the view direction v (v_z > 0), from u1, u2 uniform in [0, 1).
inline Vec3 ggx_sample_vndf(const Vec3 &v, Real ax, Real ay, Real u1, Real u2) {
    Vec3 vh = normalize({ax * v[0], ay * v[1], v[2]});  // the view in the unit-roughness configuration
    Real lensq = vh[0] * vh[0] + vh[1] * vh[1];
    Vec3 t1 = lensq > 0 ? Vec3{-vh[1] / std::sqrt(lensq), vh[0] / std::sqrt(lensq), 0} : Vec3{1, 0, 0};
    Vec3 t2 = cross(vh, t1);
    Real r = std::sqrt(u1), phi = 2 * kPi * u2;
    Real p1 = r * std::cos(phi), p2 = r * std::sin(phi);
    Real s = Real(0.5) * (1 + vh[2]);  // warp the disk towards the visible half of the hemisphere
    p2 = (1 - s) * std::sqrt(std::max(Real(1) - p1 * p1, Real(0))) + s * p2;
    Real p3 = std::sqrt(std::max(Real(1) - p1 * p1 - p2 * p2, Real(0)));
    Vec3 nh{p1 * t1[0] + p2 * t2[0] + p3 * vh[0], p1 * t1[1] + p2 * t2[1] + p3 * vh[1],
            p1 * t1[2] + p2 * t2[2] + p3 * vh[2]};
    return normalize({ax * nh[0], ay * nh[1], std::max(nh[2], Real(0))});  // back to the ellipsoid
}

// Its density over the solid angle of m: G1(v) max(0, v.m) D(m) / v_z.
inline Real ggx_vndf_pdf(const Vec3 &v, const Vec3 &m, Real ax, Real ay) {
    if (v[2] <= 0) return 0;
    Real g1 = 1 / (1 + ggx_lambda_aniso(v, ax, ay));
    return g1 * std::max(dot(v, m), Real(0)) * ggx_d_aniso(m, ax, ay) / v[2];
}

// The mirror direction of v about m: 2 (v.m) m - v.
inline Vec3 reflect(const Vec3 &v, const Vec3 &m) {
    Real d = 2 * dot(v, m);
    return {d * m[0] - v[0], d * m[1] - v[1], d * m[2] - v[2]};
}

// Density over the solid angle of l of reflecting v about a VNDF sample: D_v(h) / (4 v.h).
inline Real ggx_reflection_pdf(const Vec3 &v, const Vec3 &l, Real ax, Real ay) {
    Vec3 h = normalize({v[0] + l[0], v[1] + l[1], v[2] + l[2]});
    Real vh = dot(v, h);
    if (vh <= 0 || l[2] <= 0) return 0;
    return ggx_vndf_pdf(v, h, ax, ay) / (4 * vh);
}

}  // namespace sbref
