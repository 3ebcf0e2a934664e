"""ART (Advanced Rendering Toolkit 2.1.2) writer: IR scene -> folder with a self-contained
scene.arm and, for meshes, meshes/*.ply (ART has no OBJ loader).

Geometry is written in world coordinates (rectangles as quadrangles of their four corners,
meshes pre-transformed), so no ART transform conventions are involved; spheres use ART's unit
SPHERE scaled and translated. ART's camera has no up vector: it derives one from world +Z, which
is the IR's up, so cameras must have no roll (reported otherwise).

Radiometry: named CIE illuminants use ART's own tables, which are raw CIE data (D65 = 100 at
560 nm), so the IR's scale s (1.0 at 560 nm) is written as s / 100. Every other non-constant
spectrum is written as a point-sampled spectrum with the IR's values. ART's film then gives the
same absolute radiance as Mitsuba's with ``-wp d65`` (linear sRGB with a D65 white; ART's
default white point is D50). Measured: the ColorChecker under ART's D65 table renders within
0.3 dE00 of the analytic probe with ``-s46e``; the same D65 written as a sampled (or regular)
spectrum came out 10 % darker under ``-s46e`` (identical under the default 8 samples), so
illuminants with an ART table use it.

Fluorescence: the IR's bands form is ART's CONST_FLUORESCENT_COLOUR(reflectance, strength,
PNT2D(absorption, emission), VEC2D(absorption width, emission width)) under a LAMBERT_REFLECTOR,
with the same meaning (exporters/fluorescence.py was written from ART's ArCrosstalk500.c). ART
tabulates the re-radiation from 300 to 799 nm, so an emission band reaching 800 nm or beyond is
reported, and a re-radiation matrix is not mapped (reported). Spectra of fluorescent scenes are
written from 300 nm, as for Mitsuba, so that UV excitation sees the scene's values.

What ART cannot express is returned per object and field, never silently replaced:
upstream ART has no GGX or Beckmann microfacets (Blinn only), no thin-film interference, no light
tracer and no collimated emitter; of the IOR models only Sellmeier (and named glasses, which are
Sellmeier) and constants; and its outside medium is vacuum. Named conductors are written with the
IR's own eta/k tables (Mitsuba's data, exporters/data), not ART's material presets, so both
renderers render the same metal.

Test hook (tests/backends/test_art.py, docs/developing.md): ``SPECTRAL_BENCH_TEST_ART_ILLUMINANT_SCALE=F``
in the environment multiplies every emitter's and the environment's brightness by F (a planted
error of the ART route, which the ART render tests must detect), and the .arm says so in a
comment. Unset, nothing changes.
"""
from pathlib import Path

import numpy as np

from . import dispersion, fluorescence, ir, mesh_io, names, planted, spectra, textures

# ART's own CIE illuminant tables are raw CIE data (D65 = 100 at 560 nm): the IR's scale s
# (1.0 at 560 nm) becomes s / (raw table value at 560 nm): s / 100 for A and the D series, s / 11.76
# for FL8 (the CIE FL tables are not normalised at 560 nm; ART_Resources/SpectralData/CIEIlluminant.ark
# holds the same CIE 15:2004 values as colour-science, exporters/data/cie_illuminants.json)
ART_ILLUMINANTS = {"cie_a": "CIE_ILLUMINANT_A", "cie_d50": "CIE_ILLUMINANT_D50", "cie_d55": "CIE_ILLUMINANT_D55",
                   "cie_d65": "CIE_ILLUMINANT_D65", "cie_d75": "CIE_ILLUMINANT_D75", "cie_fl2": "CIE_ILLUMINANT_FL2",
                   "cie_fl7": "CIE_ILLUMINANT_FL7", "cie_fl8": "CIE_ILLUMINANT_FL8", "cie_fl11": "CIE_ILLUMINANT_FL11"}
ART_TABLE_AT_560NM = 100.0  # A and the D series
ART_CROSSTALK_RANGE = (300.0, 799.0)  # nm: ART's ArCrosstalk500, 500 cells of 1 nm from 300 nm
TEST_HOOK = "SPECTRAL_BENCH_TEST_ART_ILLUMINANT_SCALE"


