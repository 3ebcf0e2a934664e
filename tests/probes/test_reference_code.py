"""reference_code/appearance.py against published values (each test names its source), the
project's ground truth against it (one implementation), and its independence of the project."""
import ast
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy import integrate, stats

from conftest import ROOT
from spectral_bench.batch.verdict import airy, optics
from spectral_bench.exporters import dispersion, fluorescence
from spectral_bench.reference_code import appearance as ap

MODULE = ROOT / "reference_code" / "appearance.py"


def sph(theta, phi):
    """Unit vectors (..., 3) at polar angle theta from +z and azimuth phi."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)


def hemisphere_integral(f, n_theta=1200, n_phi=240):
    """Integral of f(m) over the upper hemisphere's solid angle: Gauss-Legendre in cos(theta)
    (dw = dcos dphi) on sub-intervals refined towards the pole (narrow lobes), midpoints in phi."""
    edges = np.concatenate([[0.0], np.geomspace(1e-6, 1.0, 60)])  # in 1 - cos(theta)
    x, w = np.polynomial.legendre.leggauss(n_theta // 60)
    one_minus = np.concatenate([(b - a) / 2 * x + (a + b) / 2 for a, b in zip(edges[:-1], edges[1:])])
    weights = np.concatenate([(b - a) / 2 * w for a, b in zip(edges[:-1], edges[1:])])
    cos = 1.0 - one_minus
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    m = sph(np.arccos(np.clip(cos, -1, 1))[:, None], phi[None, :])
    return float(np.sum(f(m) * weights[:, None]) * 2 * np.pi / n_phi)


# -- the module stands alone ---------------------------------------------------------------------
def test_the_module_imports_only_numpy_and_scipy():
    tree = ast.parse(MODULE.read_text())
    roots = {(n.module or "").split(".")[0] if isinstance(n, ast.ImportFrom) else a.name.split(".")[0]
             for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))
             for a in (n.names if isinstance(n, ast.Import) else [n])}
    assert roots == {"numpy", "scipy"}
    assert not any(isinstance(n, ast.ImportFrom) and n.level for n in ast.walk(tree))  # no relative import


def test_the_module_runs_copied_out_of_the_project(tmp_path):
    """Copied alone into an empty folder, imported by a fresh interpreter: it works."""
    (tmp_path / "appearance.py").write_bytes(MODULE.read_bytes())
    code = textwrap.dedent("""
        import sys, appearance
        assert not [m for m in sys.modules if m.startswith("spectral_bench")]
        print(round(float(appearance.fresnel_dielectric(1.0, 1.5)[0]), 6))
    """)
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "0.04"


# -- microfacet distributions and masking ----------------------------------------------------------
@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
@pytest.mark.parametrize("alpha", [0.05, 0.3, 1.0])
def test_projected_microfacet_area_is_one(kind, alpha):
    """Walter et al. 2007 eq. 4: the integral of D(m) cos(theta_m) over the hemisphere is 1."""
    got = hemisphere_integral(lambda m: ap.microfacet_d(kind, m[..., 2], alpha) * m[..., 2])
    assert got == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("ax, ay", [(0.2, 0.2), (0.1, 0.6), (0.9, 0.3)])
def test_anisotropic_ggx_projected_area_is_one(ax, ay):
    got = hemisphere_integral(lambda m: ap.ggx_d_aniso(m, ax, ay) * m[..., 2])
    assert got == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
@pytest.mark.parametrize("alpha", [0.1, 0.5, 1.2])
@pytest.mark.parametrize("theta_v", [0.0, 0.7, 1.3, 1.5])
def test_visible_projected_area_gives_smith_lambda(kind, alpha, theta_v):
    """Heitz 2014 (JCGT 3(2)), the definition of Lambda: the projected area of the microfacets facing
    v, integral of max(0, v.m) D(m) dm, is cos(theta_v) (1 + Lambda(v)); with G1 = 1 / (1 + Lambda)
    the visible projected area G1 * that is the geometric surface's cos(theta_v)."""
    v = sph(theta_v, 0.3)
    area = hemisphere_integral(lambda m: np.maximum(m @ v, 0.0) * ap.microfacet_d(kind, m[..., 2], alpha))
    assert area == pytest.approx(np.cos(theta_v) * (1.0 + ap.smith_lambda(kind, np.cos(theta_v), alpha)), rel=1e-5)
    assert area * ap.smith_g1(kind, np.cos(theta_v), alpha) == pytest.approx(np.cos(theta_v), rel=1e-5)


