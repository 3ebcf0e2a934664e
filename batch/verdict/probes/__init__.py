"""Analytic probes: image regions whose expected value follows from the scene's own spectra by
a closed form, independently of any renderer (plain numpy; colour-science for CIELAB/CIEDE2000).

- lambert.py: Lambertian patches under a uniform environment (rho * L, CIEDE2000);
- fresnel.py: a smooth dielectric reflecting an area light through a polariser (Fresnel, Malus,
  Brewster) and the degree of polarisation;
- stokes.py: the validity of Stokes output (S0 >= |(S1, S2, S3)|);
- fluorescence.py: a lone (fluorescent) Lambertian sphere under a uniform environment
  (rho L + integral P L, judged against the region's own standard error).

Each probe is a dict {name, expected, measured, error, unit, pass}; ``pass`` is None when the
probe cannot be measured at the render's resolution (fewer than MIN_PIXELS whole pixels).
"""
from . import fluorescence, fresnel, lambert, stokes
from .common import MIN_PIXELS, Measurement  # noqa: F401 - part of the interface

# Every probe: a function of one Measurement returning a list of probe records; a probe that does
# not apply to the scene returns [].
PROBES = [lambert.patches, fresnel.brewster, stokes.validity, fluorescence.lone_sphere]


def evaluate(scene, names, image, reference=None, stderr=None):
    """Every probe that applies to ``scene``, measured on ``image`` (channels ``names``)."""
    m = Measurement(scene, list(names), image, stderr, reference)
    return [record for probe in PROBES for record in probe(m)]
