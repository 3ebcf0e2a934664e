"""Spectral annotations stored on Blender datablocks (``<datablock>.spectral_bench``).

Ranges are soft (UI sliders) on purpose: an out-of-range value is kept and reported by the
IR validation with scene, object and field, rather than silently clamped.
"""
import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       FloatVectorProperty, IntProperty, PointerProperty, StringProperty)

from . import dispersion, ir, spectra

SPECTRUM_TYPES = [
    ("CONSTANT", "Constant", "The same value at every wavelength"),
    ("SAMPLED", "Sampled", "Wavelength/value pairs, linearly interpolated, edge values padded"),
    ("NAMED", "Named", "A named table (CIE illuminants), 1.0 at 560 nm times scale"),
    ("BLACKBODY", "Blackbody", "Planck's law at a temperature, 1.0 at 560 nm times scale"),
]


def _named_items(self, context):
    return [(n, n, "") for n in spectra.named_spectra()]


class SpectrumSample(bpy.types.PropertyGroup):
    wavelength: FloatProperty(name="Wavelength (nm)", default=550.0)
    value: FloatProperty(name="Value", default=0.0)


class SpectrumProps(bpy.types.PropertyGroup):
    kind: EnumProperty(name="Type", items=SPECTRUM_TYPES, default="CONSTANT")
    value: FloatProperty(name="Value", default=0.5, soft_min=0.0)
    named: StringProperty(name="Name", default="cie_d65",
                          search=lambda self, context, edit_text: spectra.named_spectra())
    scale: FloatProperty(name="Scale", default=1.0, soft_min=0.0)
    temperature: FloatProperty(name="Temperature (K)", default=6500.0, soft_min=1000.0)
    samples: CollectionProperty(type=SpectrumSample)


MATERIAL_KINDS = [
    ("NONE", "None", "Not annotated: the exporter reports it"),
    ("DIFFUSE", "Diffuse", "Lambertian reflector"),
    ("CONDUCTOR", "Conductor", "Metal with complex IOR (named table or eta/k spectra)"),
    ("DIELECTRIC", "Dielectric", "Transparent dielectric with a real IOR"),
    ("COATED", "Coated Diffuse", "A dielectric coat (Interior IOR, microfacets) over a Lambertian base (Reflectance): "
                                 "Mitsuba 3's plastic / roughplastic"),
]
IOR_MODELS = [
    ("CONSTANT", "Constant", "One IOR at every wavelength (every renderer's native dielectric)"),
    ("NAMED", "Named Glass", "A glass with the manufacturer's Sellmeier coefficients (exporters/dispersion.py)"),
    ("SELLMEIER", "Sellmeier", "n^2 = 1 + sum B_i l^2 / (l^2 - C_i), l in micrometres, C_i in um^2"),
    ("CAUCHY", "Cauchy", "n = A + B / l^2 + C / l^4, l in micrometres"),
]
DISTRIBUTIONS = [("SMOOTH", "Smooth", "Perfectly specular")] + [
    (d.upper(), d.upper() if d == "ggx" else d.title(), f"{d} microfacet distribution") for d in ir.DISTRIBUTIONS]


FLUORESCENCE_KINDS = [
    ("NONE", "None", "Not fluorescent"),
    ("BANDS", "Bands", "Absorption and emission bands (ART's CONST_FLUORESCENT_COLOUR): a pyramid of re-radiation"),
    ("MATRIX", "Matrix", "A re-radiation (Donaldson) matrix from a JSON file: wavelengths and matrix[i][o] in 1/nm"),
]