@pytest.mark.parametrize("ax, ay, theta_v, phi_v", [(0.1, 0.6, 1.2, 0.4), (0.9, 0.3, 0.5, 2.0)])
def test_anisotropic_lambda_follows_the_same_identity(ax, ay, theta_v, phi_v):
    v = sph(theta_v, phi_v)
    area = hemisphere_integral(lambda m: np.maximum(m @ v, 0.0) * ap.ggx_d_aniso(m, ax, ay))
    assert area == pytest.approx(np.cos(theta_v) * (1.0 + ap.ggx_lambda_aniso(v, ax, ay)), rel=1e-5)


def test_shadowing_forms():
    """Heitz 2014: the height-correlated form is never below the separable one (it counts a
    point masked in both directions once) and both equal G1 of the other direction when one
    direction is the normal (Lambda = 0)."""
    rng = np.random.default_rng(3)
    ci, co, a = rng.uniform(0.05, 1, 500), rng.uniform(0.05, 1, 500), rng.uniform(0.05, 1.5, 500)
    for kind in ("ggx", "beckmann"):
        sep, hc = ap.smith_g(kind, ci, co, a, "separable"), ap.smith_g(kind, ci, co, a, "height-correlated")
        assert np.all(hc >= sep - 1e-15) and np.all(hc <= 1.0)
        np.testing.assert_allclose(ap.smith_g(kind, 1.0, co, a, "height-correlated"), ap.smith_g1(kind, co, a), rtol=1e-12)
        np.testing.assert_allclose(ap.smith_g(kind, 1.0, co, a, "separable"), ap.smith_g1(kind, co, a), rtol=1e-12)


# -- visible-normal sampling (Heitz 2018) ------------------------------------------------------------
VNDF_CASES = [(0.5, 0.5, 0.6, 0.0), (0.2, 0.7, 1.2, 0.8), (0.9, 0.3, 0.0, 0.0), (0.05, 0.05, 1.4, 2.5)]


@pytest.mark.parametrize("ax, ay, theta_v, phi_v", VNDF_CASES)
def test_vndf_pdf_integrates_to_one(ax, ay, theta_v, phi_v):
    """Heitz 2018 eq. 1-2 (JCGT 7(4)): D_v(m) = G1(v) max(0, v.m) D(m) / v_z is a density."""
    v = sph(theta_v, phi_v)
    assert hemisphere_integral(lambda m: ap.ggx_vndf_pdf(v, m, ax, ay)) == pytest.approx(1.0, abs=1e-5)


def vndf_bins(ax, ay, v, n_cos=12, n_phi=16, sub=12):
    """Bin edges in (cos theta_m, phi_m) and each bin's probability under ggx_vndf_pdf (midpoint
    rule on sub x sub points per bin; dw = dcos dphi). Cos edges follow the pdf's own quantiles
    of cos theta (from a fine quadrature), so no bin is nearly empty."""
    fine = np.linspace(0, 1, 4001)
    mid = 0.5 * (fine[1:] + fine[:-1])
    phis = (np.arange(720) + 0.5) * 2 * np.pi / 720
    marg = ap.ggx_vndf_pdf(v, sph(np.arccos(mid)[:, None], phis[None, :]), ax, ay).sum(axis=1)
    cdf = np.concatenate([[0], np.cumsum(marg)]) / marg.sum()
    edges_c = np.interp(np.linspace(0, 1, n_cos + 1), cdf, fine)
    edges_c[0], edges_c[-1] = 0.0, 1.0
    edges_p = np.linspace(-np.pi, np.pi, n_phi + 1)
    probs = np.zeros((n_cos, n_phi))
    t = (np.arange(sub) + 0.5) / sub
    for i in range(n_cos):
        c = edges_c[i] + (edges_c[i + 1] - edges_c[i]) * t
        for j in range(n_phi):
            p = edges_p[j] + (edges_p[j + 1] - edges_p[j]) * t
            m = sph(np.arccos(c)[:, None], p[None, :])
            probs[i, j] = ap.ggx_vndf_pdf(v, m, ax, ay).mean() * (edges_c[i + 1] - edges_c[i]) * (edges_p[j + 1] - edges_p[j])
    return edges_c, edges_p, probs


