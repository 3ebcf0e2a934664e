"""Analytic probes: image regions whose expected value follows from the scene's own spectra by
a closed form, independently of any renderer (plain numpy; colour-science for CIELAB/CIEDE2000).

- lambert.py: Lambertian patches under a uniform environment (rho * L, CIEDE2000);
- fresnel.py: a smooth dielectric reflecting an area light through a polariser (Fresnel, Malus,
  Brewster) and the degree of polarisation;
- stokes.py: the validity of Stokes output (S0 >= |(S1, S2, S3)|).

Each probe is a dict {name, expected, measured, error, unit, pass}; ``pass`` is None when the
probe cannot be measured at the render's resolution (fewer than MIN_PIXELS whole pixels).
"""
from . import fresnel, lambert, stokes
from .common import MIN_PIXELS  # noqa: F401 - part of the interface


def evaluate(scene, names, image, reference=None):
    """Every probe that applies to ``scene``, measured on ``image`` (channels ``names``)."""
    return (lambert.patches(scene, names, image) + fresnel.brewster(scene, names, image)
            + stokes.validity(scene, names, image, reference))
