"""pbrt-v4 writer: IR scene -> folder with a scene.pbrt (pbrt-v4's scene format) and, for meshes,
meshes/<object>.ply. The folder renders with ``pbrt scene.pbrt`` unchanged (pbrt-v4 at 5f7a6068;
parameter names read from its source: lights.cpp, materials.cpp, cameras.cpp, film.cpp).

What each IR field becomes (docs/scene-format.md, "pbrt-v4" section, says the same per field):

- Spectra: inline ``"spectrum NAME" [l0 v0 l1 v1 ...]`` (a PiecewiseLinearSpectrum, which pbrt
  evaluates as 0 outside its first and last wavelength), tabulated at the IR's own samples (a
  sampled spectrum's points, a named table's points) and always from 360 to 830 nm with the edge
  values continued, as the IR defines them; a constant is the two points 360 and 830; a blackbody
  (a formula) is tabulated at 1 nm.
- Lights: pbrt divides every light's spectrum by its photometric value (lights.cpp: ``scale /=
  SpectrumToPhotometric(L)``, the sum over whole nanometres 360-830 of the CIE Y function times the
  spectrum; util/spectrum.cpp), and its spectral film multiplies what reaches it by CIE_Y_integral
  (106.856895, film.h SpectralFilm::AddSample; util/spectrum.h). The writer's ``"float scale"`` is
  the product's inverse, the spectrum's luminance as the IR defines it: sum(y_bar s) / CIE_Y_integral
  (a flat spectrum 1: scale 1), computed from the same CIE 1931 table (exporters/data: pbrt's CIE_Y
  table agrees with it to 5e-9 at every nanometre), so the film's buckets hold the IR's absolute
  radiance (measured: tests/exporters/test_pbrt_renders.py; with the photometric value alone they
  were CIE_Y_integral times too bright). A spectrum of photometric value 0 (no emission) is written
  as the flat spectrum 1 with scale 0 (pbrt would divide 0 by 0).
  area emitter -> ``AreaLightSource "diffuse"`` (one-sided, ``twosided`` false, as the IR);
  environment -> ``LightSource "infinite"`` with ``L``; point -> ``"point"`` (``I``, ``from``);
  directional -> ``"distant"`` (``L``, from 0 to the IR's direction of travel); spot -> ``"spot"``
  only with a hard edge (beam_width = cutoff_angle: ``coneangle``, ``conedelta`` 0), as pbrt's
  falloff is a smoothstep in cos between the cones, not the IR's linear falloff in angle.
- Materials: diffuse -> ``"diffuse"`` ``reflectance`` (with a reflectance_texture an ``"imagemap"``
  spectrum texture of the linear OpenEXR exporters/textures.py writes: pbrt's RGBAlbedoSpectrum
  uplift; the mesh's uvs as the PLY's u, v); conductor -> ``"conductor"`` with ``eta``
  and ``k`` (named conductors as the IR's own tables, not pbrt's named spectra); dielectric ->
  ``"dielectric"`` with ``"float eta"`` int_ior / ext_ior (pbrt's eta is relative and its outside
  is the normal's side, as the IR's ext_ior), a dispersion model as ``"spectrum eta"`` n(l) / ext_ior
  at 1 nm (pbrt then follows the first wavelength of a sample and terminates the other three,
  materials.h); GGX alpha as ``"float roughness"`` with ``"bool remaproughness" false`` (pbrt's
  default remaps roughness to alpha); an object without a BSDF, or an emitter without one, is a
  black diffuse (reflectance 0).
- Shapes: rectangle -> a two-triangle ``trianglemesh`` over [-1, 1]^2 under its ``Transform``
  (pbrt flips a triangle's normal when the transform swaps handedness, which is the IR's normal
  transformed by the inverse transpose); sphere -> ``"sphere"`` translated to its centre; mesh ->
  ``"plymesh"`` of its vertices in world coordinates (flat faces: no normals in the file).
- Camera: ``"perspective"``; its ``Transform`` is the inverse of the IR's to_world times
  diag(1, 1, -1) (pbrt's camera looks down +z, raster y down); ``fov`` with an explicit
  ``screenwindow`` so that ``fov`` spans the IR's fov_axis and the principal point is the image
  centre (pbrt's own fov spans the shorter axis). ``PixelFilter "box"`` of radius 0.5 (a pixel
  averages its own area), ``Sampler "independent"`` with ``pixelsamples`` = spp and no seed
  (``pbrt --seed`` sets each pass's), ``Integrator "path"`` with ``maxdepth`` = max_depth - 1
  (pbrt counts scattering events, the IR path segments; cpu/integrators.cpp PathIntegrator::Li).
  The IR's ``ptracer`` asks for an estimator, not an image: pbrt's path tracer estimates the
  same image (a collimated emitter, which needs light tracing, is unsupported anyway).
- Film: ``"spectral"`` (FILM below): full floats (``savefp16`` false), box buckets over 360-830 nm.

What pbrt-v4 cannot express is returned by :func:`unsupported` as (object, field, message), and
the written file leaves that part out and says so at its top, never a stand-in: polarisation
(camera.polarizer, render.output stokes), fluorescence, thin-film interference, Beckmann
microfacets, collimated emitters, spots with a soft edge, and 0 < alpha < 1e-3 (pbrt renders it as
a perfect mirror: TrowbridgeReitzDistribution::EffectivelySmooth).

What pbrt-v4 expresses only by a stated modelling is returned by :func:`approximations` as
(object, field, message), written at the top of the file (``# APPROXIMATED:``) and recorded by the
backend in the job's ``approximated`` list:

- One-sided surfaces. The IR's diffuse and conductor surfaces reflect on their front only (a back
  face is black); pbrt-v4's reflect on both sides (bxdfs.h: DiffuseBxDF::f and ConductorBxDF::f ask
  only SameHemisphere(wo, wi); no material, MixMaterial's amount texture included, sees which side
  was hit; ``Material "interface"`` lets the ray through, it does not absorb). A rectangle with such
  a BSDF is written with a black closed backing: a box BACKING_DEPTH times its shorter side deep
  behind it, of reflectance 0, whose lid is the rectangle itself (the box's corners are the
  rectangle's, under the same Transform, so the edges are shared exactly). No path from outside
  reaches the rectangle's back without first ending on the black box, as in the IR; the one change
  is the box's black sides (its perimeter times the depth), which hide what lies just past the
  rectangle's edges, 1e-4 of its size. A mesh with such a BSDF that is not closed (an edge not
  shared by exactly two faces), and a sphere with the camera inside, keep pbrt's two-sided
  reflection and are listed as such (not corrected).
- GGX shadowing-masking. pbrt-v4's is the height-correlated G2 = 1 / (1 + Lambda(o) + Lambda(i))
  (util/scattering.h TrowbridgeReitzDistribution::G), the IR's the separable G1(o) G1(i); pbrt has
  no other, so a rough GGX surface is written with pbrt's, and listed with the ratio
  G2 / (G1 G1) = 1 + Lambda(o) Lambda(i) / (1 + Lambda(o) + Lambda(i)) at its alpha with view and
  light 80 degrees from the normal (ggx_copper_grazing measured +3.9 % against the separable closed
  form, 1.00016 against the height-correlated one: known_deviations.toml).

pbrt samples light spectra at the nearest whole nanometre (DenselySampledSpectrum), exact for the
box buckets of tables whose knots are whole nanometres.

Names reach the file only as comments (names.comment_text) and mesh file names through
names.file_stem. Test hook (planted error, like ART's): ``SPECTRAL_BENCH_TEST_PBRT_LIGHT_SCALE=F``
multiplies every light's scale by F and the file says so in a comment.
"""
import math
from pathlib import Path