def chi_square_of_samples(m, ax, ay, v):
    """(p-value, dof) of Pearson's chi-square test of sampled normals m against ggx_vndf_pdf."""
    edges_c, edges_p, probs = vndf_bins(ax, ay, v)
    counts, _, _ = np.histogram2d(m[:, 2], np.arctan2(m[:, 1], m[:, 0]), bins=[edges_c, edges_p])
    expected = probs.ravel() / probs.sum() * len(m)
    keep = expected >= 5  # Pearson's approximation needs >= 5 expected per bin
    obs = counts.ravel()[keep]
    exp = expected[keep] * obs.sum() / expected[keep].sum()
    return stats.chisquare(obs, exp).pvalue, keep.sum() - 1


@pytest.mark.parametrize("ax, ay, theta_v, phi_v", VNDF_CASES[:3])
def test_vndf_samples_follow_the_pdf(ax, ay, theta_v, phi_v):
    """Heitz 2018: ggx_sample_vndf draws m with density D_v(m). Pearson's chi-square of 200,000
    samples (fixed seed) over about 190 bins; the test's level is 1e-3."""
    v = sph(theta_v, phi_v)
    u = np.random.default_rng(7).random((200_000, 2))
    m = ap.ggx_sample_vndf(v, ax, ay, u[:, 0], u[:, 1])
    np.testing.assert_allclose(np.linalg.norm(m, axis=-1), 1.0, atol=1e-12)
    assert np.all(m @ v > -1e-12)  # only normals facing v are visible
    p, dof = chi_square_of_samples(m, ax, ay, v)
    assert dof > 100 and p > 1e-3


def test_the_chi_square_test_rejects_a_wrong_sampler():
    """The same test on the distribution of normals D(m) cos (not the visible normals) fails."""
    ax = ay = 0.5
    v = sph(1.2, 0.0)
    u = np.random.default_rng(7).random((200_000, 2))
    m = ap.ggx_sample_vndf(np.array([0.0, 0.0, 1.0]), ax, ay, u[:, 0], u[:, 1])  # D(m) cos: v = normal
    p, _ = chi_square_of_samples(m, ax, ay, v)
    assert p < 1e-6


def test_reflection_pdf_integrates_to_the_reflected_fraction():
    """Heitz 2018 eq. 17: reflecting v about VNDF samples gives l with density D_v(h) / (4 v.h);
    it integrates over the upper hemisphere to the fraction of reflections that stay above it."""
    ax, ay, v = 0.4, 0.25, sph(0.9, 0.5)
    u = np.random.default_rng(11).random((400_000, 2))
    l = ap.reflect(v, ap.ggx_sample_vndf(v, ax, ay, u[:, 0], u[:, 1]))
    above = float(np.mean(l[:, 2] > 0))
    got = hemisphere_integral(lambda d: ap.ggx_reflection_pdf(v, d, ax, ay))
    assert got == pytest.approx(above, abs=4 * np.sqrt(above * (1 - above) / len(u)) + 1e-5)


# -- Fresnel ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [1.333, 1.5, 2.4])
def test_fresnel_at_normal_incidence_and_brewster(n):
    """Hecht, Optics, 5th ed., 4.6: R = ((n - 1) / (n + 1))^2 at normal incidence (4 % for
    n = 1.5); r_p = 0 at Brewster's angle tan(theta_B) = n (eq. 4.52), from both sides."""
    rs, rp = ap.fresnel_dielectric(1.0, n)
    assert rs == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12) and rp == pytest.approx(rs, rel=1e-12)
    assert abs(ap.fresnel_amplitudes(np.cos(np.arctan(n)), 1.0, n)[1]) < 1e-12
    assert ap.fresnel_dielectric(np.cos(np.arctan(n)), n)[1] < 1e-24
    assert ap.fresnel_dielectric(np.cos(np.arctan(1 / n)), 1 / n)[1] < 1e-24  # internal Brewster angle
    assert abs(ap.fresnel_amplitudes(np.cos(np.arctan(n)), 1.0, n)[0]) > 0.1


def test_fresnel_total_internal_reflection():
    """Hecht 4.7: beyond the critical angle sin(theta_c) = n2 / n1, R = 1 (|r| = 1 with a phase)."""
    theta_c = np.arcsin(1 / 1.5)
    cos = np.cos(np.linspace(theta_c + 1e-6, np.pi / 2 - 1e-6, 50))
    rs, rp = ap.fresnel_amplitudes(cos, 1.5, 1.0)
    np.testing.assert_allclose(np.abs(rs), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(rp), 1.0, atol=1e-12)
    for r in ap.fresnel_dielectric(cos, 1 / 1.5):
        np.testing.assert_allclose(r, 1.0)


