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
def test_a_coloured_principled_is_a_diffuse_uplifted_by_jakob_and_its_specular_layer_is_a_warning(colour):
    bsdf, emitter, w = principled(Base_Color=(*colour, 1.0), Metallic=0.0, Roughness=0.3)
    assert bsdf["type"] == "diffuse" and bsdf["reflectance"]["type"] == "sampled" and emitter is None
    assert "Jakob 2019" in bsdf["reflectance"]["source"]
    assert "uplifted to a smooth reflectance spectrum by Jakob and Hanika 2019" in w["inputs[Base Color]"]
    assert "has no IR counterpart" in w["inputs[Specular IOR Level]"]


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
