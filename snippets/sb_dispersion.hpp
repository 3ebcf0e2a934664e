// spectral_bench reference code: index of refraction models and ART's fluorescence bands.
// Header-only C++17, no dependencies; the numpy original is reference_code/appearance.py.
//
// Sellmeier: n^2 = 1 + sum_i B_i l^2 / (l^2 - C_i), l in micrometres, C_i in um^2 (SCHOTT,
// "TIE-29: Refractive Index and Dispersion", 2016). SCHOTT N-BK7: B = {1.03961212, 0.231792344,
// 1.01046945}, C = {0.00600069867, 0.0200179144, 103.560653} give n_d (587.56 nm) = 1.51680.
// Cauchy: n = A + B / l^2 + C / l^4, l in um.
// ART 2.1.2's CONST_FLUORESCENT_COLOUR (ArCrosstalk500.c): re-radiation P(l_i, l_o) in 1/nm,
// strength * max(0, min(1 - |l_i - a| / wa, 1 - |l_o - e| / we)), zero where l_o <= l_i and
// outside 300-830 nm on either axis.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace sbref {

// n at wavelength_nm of a Sellmeier glass with `terms` coefficients (NaN inside an absorption band).
inline double sellmeier(double wavelength_nm, const double *B, const double *C, std::size_t terms) {
    double l2 = (wavelength_nm * 1e-3) * (wavelength_nm * 1e-3), n2 = 1;
    for (std::size_t i = 0; i < terms; ++i) n2 += B[i] * l2 / (l2 - C[i]);
    return std::sqrt(n2);
}

inline double cauchy(double wavelength_nm, double A, double B = 0, double C = 0) {
    double l2 = (wavelength_nm * 1e-3) * (wavelength_nm * 1e-3);
    return A + B / l2 + C / (l2 * l2);
}

constexpr double kFluorescenceMinNm = 300, kFluorescenceMaxNm = 830;

inline double art_fluorescence_bands(double l_i, double l_o, double absorption_peak, double absorption_width,
                                     double emission_peak, double emission_width, double strength) {
    if (!(l_o > l_i) || l_i < kFluorescenceMinNm || l_i > kFluorescenceMaxNm || l_o < kFluorescenceMinNm ||
        l_o > kFluorescenceMaxNm)
        return 0;
    double fx = 1 - std::abs(l_i - absorption_peak) / absorption_width;
    double fy = 1 - std::abs(l_o - emission_peak) / emission_width;
    return strength * std::max(0.0, std::min(fx, fy));
}

}  // namespace sbref