def test_fresnel_amplitudes_reverse_with_stokes_relations():
    """Stokes relations (Hecht eq. 4.86-4.87): r' = -r for the reverse path, and r^2 + t t' = 1."""
    n, cos_i = 1.7, np.linspace(0.05, 1.0, 40)
    cos_t = np.sqrt(1 - (1 - cos_i**2) / n**2)
    rs, rp = ap.fresnel_amplitudes(cos_i, 1.0, n)
    rs_back, rp_back = ap.fresnel_amplitudes(cos_t, n, 1.0)
    np.testing.assert_allclose(rs_back, -rs, atol=1e-12)
    np.testing.assert_allclose(rp_back, -rp, atol=1e-12)
    r_s, r_p = ap.fresnel_dielectric(cos_i, n)
    np.testing.assert_allclose(np.abs(rs) ** 2, r_s, atol=1e-12)
    np.testing.assert_allclose(np.abs(rp) ** 2, r_p, atol=1e-12)


@pytest.mark.parametrize("eta, k", [(0.27, 2.78), (1.2, 2.6), (2.9, 3.0)])
def test_conductor_at_normal_incidence(eta, k):
    """Born and Wolf 14.2: R = ((n - 1)^2 + k^2) / ((n + 1)^2 + k^2) at normal incidence; R_s = R_p."""
    expected = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)
    assert ap.fresnel_conductor(1.0, eta, k) == pytest.approx(expected, rel=1e-12)
    rs, rp = ap.fresnel_conductor_sp(1.0, eta, k)
    assert rs == pytest.approx(rp, rel=1e-12)
    s, p = ap.fresnel_amplitudes(np.linspace(0, 1, 30), 1.0, eta + 1j * k)
    np.testing.assert_allclose(0.5 * (abs(s) ** 2 + abs(p) ** 2), ap.fresnel_conductor(np.linspace(0, 1, 30), eta, k),
                               atol=1e-12)


def test_mueller_reflection_at_a_mirror_and_at_brewster():
    """Collett 2005: a reflection's Mueller matrix is non-depolarising (A^2 = B^2 + C^2 + S^2); at
    normal incidence it is R diag(1, 1, -1, -1) (circular polarisation changes handedness on
    reflection, Hecht 8.10); at Brewster's angle it is R_s / 2 times the ideal s polariser."""
    n = 1.5
    m = ap.mueller_reflection(*ap.fresnel_amplitudes(1.0, 1.0, n))
    np.testing.assert_allclose(m, 0.04 * np.diag([1.0, 1.0, -1.0, -1.0]), atol=1e-15)
    rs = ap.fresnel_dielectric(np.cos(np.arctan(n)), n)[0]
    m = ap.mueller_reflection(*ap.fresnel_amplitudes(np.cos(np.arctan(n)), 1.0, n))
    polariser = 0.5 * np.array([[1, 1, 0, 0], [1, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]])
    np.testing.assert_allclose(m, rs * polariser, atol=1e-14)
    cos = np.linspace(0.01, 1, 30)
    mm = ap.mueller_reflection(*ap.fresnel_amplitudes(cos, 1.0, 0.2 + 3.0j))
    a, b, c, s = mm[:, 0, 0], mm[:, 0, 1], mm[:, 2, 2], mm[:, 2, 3]
    np.testing.assert_allclose(a**2, b**2 + c**2 + s**2, rtol=1e-12)