import numpy as np

from . import dispersion, ir, mesh_io, names, planted, spectra, textures

FILM = {"nbuckets": 47, "lambdamin": 360.0, "lambdamax": 830.0}  # 47 box buckets of 10 nm
SAMPLER = "independent"
SCENE_FILE = "scene.pbrt"
FILM_FILE = "scene.exr"
MIN_ROUGH_ALPHA = 1e-3  # util/scattering.h TrowbridgeReitzDistribution::EffectivelySmooth
CIE_Y_INTEGRAL = 106.856895  # pbrt-v4 util/spectrum.h: the spectral film multiplies by it
FORMULA_STEP_NM = 1.0  # a blackbody or an IOR model tabulated at every nanometre
BACKING_DEPTH = 1e-4  # a one-sided rectangle's black backing box: its depth over the shorter side
ONE_SIDED = ("diffuse", "conductor")  # the IR's BSDFs that reflect on the front only (pbrt's: both sides)
GRAZING_DEG = 80.0  # where the shadowing ratio is stated (ggx_copper_grazing's view and light)
TEST_HOOK = "SPECTRAL_BENCH_TEST_PBRT_LIGHT_SCALE"
# pbrt-v4 camera space (+x right, +y up, looking down +z) -> the IR's (looking down -z)
_CAMERA_FLIP = np.diag([1.0, 1.0, -1.0, 1.0])


