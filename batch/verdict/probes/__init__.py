"""Analytic probes: image regions whose expected value follows from the scene's own spectra by
a closed form, independently of any renderer (plain numpy; colour-science for CIELAB/CIEDE2000).

- lambert.py: Lambertian patches under a uniform environment (rho * L, CIEDE2000);
- fresnel.py: a smooth dielectric reflecting an area light through a polariser (Fresnel, Malus,
  Brewster) and the degree of polarisation;
- ggx.py: rough conductor plates lit only by area lights (quadrature of the microfacet BRDF);
- stokes.py: the validity of Stokes output (S0 >= |(S1, S2, S3)|);
- thin_film.py: a smooth filmed conductor sphere in a uniform environment (Airy reflectance);
- prism.py: a collimated beam through a dispersive dielectric onto a screen (Snell's law per
  wavelength: band positions and order; Fresnel: the flux on the screen).
- fluorescence.py: a lone (fluorescent) Lambertian sphere under a uniform environment
  (rho L + integral P L, judged against the region's own standard error).
- floor_sphere.py: a (fluorescent) Lambertian sphere above a diffuse floor rectangle under a
  uniform environment (the sky's share exact by Lambert's polygon formula, the floor's bounded:
  an interval per pixel, judged one-sided where it is narrow).
- furnace.py: the camera inside a closed diffuse enclosure that emits Le and reflects rho
  (Le (1 - rho^d) / (1 - rho) per wavelength, d the max depth; and what an RGB renderer gets).
- white_furnace.py: a lone rough sphere of a perfect conductor (Fresnel 1) under a uniform
  environment (E(mu_o, alpha) L, E the single-scattering directional albedo by quadrature).
- rough_film.py: rough (Beckmann) conductor spheres, filmed or bare, under a uniform environment
  beside other passive objects (the sky's share exact by a quadrature of the lobe, the other
  objects' light bounded: an interval per pixel, judged one-sided where it is narrow).
- coated.py: a smooth coated diffuse sphere (Mitsuba 3's plastic) alone in a uniform environment
  (F(mu) + rho (1 - F(mu)) per wavelength: the coat's Fresnel and its internal reflection series).
- bands.py: a spectral render's bands on the regions whose truth is a spectrum (``spectral``).

Each probe is a dict {name, expected, measured, error, unit, pass}; ``pass`` is None when the
probe cannot be measured at the render's resolution (fewer than MIN_PIXELS whole pixels). A probe
may add an image (an array under one of MAP_KEYS: ggx.py's ``residual_map``); ``evaluate`` takes
it out of the record (records are metrics.json's plain data) and hands it over in ``maps``.
"""
from . import (bands, coated, floor_sphere, fluorescence, fresnel, furnace, ggx, lambert, prism, rough_film,
               stokes, thin_film, white_furnace)
from .common import MIN_PIXELS, Measurement  # noqa: F401 - part of the interface

# Every probe: a function of one Measurement returning a list of probe records; a probe that does
# not apply to the scene returns [].
PROBES = [lambert.patches, fresnel.brewster, ggx.plates, stokes.validity, thin_film.smooth_film, prism.probes,
          fluorescence.lone_sphere, floor_sphere.sphere_on_floor, rough_film.rough_films, furnace.furnace,
          white_furnace.white_furnace,
          coated.coated_spheres, *bands.PROBES]


MAP_KEYS = ("residual_map",)  # record keys that hold an image, not data


def evaluate(scene, names, image, reference=None, stderr=None, passes=None, observers=(), maps=None, spectral=None):
    """Every probe that applies to ``scene``, measured on ``image`` (channels ``names``; ``stderr``:
    its per-pixel standard error from ``passes`` independent passes, or None; ``observers`` and
    ``spectral``: see Measurement). The records are plain data: an image a probe returns is removed from its record
    and, when ``maps`` is a dict, put there as ``maps[key][record name]``."""
    m = Measurement(scene, list(names), image, stderr, reference, passes or (1 if stderr is None else 2),
                    tuple(observers), spectral)
    # every probe's closed form assumes the scene's light is its area emitters and environment: a
    # scene with delta lights (point, spot, directional) has no probe yet; nor has a scene with an
    # image texture or an environment map (each probe reads one spectrum per object and one for the
    # environment: a texture's or a map's is its mean)
    textured = any((o.get("bsdf") or {}).get("reflectance_texture") for o in scene["objects"]) \
        or (scene.get("environment") or {}).get("type") == "map"
    records = [] if scene.get("lights") or textured else [record for probe in PROBES for record in probe(m)]
    for record in records:
        for key in MAP_KEYS:
            if key in record:
                image_map = record.pop(key)
                if maps is not None:
                    maps.setdefault(key, {})[record["name"]] = image_map
    return records