def test_mueller_reflection_is_mitsuba_s():
    """Mitsuba 3's mueller::specular_reflection (real Mitsuba), dielectric, total internal
    reflection and conductor: the same matrix (Mitsuba computes in float32)."""
    cases = [(1.0, 1.5, 0.0), (0.6, 1.5, 0.0), (0.3, 1 / 1.5, 0.0), (0.9, 1 / 1.5, 0.0), (0.5, 0.2, 3.0), (0.1, 1.2, 2.6)]
    code = textwrap.dedent(f"""
        import json, mitsuba as mi, numpy as np
        mi.set_variant("scalar_spectral_polarized")
        out = [np.array(mi.mueller.specular_reflection(c, mi.Complex2f(e, k) if k else e)).tolist()
               for c, e, k in {cases!r}]
        print(json.dumps(out))
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    import json
    for (c, e, k), mitsuba in zip(cases, json.loads(proc.stdout.strip().splitlines()[-1])):
        mine = ap.mueller_reflection(*ap.fresnel_amplitudes(c, 1.0, e + 1j * k if k else e))
        np.testing.assert_allclose(mine, mitsuba, atol=1e-6)


# -- thin film --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n1, n2, n3", [(1.0, 1.38, 1.52), (1.0, 2.0, 1.5), (1.33, 1.8, 2.4)])
def test_quarter_and_half_wave_films(n1, n2, n3):
    """Hecht 9.7.2: a film of optical thickness lambda / 4 at normal incidence reflects
    R = ((n1 n3 - n2^2) / (n1 n3 + n2^2))^2 (MgF2 on crown glass: about 1.3 %); a lambda / 2
    film is absent (R of the bare substrate)."""
    wl = 550.0
    rs, rp = ap.airy_reflectance(1.0, wl, n1, n2, wl / (4 * n2), n3 + 0j)
    expected = ((n1 * n3 - n2**2) / (n1 * n3 + n2**2)) ** 2
    assert rs == pytest.approx(expected, rel=1e-12) and rp == pytest.approx(expected, rel=1e-12)
    rs, _ = ap.airy_reflectance(1.0, wl, n1, n2, wl / (2 * n2), n3 + 0j)
    assert rs == pytest.approx(((n1 - n3) / (n1 + n3)) ** 2, rel=1e-12)
    if (n1, n2, n3) == (1.0, 1.38, 1.52):
        assert expected == pytest.approx(0.0126, abs=1e-4)


def test_ideal_antireflection_coating():
    """Hecht 9.7.2: n2 = sqrt(n1 n3) at a quarter wave reflects nothing."""
    n2 = np.sqrt(1.52)
    assert ap.airy_reflectance(1.0, 500.0, 1.0, n2, 500.0 / (4 * n2), 1.52 + 0j)[0] < 1e-30


def test_airy_mueller_is_the_bare_interface_at_zero_thickness():
    cos = np.linspace(0.05, 1, 20)
    np.testing.assert_allclose(ap.airy_mueller(cos, 500.0, 1.0, 1.4, 0.0, 0.2 + 3j),
                               ap.mueller_reflection(*ap.fresnel_amplitudes(cos, 1.0, 0.2 + 3j)), atol=1e-12)


def test_incoherent_film_is_the_average_of_the_coherent_one_over_its_fringes():
    """Born and Wolf 1.6.4: averaged over a phase period, the coherent Airy reflectance of a lossless
    film is the incoherent sum R12 + T12^2 R23 / (1 - R12 R23)."""
    cos, n1, n2, n3 = 0.8, 1.0, 1.6, 1.3 + 0j
    wl = 550.0
    cos2 = np.sqrt(1 - (1 - cos**2) / n2**2)
    period = wl / (2 * n2 * cos2)  # thickness for one 2 pi of phase
    d = np.linspace(0, period, 20001)[:-1] + 1000.0
    rs, rp = ap.airy_reflectance(cos, wl, n1, n2, d, n3)
    inc = ap.airy_incoherent_reflectance(cos, n1, n2, n3)
    assert rs.mean() == pytest.approx(float(inc[0]), rel=1e-3)
    assert rp.mean() == pytest.approx(float(inc[1]), rel=1e-3)


# -- dispersion ----------------------------------------------------------------------------------------
def test_n_bk7_matches_schott_s_data_sheet():
    """SCHOTT N-BK7 data sheet (2017): n_F (486.13 nm) 1.52238, n_d (587.56 nm) 1.51680,
    n_C (656.27 nm) 1.51432, v_d 64.17, from the Sellmeier coefficients on the same sheet."""
    glass = dispersion.NAMED_GLASSES["N-BK7"]
    n_f, n_d, n_c = ap.sellmeier([486.1327, 587.5618, 656.2725], glass["B"], glass["C"])
    assert round(float(n_f), 5) == 1.52238 and round(float(n_d), 5) == 1.51680 and round(float(n_c), 5) == 1.51432
    assert (n_d - 1) / (n_f - n_c) == pytest.approx(64.17, abs=0.01)


def test_fused_silica_matches_malitson():
    """Malitson 1965 (JOSA 55(10)): fused silica n = 1.45846 at 587.56 nm (his table, 20 C)."""
    glass = dispersion.NAMED_GLASSES["fused_silica"]
    assert float(ap.sellmeier(587.5618, glass["B"], glass["C"])) == pytest.approx(1.45846, abs=2e-5)


def test_cauchy_approximates_bk7():
    """Cauchy's two-term fit of BK7 (A = 1.5046, B = 0.00420 um^2, the textbook values, e.g.
    Jenkins and White, Fundamentals of Optics) is within 1e-3 of SCHOTT's n at F, d and C."""
    got = ap.cauchy([486.1327, 587.5618, 656.2725], 1.5046, 0.00420)
    np.testing.assert_allclose(got, [1.52238, 1.51680, 1.51432], atol=1e-3)
    assert ap.cauchy(500.0, 1.5, 0.01, 0.001) == pytest.approx(1.5 + 0.01 / 0.25 + 0.001 / 0.0625, rel=1e-14)  # l = 0.5 um


