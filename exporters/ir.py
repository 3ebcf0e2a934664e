"""The scene IR: a JSON-compatible dict, one test scene each, described by schema/scene.schema.json
and specified for importers in docs/scene-format.md (the conventions below, in full). Inside the
project named spectra, conductors and glasses stay named; scene files carry their data beside the
names (exporters/inline_data.py).

Conventions (every writer follows them):
- World space is Blender's: right-handed, Z up, lengths in scene units.
- ``camera.to_world`` maps camera space (looking down -Z, +Y up, +X right: Blender's and
  OpenGL's convention) to world space; ``fov`` in degrees along ``fov_axis`` ("x" or "y").
- ``rectangle`` is the square [-1, 1]^2 in its local z = 0 plane, normal and emission +Z.
- ``sphere`` is analytic: ``center`` and ``radius``.
- ``mesh`` has inline ``vertices``/``faces`` (triangles) or a ``file`` (PLY/OBJ, relative to
  the JSON file), both with an optional ``to_world``. Faces are flat (no normals are
  interpolated) and wound counter-clockwise seen from outside (their normals point outwards).
- Roughness ``alpha`` is the microfacet width (GGX/Beckmann alpha, Walter et al. 2007);
  alpha 0 is a smooth surface. Blender's "Roughness" r corresponds to alpha = r^2.
- Spectra and their radiometric normalisation: see spectra.py.
- A dielectric's ``int_ior`` is a number or an IOR model n(lambda) (Sellmeier, Cauchy, a named
  glass): see dispersion.py. A model needs "dispersion" (and "spectral").
- Delta ``lights`` (optional): ``point`` (``intensity``, W/sr-like: E = I / d^2), ``spot`` (a
  point light masked to a cone about local +Z of its ``to_world``: full within ``beam_width``,
  linear in angle to 0 at ``cutoff_angle``, Mitsuba's spot) and ``directional`` (``irradiance``
  on a surface facing it, travelling along ``direction``). They are never seen directly.
- ``warnings`` (optional): what an exporter converted or lost, for people; never part of the image.
- An emitter is ``area`` (Lambertian, ``radiance``) or ``collimated`` (a rectangle emitting only
  along its +Z normal, ``irradiance`` across the beam: Mitsuba's directionalarea); a collimated
  beam is reached only by light tracing (``render.integrator`` "ptracer").
- Fluorescence: a diffuse BSDF's optional ``fluorescence`` (bands, as ART's
  CONST_FLUORESCENT_COLOUR, or a re-radiation matrix) adds re-radiation P(l_i, l_o) in 1/nm to
  its elastic ``reflectance``: L_o(l_o) = rho(l_o) L(l_o) + integral P(l_i, l_o) L(l_i) dl_i,
  P = 0 for l_o <= l_i and outside 300-830 nm; quantum yield <= 1. See fluorescence.py.
- Polarisation: ``camera.polarizer.angle`` is the transmission axis of an ideal linear
  polariser in front of the lens, in degrees counter-clockwise from image right as seen from the
  camera (0 = horizontal, 90 = vertical; ART's 0 degrees is horizontal too). ``render.output``
  "stokes" adds S0..S3 in the same frame: S1 > 0 is horizontal, S2 > 0 is +45 degrees; a
  polarisation direction at angle a has S1/S0 = cos 2a, S2/S0 = sin 2a (Mitsuba 3's frame, measured).
- Thin film (``bsdf.thin_film`` of a conductor, absent when unused): a dielectric film of real
  index ``ior`` and ``thickness`` in nm on the conductor, seen from an exterior medium of real
  index ``ext_ior`` (optional, default 1.0). The conductor's eta/k are absolute indices and a
  conductor without a film has vacuum outside (Mitsuba's conductor has no exterior index), so
  the default keeps thickness 0 identical to the bare conductor. The film's reflectance is the
  Airy sum of both interfaces (batch/verdict/airy.py); rough films use it as the microfacet
  Fresnel factor (Belcour and Barla 2017).
- Coated diffuse (``bsdf.type`` "coated_diffuse"): a dielectric coat of real index ``int_ior``
  (outside ``ext_ior``, default air) over a Lambertian base of albedo ``reflectance``, one-sided:
  Mitsuba 3's ``plastic`` with ``nonlinear`` false (Weidlich and Wilkie 2007): specular F(mu_i)
  plus rho / (1 - F_dr,int) (1 - F(mu_i)) (1 - F(mu_o)) / (pi eta^2), F_dr,int the coat's
  hemispherical reflectance from inside as the exact integral (reference_code/appearance.py,
  ``coated_diffuse_brdf``); with ``roughness`` the coat is Mitsuba 3's ``roughplastic``.
  docs/scene-format.md section 6.6 states it in full and how pbrt-v4's coateddiffuse differs.
- Pixel filter is a box: each pixel is the plain integral over its area, so pixels are
  independent and a reference downsamples exactly to any integer factor (see batch/verdict/compare.py).
"""
import copy

FORMAT = "spectral-bench-scene"
VERSION = 1

PHENOMENA = ("spectral", "polarization", "fluorescence", "dispersion", "thin_film")
CASES = ("reflectance", "spectral_accuracy", "polarization", "iridescence", "fluorescence",
         "dispersion", "stability", "custom")
DISTRIBUTIONS = ("ggx", "beckmann")
AIR_IOR = 1.000277  # Mitsuba's "air"


def identity():
    return [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]


def derived_needs(scene):
    """Phenomena a scene needs from its content: a non-constant spectrum or a named conductor
    needs a spectral renderer. Explicit ``needs`` entries are kept on top of these."""
    needs = set(scene.get("needs", []))
    if scene.get("camera", {}).get("polarizer") or scene.get("render", {}).get("output") == "stokes":
        needs.add("polarization")

    def spectral(spec):
        return spec is not None and spec.get("type") != "constant"

    env = scene.get("environment")
    if env and spectral(env.get("radiance")):
        needs.add("spectral")
    for obj in scene.get("objects", []):
        bsdf = obj.get("bsdf") or {}
        if bsdf.get("type") == "conductor" and "material" in bsdf:
            needs.add("spectral")  # a named conductor is a measured eta/k table
        if bsdf.get("thin_film") is not None:
            needs.update(("thin_film", "spectral"))  # interference colours exist per wavelength only
        for key in ("reflectance", "eta", "k"):
            if spectral(bsdf.get(key)):
                needs.add("spectral")
        if bsdf.get("fluorescence"):
            needs.update(("fluorescence", "spectral"))  # re-radiation moves light between wavelengths
        em = obj.get("emitter") or {}
        if spectral(em.get("radiance")) or spectral(em.get("irradiance")):
            needs.add("spectral")
        if bsdf.get("type") == "dielectric" and isinstance(bsdf.get("int_ior"), dict):
            needs.update(("dispersion", "spectral"))  # an IOR model: n varies with wavelength
    for light in scene.get("lights", []):
        if spectral(light.get("intensity")) or spectral(light.get("irradiance")):
            needs.add("spectral")
    return sorted(needs)


def with_derived_needs(scene):
    out = copy.deepcopy(scene)
    out["needs"] = derived_needs(scene)
    return out


def describe(scene):
    """One line for logs."""
    return (f"{scene['name']} [{scene.get('case', '?')}] {scene['render']['width']}x"
            f"{scene['render']['height']} {scene['render']['spp']} spp, needs {','.join(scene.get('needs', [])) or 'rgb'}")
