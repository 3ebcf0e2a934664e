"""Issue 42: a Principled BSDF made with bpy, as a Blender user makes one (no spectral annotation on
the material; the object marked an analytic sphere), exports as a coated diffuse whose render is
what the coat's closed form predicts: Mitsuba's render passes the coat probe, and the coat's
Fresnel brightens the sphere's rim above the render of the same sphere without its specular layer
(Specular IOR Level 0: a diffuse), beyond noise, by the amount the closed forms predict. One bpy
child for the module."""
import copy

import numpy as np
import pytest

from conftest import render_with_noise, run_bpy
from spectral_bench.batch.verdict import probes
from spectral_bench.batch.verdict.probes import coated, thin_film
from spectral_bench.exporters import colorimetry, validate

pytestmark = pytest.mark.slow  # a bpy child and Mitsuba renders: over 1 s of CPU (benchmarks/TESTS.md)

SIZE, SPP = 64, 64
BASE = (0.8, 0.1, 0.1)


@pytest.fixture(scope="module")
def exported():
    return run_bpy(f"""
        import math
        from spectral_bench.exporters import extract_blender
        out = {{}}
        for name, level in (("coat", 0.5), ("bare", 0.0)):
            sc = bpy.data.scenes.new(name)
            m = bpy.data.materials.new(name + "_red")
            p = m.node_tree.nodes["Principled BSDF"]
            p.inputs["Base Color"].default_value = (*{BASE!r}, 1.0)
            p.inputs["Roughness"].default_value = 0.0
            p.inputs["Specular IOR Level"].default_value = level
            me = bpy.data.meshes.new(name + "_ball")
            import bmesh
            bm = bmesh.new()
            bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=1.0)
            bm.to_mesh(me)
            bm.free()
            me.materials.append(m)
            ob = bpy.data.objects.new(name + "_ball", me)
            ob.spectral_bench.shape = "SPHERE"
            sc.collection.objects.link(ob)
            w = bpy.data.worlds.new(name + "_sky")
            w.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            w.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
            sc.world = w
            cd = bpy.data.cameras.new(name + "_cam")
            cd.sensor_fit, cd.angle = "HORIZONTAL", math.radians(34.0)
            cam = bpy.data.objects.new(name + "_cam", cd)
            cam.location, cam.rotation_euler = (0.0, -4.0, 0.0), (math.radians(90), 0.0, 0.0)
            sc.collection.objects.link(cam)
            sc.camera = cam
            sc.render.resolution_x = sc.render.resolution_y = {SIZE}
            sc.render.resolution_percentage = 100
            out[name] = extract_blender.extract_scene(sc)
        # the Model set to Coated Diffuse and nothing else: the base takes Blender's colour, said
        bpy.data.materials["coat_red"].spectral_bench.kind = "COATED"
        out["model_only"] = extract_blender.extract_scene(bpy.data.scenes["coat"])
        print(json.dumps(out))
    """)


def _warnings(scene):
    return {(w["object"], w["field"]): w["message"] for w in scene.get("warnings", [])}


def test_the_specular_layer_is_a_coat_said_approximated(exported):
    sc = exported["coat"]
    validate.check(copy.deepcopy(sc))
    (ball,) = sc["objects"]
    assert ball["shape"]["type"] == "sphere"
    b = ball["bsdf"]
    assert b["type"] == "coated_diffuse" and "roughness" not in b and b["ext_ior"] == 1.0
    assert b["int_ior"] == pytest.approx(1.5)  # Blender 5.0.1's default IOR, Specular IOR Level 0.5
    msg = _warnings(sc)[("coat_ball", "material[coat_red].node_tree.nodes[Principled BSDF].inputs[Specular IOR Level]")]
    assert "a coated diffuse" in msg and "approximated" in msg and "lost" not in msg
    assert exported["bare"]["objects"][0]["bsdf"]["type"] == "diffuse"


def test_the_coat_renders_its_closed_form_and_brightens_the_rim_beyond_noise(exported, tmp_path):
    sc, names, img, _se = render_with_noise(exported["coat"], tmp_path / "coat", SPP, passes=1)
    recs = {p["name"]: p for p in probes.evaluate(sc, names, img, observers=["mitsuba3"])}
    tiles, rings = recs["coated coat_ball"], recs["coated coat_ball by view angle"]
    for rec in (tiles, rings):
        assert rec["pass"] or rec["alternatives"]["mitsuba3"]["pass"], rec
    # the highlight where the coat predicts it: the outer view-angle rings (grazing, F -> 1) of the
    # coated sphere against the same rings of the sphere without its specular layer
    _, _, bare, _ = render_with_noise(exported["bare"], tmp_path / "bare", SPP, passes=1)
    images, mask = coated.expected_images(sc, 0, SIZE, SIZE)
    used = np.zeros_like(mask)
    for ys, xs in thin_film.tiles(mask):
        used[ys, xs] = True
    outer = coated.view_rings(sc, 0, SIZE, SIZE, used)[-3:]
    ys = np.concatenate([r[0] for r in outer])
    xs = np.concatenate([r[1] for r in outer])
    y_row = colorimetry.srgb_to_xyz(np.eye(3))[:, 1]
    lum_coat, lum_bare = img[ys, xs, :3] @ y_row, bare[ys, xs, :3] @ y_row
    diff = lum_coat.mean() - lum_bare.mean()
    se = np.hypot(lum_coat.std(ddof=1), lum_bare.std(ddof=1)) / np.sqrt(len(ys))
    predicted = images[colorimetry.GROUND_TRUTH][ys, xs] @ y_row
    assert diff > 5 * se, (diff, se)
    # the diffuse export's rim is rho L (the closed form with a coat of index 1: F = 0), the coat's
    # F + rho (1 - F): their difference (footprint means) is what the renders show, within 5
    # standard errors and Mitsuba's recorded 0.1 % film scale
    no_coat = copy.deepcopy(sc)
    no_coat["objects"][0]["bsdf"].update(int_ior=1.0, ext_ior=1.0)
    rho_l = coated.expected_images(no_coat, 0, SIZE, SIZE)[0][colorimetry.GROUND_TRUTH][ys, xs] @ y_row
    expected_diff = predicted.mean() - rho_l.mean()
    assert abs(diff - expected_diff) < 5 * se + 0.002 * abs(diff), (diff, expected_diff, se)
    assert abs(lum_bare.mean() - rho_l.mean()) < 5 * lum_bare.std(ddof=1) / np.sqrt(len(ys)) + 0.002 * rho_l.mean()


def test_a_coated_model_without_its_spectrum_takes_blenders_base_colour(exported):
    sc = exported["model_only"]
    b = sc["objects"][0]["bsdf"]
    assert b["type"] == "coated_diffuse" and b["int_ior"] == pytest.approx(1.5046)  # the annotation's IOR
    assert b["reflectance"] == exported["coat"]["objects"][0]["bsdf"]["reflectance"]  # Blender's base colour
    msg = _warnings(sc)[("coat_ball", "material[coat_red].spectral_bench.reflectance")]
    assert "Model Coated Diffuse without a reflectance spectrum" in msg and "not the default 0.5" in msg
    assert "the Model wins" not in msg