# -- fluorescence ----------------------------------------------------------------------------------------
def test_art_bands_are_a_pyramid():
    """ART's CONST_FLUORESCENT_COLOUR: peak ``strength`` at (absorption, emission), zero on the
    base's edges, volume strength * (2 wa)(2 we) / 3 (a pyramid over a rectangle) when the
    emission band lies above the absorption band; zero where l_o <= l_i (no anti-Stokes)."""
    a, wa, e, we, s = 420.0, 30.0, 560.0, 45.0, 0.004
    assert ap.art_fluorescence_bands(a, e, a, wa, e, we, s) == pytest.approx(s)
    assert ap.art_fluorescence_bands(a + wa, e, a, wa, e, we, s) == 0.0
    li, lo = np.linspace(a - wa, a + wa, 1201), np.linspace(e - we, e + we, 1201)
    vol = integrate.trapezoid(integrate.trapezoid(ap.art_fluorescence_bands(li[:, None], lo[None, :], a, wa, e, we, s),
                                                  lo, axis=1), li)
    assert vol == pytest.approx(s * 4 * wa * we / 3, rel=1e-4)
    overlapping = ap.art_fluorescence_bands(np.array([500.0, 520.0]), np.array([490.0, 520.0]), 500.0, 40.0, 510.0, 40.0, 1.0)
    assert np.all(overlapping == 0.0)
    assert ap.art_fluorescence_bands(310.0, 835.0, 320.0, 30.0, 820.0, 20.0, 1.0) == 0.0  # outside 300-830 nm


# -- the project's ground truth is this module ---------------------------------------------------------
def test_project_optics_and_airy_agree_with_the_module_on_random_inputs():
    rng = np.random.default_rng(5)
    c, c2, a = rng.uniform(0, 1, 2000), rng.uniform(0, 1, 2000), rng.uniform(0.01, 1.5, 2000)
    eta, k, wl = rng.uniform(0.2, 3, 2000), rng.uniform(0, 5, 2000), rng.uniform(360, 830, 2000)
    for kind in ("ggx", "beckmann"):
        np.testing.assert_array_equal(optics.distribution(kind, c, a), ap.microfacet_d(kind, c, a))
        for form in ("separable", "height-correlated"):
            np.testing.assert_array_equal(optics.shadowing(kind, c, c2, a, form), ap.smith_g(kind, c, c2, a, form))
    np.testing.assert_array_equal(optics.fresnel_conductor(c, eta, k), ap.fresnel_conductor(c, eta, k))
    np.testing.assert_array_equal(airy.film_reflectance(c, wl, 1.0, 1.4, 350.0, eta + 1j * k),
                                  ap.airy_reflectance(c, wl, 1.0, 1.4, 350.0, eta + 1j * k))
    np.testing.assert_allclose(airy.bare_reflectance(c, 1.0, eta + 1j * k)[0] + airy.bare_reflectance(c, 1.0, eta + 1j * k)[1],
                               2 * ap.fresnel_conductor(c, eta, k), atol=1e-12)


def test_project_dispersion_and_fluorescence_agree_with_the_module():
    wl = np.random.default_rng(6).uniform(360, 830, 500)
    glass = dispersion.NAMED_GLASSES["N-SF11"]
    np.testing.assert_array_equal(dispersion.ior({"type": "named", "name": "N-SF11"}, wl), ap.sellmeier(wl, glass["B"], glass["C"]))
    np.testing.assert_array_equal(dispersion.ior({"type": "cauchy", "A": 1.45, "B": 0.0036, "C": 1e-5}, wl),
                                  ap.cauchy(wl, 1.45, 0.0036, 1e-5))
    fl = {"type": "bands", "absorption_peak": 450.0, "absorption_width": 40.0, "emission_peak": 600.0,
          "emission_width": 50.0, "strength": 0.01}
    w, table = fluorescence.table(fl)
    np.testing.assert_array_equal(table, ap.art_fluorescence_bands(w[:, None], w[None, :], 450.0, 40.0, 600.0, 50.0, 0.01))
