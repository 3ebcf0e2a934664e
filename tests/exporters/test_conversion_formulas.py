"""Blender's materials and lights converted to the IR (exporters/blender_conversion.py), in this
process: the conversion takes the node inputs and light values that exporters/extract_blender.py
reads from bpy, so its rules run here without Blender. The same materials and lights as
scripts/make_ordinary_blend.py's "ordinary" scene, with the same expected results as
tests/exporters/test_blender_conversion.py, whose tests extract that scene in a bpy child (slow:
over 1 s of CPU each with their module fixture). Formulas: Cycles' conventions as the module
states them (I = P / (4 pi), L = P / (pi A), alpha = roughness^2: docs/scene-format.md 6.2)."""
import math

import pytest

from spectral_bench.exporters import blender_conversion as conv


def principled(**values):
    """principled() of a Principled BSDF whose inputs are ``values`` (none linked): (bsdf, emitter,
    {field: message})."""
    warnings = {}
    inp = conv.Inputs({k.replace("_", " "): (v, None) for k, v in values.items()},
                      lambda field, msg: warnings.setdefault(field, msg))
    bsdf, emitter = conv.principled(inp, "GGX")
    return bsdf, emitter, warnings


@pytest.mark.parametrize("colour", [(0.8, 0.1, 0.1), (0.1, 0.6, 0.2), (0.1, 0.2, 0.8)])
def test_a_coloured_principled_is_a_coated_diffuse_uplifted_by_jakob_its_specular_layer_the_coat(colour):
    """Issue 42: Principled's specular layer (IOR 1.5, Specular IOR Level 0.5, roughness 0.3) is the
    coat of a coated diffuse over the uplifted base colour, its roughness the coat's GGX alpha; the
    warning says what is approximated, not that highlights are lost."""
    bsdf, emitter, w = principled(Base_Color=(*colour, 1.0), Metallic=0.0, Roughness=0.3, IOR=1.5,
                                  Specular_IOR_Level=0.5)
    assert bsdf["type"] == "coated_diffuse" and bsdf["reflectance"]["type"] == "sampled" and emitter is None
    assert bsdf["int_ior"] == 1.5 and bsdf["ext_ior"] == 1.0
    assert bsdf["roughness"] == {"distribution": "ggx", "alpha": 0.09}
    assert "Jakob 2019" in bsdf["reflectance"]["source"]
    assert "uplifted to a smooth reflectance spectrum by Jakob and Hanika 2019" in w["inputs[Base Color]"]
    msg = w["inputs[Specular IOR Level]"]
    assert "a coated diffuse" in msg and "approximated" in msg and "albedo scaling" in msg
    assert "lost" not in msg and "no IR counterpart" not in msg
    validate_bsdf(bsdf)


def validate_bsdf(bsdf):
    from spectral_bench.exporters import validate
    assert list(validate.bsdf_problems(bsdf)) == []


@pytest.mark.parametrize("ior, level", [(1.5, 1.0), (1.5, 0.25), (1.45, 0.8), (0.8, 0.7)])
def test_specular_ior_level_scales_the_coats_normal_incidence_reflectance(ior, level):
    """Blender's Specular IOR Level l: the layer's normal-incidence reflectance is 2 l F0(IOR) (0.5
    keeps the IOR, 1 doubles F0): the coat gets the IOR of that F0."""
    bsdf, _e, w = principled(Base_Color=(0.5, 0.5, 0.5, 1.0), Metallic=0.0, Roughness=0.0, IOR=ior,
                             Specular_IOR_Level=level)
    eta = bsdf["int_ior"]
    assert conv.f0_from_ior(eta) == pytest.approx(2 * level * conv.f0_from_ior(ior), rel=1e-5)
    assert (eta < 1) == (ior < 1) and "roughness" not in bsdf
    assert f"a coat of IOR {eta:.6g}" in w["inputs[Specular IOR Level]"]


def test_no_specular_layer_is_a_diffuse_and_a_tint_is_said_lost():
    bsdf, _e, w = principled(Base_Color=(0.5, 0.5, 0.5, 1.0), Metallic=0.0, Roughness=0.5, Specular_IOR_Level=0.0)
    assert bsdf == {"type": "diffuse", "reflectance": {"type": "constant", "value": 0.5}}
    assert "no specular layer" in w["inputs[Specular IOR Level]"]
    bsdf, _e, w = principled(Base_Color=(0.5, 0.5, 0.5, 1.0), Metallic=0.0, Roughness=0.5, Specular_Tint=(1, 0.5, 0.5, 1))
    assert bsdf["type"] == "coated_diffuse" and "rendered untinted" in w["inputs[Specular Tint]"]
    assert bsdf["roughness"]["alpha"] == 0.25  # Principled's default roughness 0.5


def test_a_metallic_gold_principled_is_the_measured_au_with_alpha_roughness_squared():
    bsdf, emitter, w = principled(Base_Color=(1.0, 0.78, 0.34, 1.0), Metallic=1.0, Roughness=0.3)
    assert bsdf == {"type": "conductor", "material": "Au", "roughness": {"distribution": "ggx", "alpha": 0.09}}
    assert emitter is None
    assert "rendered as Au" in w["inputs[Base Color]"]
    assert "alpha = roughness^2 = 0.09" in w["inputs[Roughness]"]


def test_lights_watts_become_the_irs_radiometry():
    assert conv.point_intensity(100.0) == pytest.approx(100.0 / (4 * math.pi)) and f"{conv.point_intensity(100.0):.6g}" == "7.95775"
    assert f"{conv.area_radiance(300.0, 1.0):.5g}" == "95.493"  # the ordinary scene's 300 W, 1 m^2 area light
    assert conv.area_radiance(300.0, 0.5) == pytest.approx(2 * conv.area_radiance(300.0, 1.0))
    assert conv.area_radiance(300.0, 0.5, normalize=False) == pytest.approx(300.0 / math.pi)  # Normalize off
    assert conv.sun_irradiance(3.0) == 3.0
    assert conv.ggx_alpha(0.3) == 0.09
