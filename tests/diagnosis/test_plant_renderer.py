"""The planting renderer (tests/plant_renderer.py) plants what it says: every scene plant changes
the exported Mitsuba scene it is given (a plant that silently matched nothing would make
benchmarks/bench_diagnosis.py count a correct render as a planted one), and every output plant
changes an image. No rendering: the exported golden scenes and a synthetic image."""
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parents[1]  # tests/: plant_renderer.py
sys.path.insert(0, str(HERE))
import plant_renderer  # noqa: E402

GOLDEN = HERE.parent / "golden" / "mitsuba"
SCENE_PLANTS = [
    ("ggx_copper_50", "alpha", "0.22", 'name="alpha" value="0.22"'),
    ("ggx_copper_50", "beckmann", "yes", 'value="beckmann"'),
    ("ggx_copper_50", "no_k", "yes", '<spectrum name="k" value="0.0" />'),
    ("ggx_copper_50", "zoom", "1.05", 'name="fov" value="32.'),
    ("ggx_copper_50", "shift", "1,0", 'principal_point_offset_x" value="0.001953125"'),
    ("polarizing_plane_0", "ior", "1.6", 'name="int_ior" value="1.6"'),
    ("dispersion_prism", "dispersion", "none", 'name="C3" value="0.0"'),
    ("iridescent_sphere_smooth", "film", "0", 'name="film_thickness" value="0.0"'),
    ("fluorescent_sphere_lone", "fluorescence", "dropped", '<bsdf type="diffuse">'),
]


@pytest.mark.parametrize("scene, plant, value, expected", SCENE_PLANTS)
def test_scene_plant_changes_the_scene(tmp_path, scene, plant, value, expected):
    src = GOLDEN / scene / "scene.xml"
    xml = tmp_path / "scene.xml"
    xml.write_text(src.read_text())
    out = plant_renderer.plant_scene(xml, {plant: value})
    text = out.read_text()
    assert out != xml and text != src.read_text() and expected in text, text[:2000]


def test_dispersion_plant_keeps_n_at_the_d_line(tmp_path):
    """One-term Sellmeier B1 = n_d^2 - 1 with N-BK7's n_d = 1.5168 (SCHOTT)."""
    xml = tmp_path / "scene.xml"
    xml.write_text((GOLDEN / "dispersion_prism" / "scene.xml").read_text())
    text = plant_renderer.plant_scene(xml, {"dispersion": "none"}).read_text()
    b1 = float(text.split('name="B1" value="')[1].split('"')[0])
    assert abs((1 + b1) ** 0.5 - 1.5168) < 1e-4 and 'name="B2" value="0.0"' in text


def test_a_scene_plant_that_matches_nothing_is_refused(tmp_path):
    xml = tmp_path / "scene.xml"
    xml.write_text((GOLDEN / "polarizing_plane_0" / "scene.xml").read_text())
    with pytest.raises(SystemExit, match="no thin film"):
        plant_renderer.plant_scene(xml, {"film": "600"})


OUTPUT_PLANTS = [("scale", "1.03"), ("channel_scale", "1.03,1,0.97"), ("offset", "0.01"), ("srgb", "applied"),
                 ("srgb", "missing"), ("gamma", "2.2"), ("space", "sRGB>ACEScg"), ("bgr", "yes"), ("flip", "y"),
                 ("flip", "x"), ("transpose", "yes"), ("clamp", "0.5"), ("emitter", "pi"), ("stokes_rotate", "90"),
                 ("s3", "flip"), ("depolarise", "yes"), ("stain", "0.3")]


@pytest.mark.parametrize("plant, value", OUTPUT_PLANTS)
def test_output_plant_changes_the_image(plant, value):
    rng = np.random.default_rng(0)
    names = list("RGB") + [f"S{k}.{c}" for k in range(4) for c in "RGB"]
    img = rng.uniform(0.1, 0.9, (16, 16, len(names)))
    out = plant_renderer.plant_output(names, img, [(plant, value)])
    assert out.shape == img.shape and not np.allclose(out, img)


def test_the_render_cache_gives_back_the_same_arrays_and_keys_on_everything_a_render_reads(tmp_path, monkeypatch):
    """tests/render_cache.py (the planted renderers' shared base render): off unless the variable
    is set; on, a second call with the same scene folder and parts reads the first call's result
    back as the same arrays (float64 whether stored as float32 or not), and a change of the
    scene file, of a file beside it or of a part is another key. No rendering: a counting stand-in."""
    import render_cache
    scene = tmp_path / "export" / "scene.xml"
    (scene.parent / "spectra").mkdir(parents=True)
    scene.write_text("<scene/>")
    (scene.parent / "spectra" / "a.spd").write_text("400 1\n700 1\n")
    (scene.parent / ".render_size.json").write_text("{}")  # the runner's hidden files are not the scene
    calls = []
    rng = np.random.default_rng(3)
    exact = rng.random((4, 5, 3)).astype(np.float32).astype(np.float64)  # a float32 film's values
    inexact = rng.random((4, 5, 3))

    def render():
        calls.append(1)
        return ["R", "G", "B"], (exact.copy(), inexact.copy())

    monkeypatch.delenv(render_cache.ENV, raising=False)
    render_cache.memo(render, scene, "rgb", 4, 0)
    render_cache.memo(render, scene, "rgb", 4, 0)
    assert len(calls) == 2  # off: every call renders
    monkeypatch.setenv(render_cache.ENV, str(tmp_path / "cache"))
    first = render_cache.memo(render, scene, "rgb", 4, 0)
    (scene.parent / ".render_size.json").write_text('{"w": 1}')
    again = render_cache.memo(render, scene, "rgb", 4, 0)
    assert len(calls) == 3 and again[0] == ["R", "G", "B"]
    for a, b in zip(first[1], again[1]):
        assert b.dtype == np.float64 and np.array_equal(a, b)
    render_cache.memo(render, scene, "rgb", 4, 1)  # another seed
    assert len(calls) == 4
    (scene.parent / "spectra" / "a.spd").write_text("400 1\n700 2\n")  # a spectrum the scene reads
    render_cache.memo(render, scene, "rgb", 4, 0)
    assert len(calls) == 5
    scene.write_text("<scene></scene>")
    render_cache.memo(render, scene, "rgb", 4, 0)
    assert len(calls) == 6
