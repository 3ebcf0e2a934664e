"""Closed-form optics for the probes (no renderer involved): the project's names for the
reference implementations in reference_code/appearance.py, which documents every formula and its
source, and which is tested against published values (tests/probes/test_reference_code.py).

- fresnel_dielectric(cos_i, eta) -> (Rs, Rp); fresnel_conductor(cos_i, eta, k) -> unpolarised R
  (Born & Wolf, Principles of Optics, 7th ed., 1.5.2 and 14.2; Hecht, Optics, 5th ed., eq. 4.42-4.43).
- distribution(kind, cos_m, alpha): GGX (Walter et al. 2007 eq. 33) or Beckmann (eq. 25) D(m).
- smith_lambda(kind, cos_v, alpha): Heitz 2014 eq. 72 (GGX) and eq. 69 (Beckmann, exact erf form).
- shadowing(kind, cos_i, cos_o, alpha, form): the separable G1(i) G1(o) (what Mitsuba 3 uses,
  mitsuba/render/microfacet.h MicrofacetDistribution::G) or the height-correlated
  1 / (1 + Lambda(i) + Lambda(o)) (Heitz 2014 eq. 99), for directions on the normal's side of
  every microfacet involved (the reflection configurations the probes integrate).
- coated_diffuse_uniform(cos_o, rho, eta): a smooth coat over a Lambertian base under a uniform
  environment, F(mu_o) + rho (1 - F(mu_o)) (Mitsuba 3's plastic, nonlinear false; Weidlich and
  Wilkie 2007).
"""
from ...reference_code.appearance import coated_diffuse_uniform, fresnel_conductor, fresnel_dielectric, smith_lambda
from ...reference_code.appearance import microfacet_d as distribution
from ...reference_code.appearance import smith_g as shadowing

__all__ = ["coated_diffuse_uniform", "fresnel_dielectric", "fresnel_conductor", "distribution", "smith_lambda", "shadowing"]
