"""snippets/ (header-only C++17): compiled with the system compiler into a small driver
(tests/snippets_driver.cpp), compared with reference_code/appearance.py to 1e-6 on random inputs,
and its visible-normal sampler checked with a chi-square test (scipy.stats). Skipped, with the
reason, where no C++ compiler is found."""
import os
import shutil
import subprocess

import numpy as np
import pytest

from conftest import ROOT
from spectral_bench.reference_code import appearance as ap

from test_reference_code import chi_square_of_samples, sph

pytestmark = pytest.mark.slow  # every test here costs over ~1 s of CPU, its children and module fixtures counted (benchmarks/TESTS.md)

SNIPPETS = ROOT / "snippets"
DRIVER = ROOT / "tests" / "snippets_driver.cpp"
TOL = 1e-6


def compiler():
    """The system C++ compiler: $CXX, else c++, g++ or clang++ on PATH (None if there is none)."""
    for name in ([os.environ["CXX"]] if os.environ.get("CXX") else []) + ["c++", "g++", "clang++"]:
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.fixture(scope="module")
def driver(tmp_path_factory):
    cxx = compiler()
    if cxx is None:
        pytest.skip("no C++ compiler found ($CXX, c++, g++, clang++): the snippets are not compiled")
    exe = tmp_path_factory.mktemp("snippets") / "driver"
    proc = subprocess.run([cxx, "-std=c++17", "-O1", "-Wall", "-Wextra", "-pedantic", "-Werror", f"-I{SNIPPETS}",
                           str(DRIVER), "-o", str(exe)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{cxx} failed:\n{proc.stderr[-4000:]}"
    return exe


def run(exe, lines):
    """Each line's results from the driver, as float arrays."""
    proc = subprocess.run([str(exe)], input="".join(f"{line}\n" for line in lines), capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return [np.array(row.split(), dtype=np.float64) for row in proc.stdout.splitlines()]


def fmt(*values):
    return " ".join(repr(float(v)) for v in values)


def random_cases(n=200, seed=2024):
    """[(driver line, expected values from the numpy module)] over random inputs."""
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n):
        c, c2 = rng.uniform(0.0, 1.0, 2)
        a, ax, ay = rng.uniform(0.02, 1.5, 3)
        kind = int(rng.integers(2))
        form = int(rng.integers(2))
        v = sph(rng.uniform(0, 1.45), rng.uniform(0, 2 * np.pi))
        m = sph(rng.uniform(0, 1.5), rng.uniform(0, 2 * np.pi))
        l = sph(rng.uniform(0, 1.5), rng.uniform(0, 2 * np.pi))
        u1, u2 = rng.uniform(0, 1, 2)
        eta, k = rng.uniform(0.1, 3.0), rng.uniform(0.0, 5.0)
        n_real = rng.uniform(0.5, 2.5)
        wl = rng.uniform(360, 830)
        n1, n2, d = rng.uniform(1.0, 1.6), rng.uniform(1.0, 2.5), rng.uniform(0, 2000)
        rs, rp = complex(*rng.normal(size=2)), complex(*rng.normal(size=2))
        dist = ("ggx", "beckmann")[kind]
        cases += [
            (f"ggx_d {fmt(c, a)}", [ap.ggx_d(c, a)]),
            (f"beckmann_d {fmt(c, a)}", [ap.beckmann_d(c, a)]),
            (f"ggx_lambda {fmt(c, a)}", [ap.ggx_lambda(c, a)]),
            (f"beckmann_lambda {fmt(c, a)}", [ap.beckmann_lambda(c, a)]),
            (f"smith_g1 {fmt(kind, c, a)}", [ap.smith_g1(dist, c, a)]),
            (f"smith_g {fmt(kind, form, c, c2, a)}",
             [ap.smith_g(dist, c, c2, a, ("separable", "height-correlated")[form])]),
            (f"ggx_d_aniso {fmt(*m, ax, ay)}", [ap.ggx_d_aniso(m, ax, ay)]),
            (f"ggx_lambda_aniso {fmt(*v, ax, ay)}", [ap.ggx_lambda_aniso(v, ax, ay)]),
            (f"ggx_sample_vndf {fmt(*v, ax, ay, u1, u2)}", ap.ggx_sample_vndf(v, ax, ay, u1, u2)),
            (f"ggx_vndf_pdf {fmt(*v, *m, ax, ay)}", [ap.ggx_vndf_pdf(v, m, ax, ay)]),
            (f"ggx_reflection_pdf {fmt(*v, *l, ax, ay)}", [ap.ggx_reflection_pdf(v, l, ax, ay)]),
            (f"fresnel_dielectric {fmt(c, n_real)}", ap.fresnel_dielectric(c, n_real)),
            (f"fresnel_conductor {fmt(c, eta, k)}", [ap.fresnel_conductor(c, eta, k)]),
            (f"fresnel_conductor_sp {fmt(c, eta, k)}", ap.fresnel_conductor_sp(c, eta, k)),
            (f"fresnel_amplitudes {fmt(c, n1, eta, k)}", _split(ap.fresnel_amplitudes(c, n1, eta + 1j * k))),
            (f"mueller_reflection {fmt(rs.real, rs.imag, rp.real, rp.imag)}", ap.mueller_reflection(rs, rp).ravel()),
            (f"airy_amplitudes {fmt(c, wl, n1, n2, d, eta, k)}", _split(ap.airy_amplitudes(c, wl, n1, n2, d, eta + 1j * k))),
            (f"airy_reflectance {fmt(c, wl, n1, n2, d, eta, k)}", ap.airy_reflectance(c, wl, n1, n2, d, eta + 1j * k)),
            (f"airy_mueller {fmt(c, wl, n1, n2, d, eta, k)}", ap.airy_mueller(c, wl, n1, n2, d, eta + 1j * k).ravel()),
        ]
        b, cc = rng.uniform(0.1, 2, 3), rng.uniform(0.0, 0.06, 3) * [1, 1, 2000]
        li, lo = rng.uniform(290, 840, 2)
        bands = (rng.uniform(350, 500), rng.uniform(5, 50), rng.uniform(500, 700), rng.uniform(5, 80), rng.uniform(0, 0.02))
        ca, cb, cc2 = rng.uniform(1.3, 1.8), rng.uniform(0, 0.02), rng.uniform(0, 1e-3)
        cases += [
            (f"sellmeier {fmt(wl, *b, *cc)}", [ap.sellmeier(wl, b, cc)]),
            (f"cauchy {fmt(wl, ca, cb, cc2)}", [ap.cauchy(wl, ca, cb, cc2)]),
            (f"art_fluorescence_bands {fmt(li, lo, *bands)}", [ap.art_fluorescence_bands(li, lo, *bands)]),
        ]
    return cases


def _split(pair):
    return [pair[0].real, pair[0].imag, pair[1].real, pair[1].imag]


def test_cpp_agrees_with_the_numpy_module_on_random_inputs(driver):
    cases = random_cases()
    got = run(driver, [line for line, _ in cases])
    assert len(got) == len(cases)
    bad = []
    for (line, expected), values in zip(cases, got):
        expected = np.asarray(np.ravel(np.asarray(expected, dtype=np.float64)))
        if values.shape != expected.shape or not np.allclose(values, expected, rtol=TOL, atol=TOL, equal_nan=True):
            bad.append((line, values.tolist(), expected.tolist()))
    assert bad == [], f"{len(bad)} of {len(cases)} calls differ; first: {bad[:3]}"
    functions = {line.split()[0] for line, _ in cases}
    assert len(functions) == 22  # every function of the headers is exercised


def test_the_comparison_sees_a_difference(driver):
    """A wrong expectation (GGX D of alpha 0.3 where the driver is asked for 0.31) is caught."""
    (value,) = run(driver, [f"ggx_d {fmt(0.9, 0.31)}"])
    assert not np.allclose(value, [ap.ggx_d(0.9, 0.3)], rtol=TOL, atol=TOL)


@pytest.mark.parametrize("ax, ay, theta_v, phi_v", [(0.5, 0.5, 0.6, 0.0), (0.2, 0.7, 1.2, 0.8)])
def test_cpp_vndf_sampler_passes_a_chi_square_test(driver, ax, ay, theta_v, phi_v):
    """Heitz 2018 (JCGT 7(4)): the C++ sampler, driven by std::mt19937_64, draws m with density
    D_v(m); Pearson's chi-square of 200,000 samples over ~190 bins, level 1e-3 (scipy.stats)."""
    v = sph(theta_v, phi_v)
    m = np.vstack(run(driver, [f"vndf_samples {fmt(*v, ax, ay, 200_000, 12345)}"]))
    assert m.shape == (200_000, 3)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 1.0, atol=1e-12)
    p, dof = chi_square_of_samples(m, ax, ay, v)
    assert dof > 100 and p > 1e-3