def planted_scale():
    """The test hook's factor on every emitter (1.0 when unset); a value that is not a positive
    number is an error naming the variable."""
    return planted.scale(TEST_HOOK)


def _num(x):
    return repr(round(float(x), 9))


def raw_table_at_560nm(name):
    """The raw CIE table's value at 560 nm (what ART's table has there)."""
    if name.startswith("cie_fl"):
        t = spectra._named_tables()[name][0]
        return float(np.interp(spectra.NORMALISATION_NM, t["wavelengths"], t["values"]))
    return ART_TABLE_AT_560NM


def _pnt(p):
    return f"PNT3D({_num(p[0])}, {_num(p[1])}, {_num(p[2])})"


class _Writer:
    def __init__(self, scene, out_dir, ggx=False):
        self.scene, self.out, self.ggx = scene, Path(out_dir), ggx
        self.unsupported = []  # (object, field, message)
        self.lines = []
        fluorescent = "fluorescence" in ir.derived_needs(scene)
        self.spectra_from = fluorescence.FLUORESCENT_SPECTRA_FROM if fluorescent else spectra.LAMBDA_MIN
        self.planted = planted_scale()

    def fluorescent(self, name, b):
        """CONST_FLUORESCENT_COLOUR under a Lambertian reflector (None when ART cannot take it)."""
        fl = b["fluorescence"]
        if fl["type"] != "bands":
            self.unsupported.append((name, "bsdf.fluorescence", "a re-radiation matrix: this writer maps ART's "
                                     "CONST_FLUORESCENT_COLOUR bands only"))
            return None
        lo, hi = ART_CROSSTALK_RANGE
        for band in ("absorption", "emission"):
            p, w = fl[f"{band}_peak"], fl[f"{band}_width"]
            if p - w < lo or p + w > hi:
                self.unsupported.append((name, f"bsdf.fluorescence.{band}_width",
                                         f"the {band} band {p - w:g}-{p + w:g} nm leaves ART's re-radiation "
                                         f"table ({lo:g}-{hi:g} nm)"))
                return None
        return (f"LAMBERT_REFLECTOR(CONST_FLUORESCENT_COLOUR({self.colour(b['reflectance'])},\n"
                f"            {_num(fl['strength'])},\n"
                f"            PNT2D({_num(fl['absorption_peak'])} NM, {_num(fl['emission_peak'])} NM),\n"
                f"            VEC2D({_num(fl['absorption_width'])} NM, {_num(fl['emission_width'])} NM)))")

    def emission(self, spec):
        """(colour, brightness) of an emitted spectrum (times the test hook's planted factor)."""
        if spec.get("type") == "named" and spec["name"] in ART_ILLUMINANTS:
            return ART_ILLUMINANTS[spec["name"]], self.planted * spec.get("scale", 1.0) / raw_table_at_560nm(spec["name"])
        return self.colour(spec), self.planted

    def colour(self, spec):
        if spectra.is_constant(spec):
            return f"CONST_COLOUR_GREY({_num(spec['value'])})"
        wl, vals = spectra.tabulate(spec, lo=self.spectra_from)
        pts = [f"PNT2D({w:g} NM, {_num(v)})" for w, v in zip(wl, vals)]
        rows = ",\n            ".join(", ".join(pts[i:i + 6]) for i in range(0, len(pts), 6))
        return f"CONST_COLOUR_PSSPECTRUM(1.0,\n            {rows},\n            PSS_END)"

    def ior(self, obj):
        """ART's expression of a dielectric's int_ior: a grey colour, or a Sellmeier dispersion
        CONST_SELLMEIER_DISPERSION_6(B1, C1, B2, C2, B3, C3) (ArnSellmeierDispersion.m: n^2 = 1 +
        sum B_i l^2 / (l^2 - C_i), l in micrometres, C_i in um^2, the IR's convention); None
        (and an unsupported entry) for a model ART cannot take exactly."""
        value = obj["bsdf"]["int_ior"]
        if not dispersion.is_model(value):
            return f"CONST_COLOUR_GREY({_num(value)})"
        coeffs = dispersion.sellmeier(value)
        if coeffs is None:
            self.unsupported.append((obj["name"], "bsdf.int_ior",
                                     f"ART has no {value.get('type')} dispersion and it is not an exact Sellmeier "
                                     "(ART takes CONST_SELLMEIER_DISPERSION_6 only)"))
            return None
        b, c = coeffs
        return "CONST_SELLMEIER_DISPERSION_6(" + ", ".join(_num(x) for pair in zip(b, c) for x in pair) + ")"

    def surface(self, obj):
        """ART material expression of an object's BSDF (None when unsupported)."""
        b, name = obj["bsdf"], obj["name"]
        if b.get("reflectance_texture") is not None:
            self.unsupported.append((name, "bsdf.reflectance_texture", "an image texture: this writer maps no ART "
                                     "texture to it (the .arm's surfaces here take one spectrum per object)"))
            return None
        if b["type"] == "diffuse" and b.get("fluorescence") is not None:
            return self.fluorescent(name, b)
        if b["type"] == "diffuse":
            return f"LAMBERT_REFLECTOR({self.colour(b['reflectance'])})"
        if b["type"] == "coated_diffuse":
            self.unsupported.append((name, "bsdf.type", "a coated diffuse (Mitsuba 3's plastic, docs/scene-format.md "
                                     "6.6): this writer maps no ART surface to it (ART's layered surfaces are another "
                                     "model, not checked against this closed form)"))
            return None
        if b.get("thin_film") is not None:
            self.unsupported.append((name, "bsdf.thin_film", "ART has no thin-film interference (upstream "
                                     "ART 2.1.2 has no iridescent surface; thesis 3.3.5)"))
            return None
        rough = b.get("roughness")
        surface = "SMOOTH_FRESNEL_SURFACE"
        if rough is not None and rough["alpha"] > 0:
            if rough["distribution"] == "ggx" and self.ggx:
                surface = f"TORRANCE_SPARROW_SURFACE(GGX_MICROFACET_DISTRIBUTION_CONST({_num(rough['alpha'])}))"
            else:
                self.unsupported.append((name, "bsdf.roughness.distribution",
                                         f"{rough['distribution']} microfacets: upstream ART has Blinn only "
                                         "(use --art-ggx with an ART build that has GGX_MICROFACET_DISTRIBUTION_CONST)"))
                return None
        if b["type"] == "conductor":
            eta, k = spectra.named_conductor(b["material"]) if "material" in b else (b["eta"], b["k"])
            material = f"STANDARD_MATERIAL({self.colour(eta)}, {self.colour(k)})"
        else:
            ext = b.get("ext_ior", ir.AIR_IOR)
            if abs(ext - 1.0) > 1e-3:
                self.unsupported.append((name, "bsdf.ext_ior", f"ART's outside medium is vacuum; got {ext}"))
                return None
            ior = self.ior(obj)
            if ior is None:
                return None
            material = f"STANDARD_MATERIAL({ior}, CONST_COLOUR_GREY(0.0))"
            if obj["shape"]["type"] != "rectangle":
                # a dielectric solid takes its surface and its interior medium as two attributes;
                # SUPPLY_MATERIAL rendered ART's glass spheres dark (measured), while a lone
                # quadrangle, which bounds no solid, needs it (the thesis' scenes do the same)
                return f"{surface} : {material}"
        return f"SUPPLY_MATERIAL({surface}, {material})"

    def shape(self, k, obj, material):
        s, var = obj["shape"], f"obj{k}"
        self.lines.append(f"    // {names.comment_text(obj['name'])}")
        if s["type"] == "rectangle":
            m = np.asarray(s["to_world"], dtype=np.float64)
            corners = [m @ np.array([x, y, 0.0, 1.0]) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
            self.lines.append(f"    Pnt3D * {var}_points = ALLOC_ARRAY(Pnt3D, 5);")
            for i, c in enumerate(corners):
                self.lines.append(f"    {var}_points[{i}] = {_pnt(c[:3])};")
            self.lines += [f"    {var}_points[4] = PNT3D_HUGE;",
                           f"    ArObj {var} = [ QUADRANGLE(0, 1, 2, 3) apply",
                           f"        : arnvertexset(art_gv, {var}_points, NULL, NULL, NULL, NULL)",
                           f"        : {material} ];"]
        elif s["type"] == "sphere":
            c = s["center"]
            self.lines.append(f"    ArObj {var} = [ SPHERE apply : {material} : USCALE({_num(s['radius'])})"
                              f" : TRANSLATION({_num(c[0])}, {_num(c[1])}, {_num(c[2])}) ];")
        else:
            verts, faces = mesh_io.load_mesh(s, self.scene.get("_base_dir"))
            v = np.asarray(verts, dtype=np.float64)
            if "to_world" in s:
                m = np.asarray(s["to_world"], dtype=np.float64)
                v = v @ m[:3, :3].T + m[:3, 3]
            rel = f"meshes/{names.file_stem(obj['name'])}.ply"
            mesh_io.write_ply(self.out / rel, v, faces)
            self.lines.append(f'    ArObj {var} = [ PLY_MESH("{rel}") apply : {material} ];')
        return var

    def scene_problems(self):
        """What ART cannot render in the scene as a whole: light tracing, collimated beams."""
        sc = self.scene
        integrator = sc["render"].get("integrator", "path")
        if integrator != "path":
            self.unsupported.append(("render", "integrator", f"{integrator!r}: ART's PATHTRACER traces from the camera only"))
        for obj in sc["objects"]:
            if (obj.get("emitter") or {}).get("type") == "collimated":
                self.unsupported.append((obj["name"], "emitter.type", "ART has no collimated (directional area) emitter"))
        if textures.env_map(sc.get("environment")):
            self.unsupported.append(("environment", "type", "an environment map: this writer maps no ART "
                                     "environment to it (UNIFORM_ENVIRONMENT_MATERIAL is uniform)"))
        for light in sc.get("lights", []):
            self.unsupported.append((light["name"], "type", f"a {light['type']} light: not mapped to ART's light "
                                     "sources (only area emitters and the uniform environment are)"))

    def camera(self):
        cam, r = self.scene["camera"], self.scene["render"]
        m = np.asarray(cam["to_world"], dtype=np.float64)
        eye, forward, up = m[:3, 3], -m[:3, 2] / np.linalg.norm(m[:3, 2]), m[:3, 1] / np.linalg.norm(m[:3, 1])
        horizontal = np.cross(forward, np.array([0.0, 0.0, 1.0]))
        if np.linalg.norm(horizontal) < 1e-3:
            self.unsupported.append((cam.get("name", "camera"), "to_world", "ART cannot look straight along the vertical"))
        else:
            expected_up = np.cross(horizontal / np.linalg.norm(horizontal), forward)
            if expected_up @ up < 1 - 1e-6:
                self.unsupported.append((cam.get("name", "camera"), "to_world",
                                         "camera roll: ART takes its up vector from world +Z"))
        w, h = r["width"], r["height"]
        t = np.tan(np.radians(cam["fov"]) / 2)
        t_diag = t * np.hypot(w, h) / (w if cam.get("fov_axis", "x") == "x" else h)
        zoom = 1.0 / (2.0 * t_diag)  # ArnCamera: tan(half diagonal field of view) = 1 / (2 zoom)
        return (f"[ CAMERA imageSize: IVEC2D({w}, {h}) ray: RAY3D({_pnt(eye)}, "
                f"VEC3D({_num(forward[0])}, {_num(forward[1])}, {_num(forward[2])})) zoom: {_num(zoom)} ]")

    def actions(self):
        sc, r = self.scene, self.scene["render"]
        # the pixel sampler needs a light source collection even when only the environment emits
        acts = ["CREATE_STANDARD_RAYCASTING_ACCELERATION_STRUCTURE",
                "[ LIGHTSOURCE_COLLECTOR sampler2D: STANDARD_SAMPLER_2D resolution: 5 type: arlightsourcetype_area ]"]
        acts.append("[ STOCHASTIC_PIXEL_SAMPLER\n"
                    "            sampleProvider: [ PATHTRACER rayCaster: STANDARD_RAYCASTER "
                    f"maximalRecursion: {r.get('max_depth', 64)} ]\n"
                    "            sampleSplattingKernel: BOX_KERNEL\n"
                    "            samplesPerPixel: SAMPLES\n"
                    "            randomValueGeneration: PSEUDORANDOM_SEQUENCE ]")
        pol = sc["camera"].get("polarizer")
        if pol:
            # ART's filter angle: transmission axis, 0 = horizontal, counter-clockwise as seen
            # from the camera (the IR's convention; tests/backends/test_art.py checks it when ART is present)
            acts.append(f"[ LINEAR_POLARISATION_FILTER angle: {_num(pol['angle'])} DEGREES strength: 1.0 ]")
        # always ART's spectral EXR (its 46 bands, S0..S3 with -p): the backend integrates it with
        # the CIE 1931 CMFs to linear sRGB as the IR defines colour. ART's own sRGB output maps
        # out-of-gamut colours into the gamut (measured: ColorChecker cyan's negative red comes out
        # positive, a 450 nm light's blue 1.06 instead of 5.26), which is ART's display choice, not
        # its light transport.
        acts.append("[ IMAGECONVERSION_ARTRAW_TO_SPECTRAL_EXR removeSource: NO ]")
        return ",\n        ".join(acts + ["ACTION_SEQUENCE_END"])

    def write(self):
        sc = self.scene
        self.lines = [f"// {names.comment_text(sc['name'])} ({names.comment_text(sc.get('case'))}), written from the scene IR v{ir.VERSION} by spectral_bench",
                      *([f"// {TEST_HOOK}={self.planted!r}: every emitter's brightness is scaled (a planted error)"]
                        if self.planted != 1.0 else []),
                      f"#ifndef SAMPLES\n#define SAMPLES {sc['render']['spp']}\n#endif", "",
                      "ARM_MAIN_FUNCTION(scene)", "{"]
        parts = []
        self.scene_problems()
        for k, obj in enumerate(sc["objects"]):
            if (obj.get("emitter") or {}).get("type") == "collimated":
                continue  # reported by scene_problems
            if obj.get("emitter"):
                colour, brightness = self.emission(obj["emitter"]["radiance"])
                material = f"LAMBERT_EMITTER({colour}, {_num(brightness)})"
                if obj.get("bsdf"):
                    self.unsupported.append((obj["name"], "bsdf", "an emitter with a BSDF (ART emitters reflect nothing)"))
            else:
                material = self.surface(obj)
            if material is None:
                continue
            parts.append(self.shape(k, obj, material))
        env = sc.get("environment")
        env_line = None
        if textures.env_map(env):
            env = None  # unsupported (scene_problems)
        if env:
            colour, brightness = self.emission(env["radiance"])
            env_line = f"UNIFORM_ENVIRONMENT_MATERIAL({colour}, {_num(brightness)})"
        self.lines += ["", f"    id geometry = UNION({', '.join(parts)}, UNION_END);",
                       f"    id camera = {self.camera()};",
                       f"    id actions = ACTION_SEQUENCE(\n        {self.actions()}\n        );",
                       "    return [ SCENE", "        sceneGeometry: geometry"]
        if env_line:
            self.lines.append(f"        environmentMaterial: {env_line}")
        self.lines += ["        camera: camera", "        actionSequence: actions", "        ];", "}", ""]
        self.out.mkdir(parents=True, exist_ok=True)
        path = self.out / "scene.arm"
        path.write_text("\n".join(self.lines))
        return path


def unsupported(scene, ggx=False):
    """[(object, field, message)] of what ART cannot express in ``scene``, without writing."""
    w = _Writer(scene, Path("."), ggx=ggx)
    w.scene_problems()
    for obj in scene["objects"]:
        if (obj.get("emitter") or {}).get("type") == "collimated":
            continue
        if obj.get("emitter"):
            if obj.get("bsdf"):
                w.unsupported.append((obj["name"], "bsdf", "an emitter with a BSDF (ART emitters reflect nothing)"))
        else:
            w.surface(obj)
    w.camera()
    return w.unsupported


def write(scene, out_dir, ggx=False):
    """Write ``scene``; returns (path of scene.arm, [(object, field, message) ART cannot express])."""
    w = _Writer(scene, out_dir, ggx=ggx)
    path = w.write()
    return path, w.unsupported