def planted_scale():
    """The test hook's factor on every light (1.0 when unset); not a positive number: an error."""
    return planted.scale(TEST_HOOK)


def _num(x):
    """A number as pbrt reads it (9 significant digits: a float32 exactly); never nan or inf."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"refusing to write {x!r} into a pbrt scene")
    text = f"{x:.9g}"
    return "0" if text == "-0" else text


def _list(values):
    return "[ " + " ".join(_num(v) for v in values) + " ]"


def _settled(a):
    """Values this writer computes (an inverse, a product) rounded to 12 decimal digits of their
    largest magnitude: linear algebra's last bits differ between machines (BLAS and LAPACK pick
    kernels by CPU), and a small entry's ninth digit lies at that level (a camera's 1.6479211e-07
    read 1.64792111e-07 on another machine), so the file would differ by machine. Rounded on a grid
    1e-12 of the scale, both land on one value, which then prints the same everywhere; the change
    is 1e-12 of the matrix's scale, far below a float32's 6e-8 that pbrt reads."""
    a = np.asarray(a, dtype=np.float64)
    scale = float(np.max(np.abs(a))) if a.size else 0.0
    if scale == 0.0 or not math.isfinite(scale):
        return a
    return np.round(a, 12 - math.ceil(math.log10(scale))) + 0.0  # + 0.0: no -0


def _matrix(m):
    """pbrt's Transform takes the matrix column by column (parser: Transpose of the 16 values)."""
    return _list(np.asarray(m, dtype=np.float64).T.reshape(-1))


def photometric(wavelengths, values):
    """pbrt's SpectrumToPhotometric of the piecewise-linear spectrum (wavelengths, values): the sum
    over l = 360, 361, ..., 830 nm of y_bar(l) s(l), y_bar the CIE 1931 table at 1 nm."""
    wl, _xb, yb, _zb = spectra.cie_1931_cmfs()
    return float(np.sum(yb * np.interp(wl, wavelengths, values)))


def light_scale(wavelengths, values):
    """The ``scale`` that makes pbrt's spectral film read the spectrum (wavelengths, values) as the
    IR's radiance: photometric / CIE_Y_integral (module docstring)."""
    return photometric(wavelengths, values) / CIE_Y_INTEGRAL


def tabulated(spec):
    """(wavelengths, values) over 360-830 nm at the IR's own samples (a formula at 1 nm)."""
    if spectra.is_constant(spec):
        v = float(spec["value"])
        return np.array([spectra.LAMBDA_MIN, spectra.LAMBDA_MAX]), np.array([v, v])
    if spec.get("type") == "blackbody":
        return spectra.tabulate(spec, step=FORMULA_STEP_NM)
    return spectra.tabulate(spec)


def _spectrum_param(name, wl, vals):
    pairs = " ".join(f"{_num(w)} {_num(v)}" for w, v in zip(wl, vals))
    return f'"spectrum {name}" [ {pairs} ]'


def _camera_position(scene):
    return np.asarray(scene["camera"]["to_world"], dtype=np.float64)[:3, 3]