class MaterialProps(bpy.types.PropertyGroup):
    kind: EnumProperty(name="Model", items=MATERIAL_KINDS, default="NONE")
    reflectance: PointerProperty(type=SpectrumProps)
    conductor_named: BoolProperty(name="Named Conductor", default=True)
    conductor: StringProperty(name="Conductor", default="Cu",
                              search=lambda self, context, edit_text: list(spectra.NAMED_CONDUCTORS))
    eta: PointerProperty(type=SpectrumProps)
    k: PointerProperty(type=SpectrumProps)
    int_ior: FloatProperty(name="Interior IOR", default=1.5046, soft_min=1.0, soft_max=3.0, precision=4)
    ext_ior: FloatProperty(name="Exterior IOR", default=ir.AIR_IOR, soft_min=1.0, soft_max=3.0, precision=6)
    ior_model: EnumProperty(name="IOR Model", items=IOR_MODELS, default="CONSTANT",
                            description="Interior IOR as a function of wavelength (dispersion)")
    glass: StringProperty(name="Glass", default="N-BK7", search=lambda self, context, edit_text: list(dispersion.NAMED_GLASSES))
    sellmeier_b: FloatVectorProperty(name="B", size=3, default=(1.03961212, 0.231792344, 1.01046945), precision=8)
    sellmeier_c: FloatVectorProperty(name="C (um^2)", size=3, default=(0.00600069867, 0.0200179144, 103.560653),
                                     precision=8)
    cauchy_a: FloatProperty(name="A", default=1.5046, precision=6)
    cauchy_b: FloatProperty(name="B (um^2)", default=0.0042, precision=8)
    cauchy_c: FloatProperty(name="C (um^4)", default=0.0, precision=8)
    distribution: EnumProperty(name="Microfacets", items=DISTRIBUTIONS, default="SMOOTH")
    alpha: FloatProperty(name="Alpha", default=0.1, soft_min=0.0, soft_max=1.0, precision=4,
                         description="Microfacet width alpha (Blender roughness r is alpha = r^2)")
    thin_film: BoolProperty(name="Thin Film", default=False,
                            description="A dielectric film on the conductor (thin-film interference, iridescence)")
    film_ior: FloatProperty(name="Film IOR", default=1.33, soft_min=1.0, soft_max=3.0, precision=4)
    film_thickness: FloatProperty(name="Film Thickness (nm)", default=550.0, soft_min=0.0, soft_max=2000.0,
                                  precision=1, description="0 is the bare conductor")
    film_ext_ior: FloatProperty(name="Exterior IOR", default=1.0, soft_min=1.0, soft_max=3.0, precision=6,
                                description="Index of the medium above the film (1: vacuum, as for a bare conductor)")
    # fluorescence of a diffuse material (exporters/fluorescence.py): re-radiation P(l_i, l_o) in 1/nm
    fluorescence: EnumProperty(name="Fluorescence", items=FLUORESCENCE_KINDS, default="NONE")
    absorption_peak: FloatProperty(name="Absorption Peak (nm)", default=370.0, soft_min=300.0, soft_max=830.0)
    absorption_width: FloatProperty(name="Absorption Width (nm)", default=40.0, soft_min=1.0, soft_max=200.0,
                                    description="Half the absorption band's base: re-radiation falls to 0 this far "
                                                "from the peak")
    emission_peak: FloatProperty(name="Emission Peak (nm)", default=650.0, soft_min=300.0, soft_max=830.0)
    emission_width: FloatProperty(name="Emission Width (nm)", default=50.0, soft_min=1.0, soft_max=200.0,
                                  description="Half the emission band's base")
    strength: FloatProperty(name="Strength (1/nm)", default=0.01, soft_min=0.0, soft_max=0.05, precision=4,
                            description="Peak of the re-radiation P in 1/nm (ART's fluo_power); the quantum "
                                        "yield must stay <= 1")
    fluorescence_matrix_file: StringProperty(name="Matrix File", subtype="FILE_PATH", default="",
                                             description="JSON with \"wavelengths\" (nm) and \"matrix\" "
                                                         "(matrix[i][o] = P(w_i, w_o) in 1/nm, 0 where o <= i)")


class LightProps(bpy.types.PropertyGroup):
    radiance: PointerProperty(type=SpectrumProps)
    collimated: BoolProperty(name="Collimated Beam", default=False,
                             description="Emit only along the light's direction (a parallel beam of the light's shape); "
                                         "the spectrum is then the irradiance across the beam. Only a light tracer "
                                         "(scene Integrator: Light Tracer) renders it")


class WorldProps(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Uniform Environment", default=False)
    radiance: PointerProperty(type=SpectrumProps)


SHAPES = [
    ("MESH", "Mesh", "Export the triangulated mesh"),
    ("SPHERE", "Analytic Sphere", "Export as an exact sphere (object location and uniform scale)"),
    ("RECTANGLE", "Analytic Rectangle", "Export as the square [-1,1]^2 in local XY, normal +Z"),
]


class CameraProps(bpy.types.PropertyGroup):
    polarizer: BoolProperty(name="Linear Polariser", default=False,
                            description="An ideal linear polariser in front of the lens")
    polarizer_angle: FloatProperty(name="Transmission Axis (deg)", default=0.0, soft_min=-180.0, soft_max=180.0,
                                   description="Counter-clockwise from image right as seen from the camera: "
                                               "0 horizontal, 90 vertical")


OUTPUTS = [("RGB", "RGB", "Linear sRGB radiance"),
           ("STOKES", "Stokes", "RGB plus Stokes S0..S3 (S1 > 0 horizontal, S2 > 0 at +45 degrees)")]


class ObjectProps(bpy.types.PropertyGroup):
    shape: EnumProperty(name="Shape", items=SHAPES, default="MESH")


class SceneProps(bpy.types.PropertyGroup):
    case: StringProperty(name="Case", default="custom")
    description: StringProperty(name="Description", default="")
    spp: IntProperty(name="Samples", default=64, soft_min=1)
    max_depth: IntProperty(name="Max Depth", default=64, soft_min=1)
    output: EnumProperty(name="Output", items=OUTPUTS, default="RGB")
    needs_polarization: BoolProperty(name="Needs Polarisation", default=False)
    needs_fluorescence: BoolProperty(name="Needs Fluorescence", default=False)
    integrator: EnumProperty(name="Integrator", default="PATH", items=[
        ("PATH", "Path Tracer", "Paths from the camera (every backend)"),
        ("PTRACER", "Light Tracer", "Paths from the lights (Mitsuba's ptracer): caustics such as a collimated "
                                    "beam through a prism; ART has none")])


CLASSES = (SpectrumSample, SpectrumProps, MaterialProps, LightProps, WorldProps, CameraProps, ObjectProps, SceneProps)
TARGETS = {bpy.types.Material: MaterialProps, bpy.types.Light: LightProps, bpy.types.World: WorldProps,
           bpy.types.Camera: CameraProps, bpy.types.Object: ObjectProps, bpy.types.Scene: SceneProps}


def register():
    if getattr(bpy.types.Scene, "spectral_bench", None) is not None and SceneProps.is_registered:
        return  # already registered (batch/blend_input.py registers these alone to read a .blend)
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for target, group in TARGETS.items():
        target.spectral_bench = PointerProperty(type=group)


def unregister():
    for target in TARGETS:
        del target.spectral_bench
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
