// Test driver of snippets/ (tests/test_snippets.py): reads one call per line, "<function> <args...>",
// and prints the results of that call on one line (%.17g). One extra command, "vndf_samples vx vy
// vz ax ay count seed", prints count sampled normals drawn with the header's sampler and
// std::mt19937_64, for the chi-square test.
#include <cstdio>
#include <functional>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "spectral_bench_reference.hpp"

using namespace sbref;

namespace {

std::vector<double> read(std::istringstream &in, int n) {
    std::vector<double> v(n);
    for (double &x : v) in >> x;
    return v;
}

Vec3 vec(const std::vector<double> &a, int i) { return {a[i], a[i + 1], a[i + 2]}; }
Distribution kind(double k) { return k == 0 ? Distribution::GGX : Distribution::Beckmann; }

void print(const std::vector<double> &out) {
    for (std::size_t i = 0; i < out.size(); ++i) std::printf(i ? " %.17g" : "%.17g", out[i]);
    std::printf("\n");
}

using Call = std::function<std::vector<double>(std::istringstream &)>;

const std::map<std::string, Call> &calls() {
    static const std::map<std::string, Call> table = {
        {"ggx_d", [](auto &in) { auto a = read(in, 2); return std::vector<double>{ggx_d(a[0], a[1])}; }},
        {"beckmann_d", [](auto &in) { auto a = read(in, 2); return std::vector<double>{beckmann_d(a[0], a[1])}; }},
        {"ggx_lambda", [](auto &in) { auto a = read(in, 2); return std::vector<double>{ggx_lambda(a[0], a[1])}; }},
        {"beckmann_lambda", [](auto &in) { auto a = read(in, 2); return std::vector<double>{beckmann_lambda(a[0], a[1])}; }},
        {"smith_g1", [](auto &in) { auto a = read(in, 3); return std::vector<double>{smith_g1(kind(a[0]), a[1], a[2])}; }},
        {"smith_g", [](auto &in) {
             auto a = read(in, 5);
             auto form = a[1] == 0 ? Shadowing::Separable : Shadowing::HeightCorrelated;
             return std::vector<double>{smith_g(kind(a[0]), a[2], a[3], a[4], form)};
         }},
        {"ggx_d_aniso", [](auto &in) { auto a = read(in, 5); return std::vector<double>{ggx_d_aniso(vec(a, 0), a[3], a[4])}; }},
        {"ggx_lambda_aniso", [](auto &in) { auto a = read(in, 5); return std::vector<double>{ggx_lambda_aniso(vec(a, 0), a[3], a[4])}; }},
        {"ggx_sample_vndf", [](auto &in) {
             auto a = read(in, 7);
             Vec3 m = ggx_sample_vndf(vec(a, 0), a[3], a[4], a[5], a[6]);
             return std::vector<double>{m[0], m[1], m[2]};
         }},
        {"ggx_vndf_pdf", [](auto &in) { auto a = read(in, 8); return std::vector<double>{ggx_vndf_pdf(vec(a, 0), vec(a, 3), a[6], a[7])}; }},
        {"ggx_reflection_pdf", [](auto &in) {
             auto a = read(in, 8);
             return std::vector<double>{ggx_reflection_pdf(vec(a, 0), vec(a, 3), a[6], a[7])};
         }},
        {"fresnel_dielectric", [](auto &in) {
             auto a = read(in, 2);
             auto [rs, rp] = fresnel_dielectric(a[0], a[1]);
             return std::vector<double>{rs, rp};
         }},
        {"fresnel_conductor", [](auto &in) { auto a = read(in, 3); return std::vector<double>{fresnel_conductor(a[0], a[1], a[2])}; }},
        {"fresnel_conductor_sp", [](auto &in) {
             auto a = read(in, 3);
             auto [rs, rp] = fresnel_conductor_sp(a[0], a[1], a[2]);
             return std::vector<double>{rs, rp};
         }},
        {"fresnel_amplitudes", [](auto &in) {
             auto a = read(in, 4);
             auto [rs, rp] = fresnel_amplitudes(a[0], a[1], Complex(a[2], a[3]));
             return std::vector<double>{rs.real(), rs.imag(), rp.real(), rp.imag()};
         }},
        {"mueller_reflection", [](auto &in) {
             auto a = read(in, 4);
             auto m = mueller_reflection(Complex(a[0], a[1]), Complex(a[2], a[3]));
             return std::vector<double>(m.begin(), m.end());
         }},
        {"airy_amplitudes", [](auto &in) {
             auto a = read(in, 7);
             auto [rs, rp] = airy_amplitudes(a[0], a[1], a[2], a[3], a[4], Complex(a[5], a[6]));
             return std::vector<double>{rs.real(), rs.imag(), rp.real(), rp.imag()};
         }},
        {"airy_reflectance", [](auto &in) {
             auto a = read(in, 7);
             auto [rs, rp] = airy_reflectance(a[0], a[1], a[2], a[3], a[4], Complex(a[5], a[6]));
             return std::vector<double>{rs, rp};
         }},
        {"airy_mueller", [](auto &in) {
             auto a = read(in, 7);
             auto m = airy_mueller(a[0], a[1], a[2], a[3], a[4], Complex(a[5], a[6]));
             return std::vector<double>(m.begin(), m.end());
         }},
        {"sellmeier", [](auto &in) {
             auto a = read(in, 7);
             double b[3] = {a[1], a[2], a[3]}, c[3] = {a[4], a[5], a[6]};
             return std::vector<double>{sellmeier(a[0], b, c, 3)};
         }},
        {"cauchy", [](auto &in) { auto a = read(in, 4); return std::vector<double>{cauchy(a[0], a[1], a[2], a[3])}; }},
        {"art_fluorescence_bands", [](auto &in) {
             auto a = read(in, 7);
             return std::vector<double>{art_fluorescence_bands(a[0], a[1], a[2], a[3], a[4], a[5], a[6])};
         }},
    };
    return table;
}

}  // namespace

int main() {
    std::string line;
    while (std::getline(std::cin, line)) {
        std::istringstream in(line);
        std::string name;
        in >> name;
        if (name == "vndf_samples") {
            auto a = read(in, 7);
            std::mt19937_64 rng(static_cast<unsigned long long>(a[6]));
            std::uniform_real_distribution<double> u(0.0, 1.0);
            for (long i = 0; i < static_cast<long>(a[5]); ++i) {
                double u1 = u(rng), u2 = u(rng);
                Vec3 m = ggx_sample_vndf(vec(a, 0), a[3], a[4], u1, u2);
                std::printf("%.17g %.17g %.17g\n", m[0], m[1], m[2]);
            }
            continue;
        }
        auto it = calls().find(name);
        if (it == calls().end()) {
            std::fprintf(stderr, "unknown function %s\n", name.c_str());
            return 2;
        }
        print(it->second(in));
    }
    return 0;
}