# pbrt-v4's coateddiffuse (materials.h CoatedDiffuseMaterial, bxdfs.h LayeredBxDF) is a stochastic
# random walk between the coat and the base (Guo et al. 2018's position-free Monte Carlo) through a
# layer whose thickness attenuates every crossing, truncated at maxdepth: in the limit the physical
# layer, whose diffuse lobe is rho' / (1 - rho' F_dr,int) (1 - F(i)) (1 - F(o)) / (pi eta^2), where the
# IR's (Mitsuba 3's plastic, nonlinear false) has rho / (1 - F_dr,int) (docs/scene-format.md 6.6).
# Measured on coated_sphere (2026-12-05, 64 x 64, 64 spp; the sphere's mean): written with rho itself
# it renders 0.65, 0.79, 0.78 (R, G, B) of the IR's model at thickness 1e-5 (0.62, 0.79, 0.77 at
# pbrt's default 0.01) and passes against the physical series at 1e-5; written with rho' = rho / (1 -
# F_dr,int + rho F_dr,int), thickness 1e-5 and maxdepth 64 it is the IR's model in expectation
# (the probe's view-angle rings pass, the noise test against Mitsuba's reference passes, R 0.025 %
# dark +- 0.041), but its per-pixel noise is so skewed (the walk's rare bright samples) that the
# probe's 4 x 4 tile t-tests fail (z 7.7, one tile of 6804, at default settings). Until the probe
# judges such noise the writer leaves a coated diffuse out, unsupported, rather than fail the run.
COATED_UNSUPPORTED = ("a coated diffuse (Mitsuba 3's plastic, nonlinear false): pbrt v4's coateddiffuse is a "
                      "stochastic layered model of the physical layer (internal reflections rho F_dr,int in the "
                      "series' denominator, a thickness that attenuates): written as it is it renders 0.65, 0.79, "
                      "0.78 (R, G, B) of coated_sphere's closed form (measured); with a base rho / (1 - F_dr,int + "
                      "rho F_dr,int) it is the model in expectation, but its skewed per-pixel noise fails the coat "
                      "probe's tile test (measured; docs/scene-format.md 6.6): not written")


class _Writer:
    def __init__(self, scene, out_dir):
        self.scene, self.out = scene, Path(out_dir)
        self.unsupported = []  # (object, field, message)
        self.planted = planted_scale()
        self.approximated = []  # (object, field, message), set by write()

    # -- what pbrt-v4 cannot express -----------------------------------------------------------
    def bsdf_problems(self, obj):
        """[(field, message)] of an object's BSDF pbrt-v4 cannot express."""
        b, out = obj.get("bsdf"), []
        if not b:
            return out
        if b["type"] == "coated_diffuse":
            out.append(("bsdf.type", COATED_UNSUPPORTED))
            return out
        if b.get("fluorescence") is not None:
            out.append(("bsdf.fluorescence", "pbrt v4 has no fluorescence (no reradiation between wavelengths "
                        "anywhere in src/pbrt)"))
        if b.get("thin_film") is not None:
            out.append(("bsdf.thin_film", "pbrt v4 has no thin film interference (no Airy sum material)"))
        rough = b.get("roughness")
        if rough is not None and rough["alpha"] > 0:
            if rough["distribution"] != "ggx":
                out.append(("bsdf.roughness.distribution", f"{rough['distribution']} microfacets: pbrt v4's are "
                            "Trowbridge Reitz (GGX) only"))
            elif rough["alpha"] < MIN_ROUGH_ALPHA:
                out.append(("bsdf.roughness.alpha", f"alpha {rough['alpha']:g}: pbrt v4 renders alpha below "
                            f"{MIN_ROUGH_ALPHA:g} as a perfect mirror (TrowbridgeReitzDistribution::EffectivelySmooth)"))
        return out

    def approximations(self):
        """[(object, field, message)] of what is written by a stated modelling (module docstring)."""
        found = []
        for obj in self.scene["objects"]:
            b = obj.get("bsdf")
            if not b or self.bsdf_problems(obj):
                continue
            s = obj["shape"]
            if b["type"] in ONE_SIDED:
                if s["type"] == "rectangle":
                    found.append((obj["name"], "bsdf.type", (
                        f"one sided {b['type']}: pbrt v4's reflects on both sides (DiffuseBxDF/ConductorBxDF::f), so "
                        f"it is written with a black closed backing, a box {BACKING_DEPTH:g} of its shorter side deep "
                        "behind it with the rectangle as its lid: exact for every path to its back, the box's black "
                        "sides hide what lies just past its edges")))
                elif s["type"] == "mesh" and not self.closed_mesh(obj):
                    found.append((obj["name"], "bsdf.type", (
                        f"one sided {b['type']} on a mesh that is not closed: pbrt v4 reflects on its back faces too "
                        "(the IR's are black there); not corrected")))
                elif s["type"] == "sphere" and np.linalg.norm(
                        _camera_position(self.scene) - np.asarray(s["center"], dtype=np.float64)) < float(s["radius"]):
                    found.append((obj["name"], "bsdf.type", (
                        f"one sided {b['type']} sphere with the camera inside: pbrt v4 reflects on its inside too "
                        "(the IR's is black there); not corrected")))
            rough = b.get("roughness")
            if rough is not None and rough["alpha"] > 0 and rough["distribution"] == "ggx":
                ratio = shadowing_ratio(rough["alpha"], GRAZING_DEG)
                found.append((obj["name"], "bsdf.roughness", (
                    "shadowing: the IR's separable Smith G1(o) G1(i) written as pbrt v4's height correlated "
                    "G2 = 1 / (1 + Lambda(o) + Lambda(i)) (util/scattering.h; pbrt has no other): equal at normal "
                    f"incidence, G2 / (G1 G1) = {ratio:.4f} at alpha {rough['alpha']:g} with view and light "
                    f"{GRAZING_DEG:g} degrees from the normal ({100 * (ratio - 1):.2g} % brighter there, more towards grazing)")))
        return found

    def closed_mesh(self, obj):
        """Whether every edge of the mesh is shared by exactly two of its faces."""
        _verts, faces = mesh_io.load_mesh(obj["shape"], self.scene.get("_base_dir"))
        edges = {}
        for face in faces:
            face = [int(i) for i in face]
            for a, b in zip(face, face[1:] + face[:1]):
                key = (min(a, b), max(a, b))
                edges[key] = edges.get(key, 0) + 1
        return bool(edges) and all(n == 2 for n in edges.values())

    def scene_problems(self):
        sc, found = self.scene, []
        cam = sc["camera"]
        if cam.get("polarizer"):
            found.append((cam.get("name", "camera"), "polarizer", "pbrt v4 has no polarisation (no Stokes vectors, "
                          "no polariser)"))
        if sc["render"].get("output", "rgb") == "stokes":
            found.append(("render", "output", "Stokes output: pbrt v4 has no polarisation"))
        for obj in sc["objects"]:
            em = obj.get("emitter") or {}
            if em.get("type") == "collimated":
                found.append((obj["name"], "emitter.type", "pbrt v4 has no collimated (directional area) emitter"))
            found += [(obj["name"], f, m) for f, m in self.bsdf_problems(obj)]
        for light in sc.get("lights", []):
            if light["type"] == "spot" and light["beam_width"] < light["cutoff_angle"]:
                found.append((light["name"], "beam_width", f"a soft spot edge ({light['beam_width']:g} to "
                              f"{light['cutoff_angle']:g} degrees): pbrt v4's falls off as a smoothstep in cos, "
                              "the IR's linearly in angle"))
        reported = {f.split(".")[-1] for _o, f, _m in found}
        by_need = {"polarization": ("polarizer", "output"), "fluorescence": ("fluorescence",),
                   "thin_film": ("thin_film",)}
        for need in sc.get("needs", []):
            if need in by_need and not reported & set(by_need[need]):
                found.append(("scene", "needs", f"{need}: pbrt v4 has none"))
        self.unsupported = found
        return found

    # -- writing ----------------------------------------------------------------------------------
    def light_params(self, key, spec):
        """``"spectrum KEY" [...] "float scale" S`` with S undoing pbrt's photometric normalisation
        and its spectral film's factor."""
        wl, vals = tabulated(spec)
        y = light_scale(wl, vals)
        if not y > 0:
            return f'{_spectrum_param(key, [spectra.LAMBDA_MIN, spectra.LAMBDA_MAX], [1.0, 1.0])} "float scale" [ 0 ]'
        return f'{_spectrum_param(key, wl, vals)} "float scale" [ {_num(y * self.planted)} ]'

    def material(self, obj):
        b = obj.get("bsdf")
        if not b:
            return 'Material "diffuse" "spectrum reflectance" [ 360 0 830 0 ]', []
        notes = []
        rough = b.get("roughness")
        alpha = rough["alpha"] if rough is not None else 0.0
        rough_text = f'"float roughness" [ {_num(alpha)} ] "bool remaproughness" false'
        if alpha > 0:
            notes.append("GGX: pbrt v4's shadowing and masking is height correlated, 1 / (1 + Lambda(o) + Lambda(i)); "
                         "the IR's is separable, G1(o) G1(i) (APPROXIMATED above)")
        if b["type"] == "diffuse" and b.get("reflectance_texture") is not None:
            # linear sRGB as float OpenEXR (exporters/textures.py); pbrt uplifts each texel to an
            # RGBAlbedoSpectrum (Jakob and Hanika's sigmoid) and reads t up (it flips t itself)
            tex = b["reflectance_texture"]
            rel = textures.write_linear(tex, obj["name"], self.scene.get("_base_dir"), self.out)
            tex_id = f"{names.file_stem(obj['name'])}_reflectance"
            filt = "point" if tex.get("filter") == "nearest" else "bilinear"
            notes.append(f"reflectance texture: {textures.UPLIFTS['pbrt']}")
            return (f'Texture "{tex_id}" "spectrum" "imagemap" "string filename" "{rel}" "string filter" "{filt}" '
                    f'"string wrap" "repeat"\n    Material "diffuse" "texture reflectance" "{tex_id}"'), notes
        if b["type"] == "diffuse":
            return f'Material "diffuse" {_spectrum_param("reflectance", *tabulated(b["reflectance"]))}', notes
        if b["type"] == "conductor":
            eta, k = spectra.named_conductor(b["material"]) if "material" in b else (b["eta"], b["k"])
            return (f'Material "conductor"\n    {_spectrum_param("eta", *tabulated(eta))}\n'
                    f'    {_spectrum_param("k", *tabulated(k))}\n    {rough_text}'), notes
        if b["type"] == "dielectric":
            ext = float(b.get("ext_ior", ir.AIR_IOR))
            value = b["int_ior"]
            if dispersion.is_dispersive(value):
                wl = np.arange(spectra.LAMBDA_MIN, spectra.LAMBDA_MAX + 0.5, FORMULA_STEP_NM)
                eta = _spectrum_param("eta", wl, dispersion.ior(value, wl) / ext)
                notes.append("dispersive: n(l) / ext_ior at 1 nm; pbrt follows one wavelength per sample past it")
            else:
                eta = f'"float eta" [ {_num(float(value) / ext)} ]'
            return f'Material "dielectric"\n    {eta}\n    {rough_text}', notes
        raise ValueError(f"unknown bsdf type {b['type']!r}")

    def shape(self, obj):
        s = obj["shape"]
        if s["type"] == "rectangle":
            return [f"Transform {_matrix(s['to_world'])}",
                    'Shape "trianglemesh" "point3 P" [ -1 -1 0 1 -1 0 1 1 0 -1 1 0 ] "integer indices" [ 0 1 2 0 2 3 ]']
        if s["type"] == "sphere":
            c = s["center"]
            return [f"Translate {_num(c[0])} {_num(c[1])} {_num(c[2])}",
                    f'Shape "sphere" "float radius" [ {_num(s["radius"])} ]']
        if s["type"] == "mesh":
            verts, faces = mesh_io.load_mesh(s, self.scene.get("_base_dir"))
            v = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
            if "to_world" in s:  # world coordinates, as the Mitsuba and ART exports place them
                m = np.asarray(s["to_world"], dtype=np.float64)
                v = v @ m[:3, :3].T + m[:3, 3]
            rel = f"meshes/{names.file_stem(obj['name'])}.ply"
            mesh_io.write_ply(self.out / rel, v, faces, uvs=s.get("uvs"))
            return [f'Shape "plymesh" "string filename" "{rel}"']
        raise ValueError(f"unknown shape type {s['type']!r}")

    def backing(self, obj):
        """A one-sided rectangle's black closed backing (module docstring), under the rectangle's
        Transform: its four corners and the same four moved BACKING_DEPTH of the shorter side behind
        it (along the IR's normal, in world units), a back and four sides of reflectance 0."""
        m = np.asarray(obj["shape"]["to_world"], dtype=np.float64)[:3, :3]
        inv = np.linalg.inv(m)
        normal = inv.T @ np.array([0.0, 0.0, 1.0])
        normal /= np.linalg.norm(normal)
        depth = BACKING_DEPTH * min(np.linalg.norm(m @ [2.0, 0.0, 0.0]), np.linalg.norm(m @ [0.0, 2.0, 0.0]))
        offset = _settled(inv @ (-depth * normal))  # in the rectangle's own coordinates
        lid = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
        points = np.vstack([lid, lid + offset])
        tris = [4, 5, 6, 4, 6, 7]
        for i in range(4):
            j = (i + 1) % 4
            tris += [i, j, j + 4, i, j + 4, i + 4]
        return [f"# {names.comment_text(obj['name'])}'s black backing: one sided in the IR (APPROXIMATED above)",
                'Material "diffuse" "spectrum reflectance" [ 360 0 830 0 ]',
                f'Shape "trianglemesh" "point3 P" {_list(points.reshape(-1))} "integer indices" [ '
                + " ".join(str(t) for t in tris) + " ]"]

    def camera(self):
        sc = self.scene
        cam, r = sc["camera"], sc["render"]
        w, h = int(r["width"]), int(r["height"])
        to_world = np.asarray(cam["to_world"], dtype=np.float64) @ _CAMERA_FLIP
        camera_from_world = _settled(np.linalg.inv(to_world))
        if cam.get("fov_axis", "x") == "x":
            window = (-1.0, 1.0, -h / w, h / w)
        else:
            window = (-w / h, w / h, -1.0, 1.0)
        return [f"# camera {names.comment_text(cam.get('name', 'camera'))}: the IR's to_world times diag(1, 1, -1), inverted",
                f"Transform {_matrix(camera_from_world)}",
                f'Camera "perspective" "float fov" [ {_num(cam["fov"])} ] "float screenwindow" {_list(window)}',
                f'Sampler "{SAMPLER}" "integer pixelsamples" [ {int(r["spp"])} ]',
                f'Integrator "path" "integer maxdepth" [ {int(r.get("max_depth", 64)) - 1} ]',
                'PixelFilter "box" "float xradius" [ 0.5 ] "float yradius" [ 0.5 ]',
                f'Film "spectral" "integer xresolution" [ {w} ] "integer yresolution" [ {h} ] '
                f'"string filename" "{FILM_FILE}"\n    "bool savefp16" false "integer nbuckets" [ {FILM["nbuckets"]} ] '
                f'"float lambdamin" [ {_num(FILM["lambdamin"])} ] "float lambdamax" [ {_num(FILM["lambdamax"])} ]']

    def lights(self, skipped=()):
        out = []
        for light in self.scene.get("lights", []):
            out.append(f"# light {names.comment_text(light['name'])}")
            if light["name"] in skipped:
                out.append("# (left out: see NOT EXPRESSED above)")
                continue
            kind = light["type"]
            if kind == "point":
                p = light["position"]
                out.append(f'LightSource "point" "point3 from" {_list(p)}\n    {self.light_params("I", light["intensity"])}')
            elif kind == "spot":
                cutoff = float(light["cutoff_angle"])
                out += ["AttributeBegin", f"    Transform {_matrix(light['to_world'])}",
                        f'    LightSource "spot" "point3 from" [ 0 0 0 ] "point3 to" [ 0 0 1 ] "float coneangle" '
                        f'[ {_num(cutoff)} ] "float conedelta" [ 0 ]\n        {self.light_params("I", light["intensity"])}',
                        "AttributeEnd"]
            else:
                out.append(f'LightSource "distant" "point3 from" [ 0 0 0 ] "point3 to" {_list(light["direction"])}\n'
                           f'    {self.light_params("L", light["irradiance"])}')
        return out

    def write(self):
        sc = self.scene
        self.scene_problems()
        skipped = {o for o, f, _m in self.unsupported if f.startswith(("bsdf", "emitter"))}
        skipped_lights = {o for o, f, _m in self.unsupported if f == "beam_width"}
        lines = [f"# {names.comment_text(sc['name'])} ({names.comment_text(sc.get('case'))}), written from the scene IR "
                 f"v{ir.VERSION} by spectral_bench for pbrt v4 (exporters/pbrt_writer.py)",
                 "# every light's scale is its spectrum's photometric value (which pbrt divides by, lights.cpp) over "
                 "CIE_Y_integral (which the spectral film multiplies by, film.h)"]
        if self.planted != 1.0:
            lines.append(f"# {TEST_HOOK}={self.planted!r}: every light's scale is multiplied by it (a planted error)")
        for o, f, m in self.unsupported:
            lines.append(f"# NOT EXPRESSED (left out): {names.comment_text(f'{o}.{f}: {m}')}")
        self.approximated = self.approximations()
        for o, f, m in self.approximated:
            lines.append(f"# APPROXIMATED: {names.comment_text(f'{o}.{f}: {m}')}")
        backed = {o for o, f, _m in self.approximated if f == "bsdf.type"
                  and next(x for x in sc["objects"] if x["name"] == o)["shape"]["type"] == "rectangle"}
        if sc["render"].get("integrator", "path") != "path":
            lines.append(f"# the IR asks for the {names.comment_text(sc['render']['integrator'])} estimator; pbrt's path "
                         "tracer estimates the same image")
        lines += self.camera()
        lines += ["", "WorldBegin", ""]
        env = sc.get("environment")
        if textures.env_map(env):
            # pbrt's image light reads an equal-area octahedral square (resampled, rotation applied)
            # in the world's frame, uplifts each texel as an RGBIlluminantSpectrum and divides by
            # its colour space's illuminant's photometric value: with the film's CIE_Y_integral, a
            # white texel is D65 of luminance 1, the IR's (docs/scene-format.md 7.1); scale as is
            rel = textures.write_equal_area(env, sc.get("_base_dir"), self.out)
            lines.append(f'LightSource "infinite" "string filename" "{rel}" '
                         f'"float scale" [ {_num(float(env.get("scale", 1.0)) * self.planted)} ]')
        elif env:
            lines.append(f'LightSource "infinite" {self.light_params("L", env["radiance"])}')
        lines += self.lights(skipped_lights)
        for obj in sc["objects"]:
            lines.append("")
            lines.append(f"# {names.comment_text(obj['name'])}")
            if obj["name"] in skipped:
                lines.append("# (left out: see NOT EXPRESSED above)")
                continue
            material, notes = self.material(obj)
            lines.append("AttributeBegin")
            lines += [f"    # {names.comment_text(n)}" for n in notes]
            em = obj.get("emitter")
            shape = self.shape(obj)
            backing = self.backing(obj) if obj["name"] in backed else []
            if backing and em:  # before the AreaLightSource, which applies to every shape after it
                lines += ["    " + line for line in shape[:-1] + backing]
                shape = shape[-1:]
                backing = []
            lines.append("    " + material)
            if em:
                lines.append(f'    AreaLightSource "diffuse" {self.light_params("L", em["radiance"])} "bool twosided" false')
            lines += ["    " + line for line in shape + backing]
            lines.append("AttributeEnd")
        self.out.mkdir(parents=True, exist_ok=True)
        path = self.out / SCENE_FILE
        path.write_text("\n".join(lines) + "\n")
        return path


def unsupported(scene):
    """[(object, field, message)] of what pbrt-v4 cannot express in ``scene``, without writing."""
    return _Writer(scene, Path(".")).scene_problems()


def approximations(scene):
    """[(object, field, message)] of what pbrt-v4 expresses only by a stated modelling in ``scene``
    (module docstring), without writing; objects left out as unsupported are not listed."""
    return _Writer(scene, Path(".")).approximations()


def shadowing_ratio(alpha, theta_deg):
    """pbrt-v4's height-correlated GGX G2 over the separable G1 G1 with view and light both
    ``theta_deg`` from the normal: 1 + L L / (1 + 2 L), L = (sqrt(1 + alpha^2 tan^2) - 1) / 2."""
    lam = (math.sqrt(1.0 + (alpha * math.tan(math.radians(theta_deg))) ** 2) - 1.0) / 2.0
    return 1.0 + lam * lam / (1.0 + 2.0 * lam)


def write(scene, out_dir):
    """Write ``scene`` into ``out_dir``; returns the path of scene.pbrt. What pbrt-v4 cannot express
    (``unsupported(scene)``) is left out and named at the top of the file."""
    return _Writer(scene, out_dir).write()
