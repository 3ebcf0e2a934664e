"""The pbrt writer's exports rendered by pbrt-v4 itself, judged by closed forms: the absolute
radiance of a white Lambertian plate under a uniform D65 environment (the Lambert probe,
batch/verdict/probes/lambert.py) and under a D65 area light (Lambert's polygon formula for the
irradiance), and a GGX copper plate under an area light (the GGX probe with pbrt's
height-correlated shadowing). Each test shows its power: what it could detect is well below the
2 % of the writer's planted light error (pbrt_writer.TEST_HOOK), and that planted error fails it.

pbrt is found as the backend finds it: the env file scripts/build_pbrt.sh writes (.pbrt/env.json,
or SPECTRAL_BENCH_PBRT_ENV), else ``pbrt`` on PATH; without one these tests are skipped, saying so.
The spectral film is read here as the backend reads it: buckets as box bands, each divided by its
expected occupancy 1 - (1 - 4 / N)^n (an empty bucket reads 0; n samples of 4 wavelengths)."""
import copy
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT
from spectral_bench.batch import spectral_exr
from spectral_bench.batch.verdict import raycast, stats
from spectral_bench.batch.verdict.probes import common, ggx, lambert
from spectral_bench.exporters import ir, pbrt_writer, spectra

WAVELENGTHS_PER_SAMPLE = 4  # pbrt-v4 NSpectrumSamples
PLANTED = 1.02  # the writer's planted error: every light 2 % brighter


def find_pbrt():
    env_file = Path(os.environ.get("SPECTRAL_BENCH_PBRT_ENV") or ROOT / ".pbrt" / "env.json")
    try:
        exe = Path(json.loads(env_file.read_text())["pbrt"])
        if exe.is_file() and os.access(exe, os.X_OK):
            return exe
    except (OSError, ValueError, KeyError, TypeError):
        pass
    found = shutil.which("pbrt")
    return Path(found) if found else None


PBRT = find_pbrt()
pytestmark = [pytest.mark.slow, pytest.mark.skipif(PBRT is None, reason=(
    "no pbrt-v4: no .pbrt/env.json (scripts/build_pbrt.sh SRC builds pbrt from its source) and no pbrt on PATH: "
    "the writer's exports are not rendered"))]


def render(scene, folder, passes=4, spp=128, planted=None):
    """(names, mean RGB image, its per-pixel standard error) of ``passes`` pbrt runs of the export,
    seeds 0..passes-1."""
    env = dict(os.environ)
    env.pop(pbrt_writer.TEST_HOOK, None)
    if planted:
        os.environ[pbrt_writer.TEST_HOOK] = repr(planted)
    try:
        path = pbrt_writer.write(scene, folder)
    finally:
        os.environ.pop(pbrt_writer.TEST_HOOK, None)
    images = []
    for seed in range(passes):
        out = folder / f"pass{seed}.exr"
        proc = subprocess.run([str(PBRT), "--seed", str(seed), "--spp", str(spp), "--nthreads", "2", "--outfile", str(out),
                               str(path)], capture_output=True, text=True, timeout=600, cwd=folder, env=env)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        image = spectral_exr.read(out)
        centres = np.asarray(image.wavelengths_nm, dtype=np.float64)
        assert centres.size == pbrt_writer.FILM["nbuckets"]
        width = (centres[-1] - centres[0]) / (centres.size - 1)
        image.stokes[0] = image.stokes[0] / (1.0 - (1.0 - WAVELENGTHS_PER_SAMPLE / centres.size) ** spp)
        names, rgb = spectral_exr.to_rgb(image, bands="box", band_width_nm=width)
        images.append(rgb)
    stack = np.stack(images)
    return names, stack.mean(axis=0), stack.std(axis=0, ddof=1) / np.sqrt(passes)


def _camera(eye, target, fov=40.0):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, back, eye
    return {"name": "cam", "fov": fov, "fov_axis": "x", "to_world": m.tolist()}


D65 = {"type": "named", "name": "cie_d65", "scale": 1.0}
WHITE = {"type": "constant", "value": 0.9}


def _scene(name, objects, environment=None, size=64, spp=128):
    sc = {"format": ir.FORMAT, "version": ir.VERSION, "name": name, "case": "custom",
          "render": {"width": size, "height": size, "spp": spp, "max_depth": 64, "filter": "box"},
          "camera": _camera([0.0, -3.0, 3.0], [0.0, 0.0, 0.0]), "environment": environment, "objects": objects}
    return ir.with_derived_needs(sc)


def _plate():
    return {"name": "plate", "shape": {"type": "rectangle", "to_world": ir.identity()},
            "bsdf": {"type": "diffuse", "reflectance": WHITE}, "emitter": None}


def _lambert_records(scene, names, image, stderr, passes):
    return lambert.patches(common.Measurement(scene, names, image, stderr, None, passes))


def test_white_plate_under_a_d65_environment_has_the_lambert_probes_radiance(tmp_path):
    """rho L(l) everywhere on the plate (nothing above it): the Lambert probe's per-patch test on
    the render's own noise. D65 is not flat, so pbrt's division by its photometric value shows
    unless the writer's scale undoes it; the planted 2 % fails."""
    sc = _scene("plate_d65_env", [_plate()], {"type": "uniform", "radiance": D65})
    names, image, stderr = render(sc, tmp_path / "ok")
    records = _lambert_records(sc, names, image, stderr, 4)
    judged = [r for r in records if r["pass"] is not None]
    assert judged and all(r["pass"] for r in judged), records
    patch = next(r for r in judged if "plate" in r["name"])
    expected = np.asarray(patch["expected"])
    # power: the mean over the patch's pixels has a relative standard error far below the planted 2 %
    mask = raycast.pixels_inside(sc["camera"], 64, 64, sc["objects"], 0)
    rel_se = float(np.sqrt((stderr[mask][:, 1] ** 2).sum()) / mask.sum() / expected[1])
    assert 6 * rel_se < PLANTED - 1, rel_se
    measured = image[mask].mean(axis=0)
    np.testing.assert_allclose(measured, expected, rtol=6 * rel_se + 1e-4)
    names, image, stderr = render(sc, tmp_path / "planted", planted=PLANTED)
    planted = [r for r in _lambert_records(sc, names, image, stderr, 4) if r["pass"] is not None]
    assert not all(r["pass"] for r in planted), planted


def box_rgb(spec):
    """Linear sRGB of a spectrum as the film's buckets hold it: its mean over each 10 nm bucket, read
    as box bands (what the reading above does to a render). The exact CMF integral differs from it
    by up to 1.1e-4 (blue, for D65 and D50): visible at this test's noise, and no part of the writer."""
    edges = np.linspace(pbrt_writer.FILM["lambdamin"], pbrt_writer.FILM["lambdamax"], pbrt_writer.FILM["nbuckets"] + 1)
    fine = np.arange(edges[0], edges[-1], 0.01) + 0.005
    values = spectra.evaluate(spec, fine)
    means = np.array([values[(fine >= a) & (fine < b)].mean() for a, b in zip(edges[:-1], edges[1:])])
    centres = tuple((edges[:-1] + edges[1:]) / 2)
    return means @ spectral_exr.rgb_weights(centres, "cie1931", "box", float(edges[1] - edges[0]))


def _polygon_factor(points, normal, corners):
    """Lambert's formula: irradiance from a uniform Lambertian polygon of radiance 1 at ``points``
    (P x 3) with unit ``normal``: 1/2 sum over edges of the angle the edge subtends times the normal's
    component along the edge's plane normal (Lambert 1760; Arvo 1995, "Applications of Irradiance
    Tensors", eq. 1)."""
    r = corners[None, :, :] - points[:, None, :]
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    total = np.zeros(len(points))
    for i in range(len(corners)):
        a, b = r[:, i], r[:, (i + 1) % len(corners)]
        cross = np.cross(a, b)
        gamma = np.arctan2(np.linalg.norm(cross, axis=-1), np.sum(a * b, axis=-1))
        total += gamma * (cross @ normal) / np.linalg.norm(cross, axis=-1)
    return np.abs(total) / 2.0


def test_white_plate_under_a_d65_area_light_has_lamberts_irradiance(tmp_path):
    """A square D65 light of radiance 5 (at 560 nm) facing down 1.5 above the plate: every plate
    pixel's radiance is rho / pi E with E from Lambert's polygon formula (no environment, nothing
    else to reflect light), averaged over the pixel's footprint; judged per channel on the pixels'
    own spread (stats.region_mean_test); the planted 2 % fails."""
    s = 0.4
    light = {"name": "lamp", "shape": {"type": "rectangle", "to_world": [[s, 0, 0, 0], [0, -s, 0, 0], [0, 0, -1, 1.5],
                                                                          [0, 0, 0, 1]]},
             "bsdf": None, "emitter": {"type": "area", "radiance": dict(D65, scale=5.0)}}
    sc = _scene("plate_d65_area", [_plate(), light])
    cam, w, h = sc["camera"], 64, 64
    origin, dirs = raycast.camera_rays(cam, w, h, "corners")
    who, _ = raycast.nearest(sc["objects"], origin, dirs)
    on = who == 0
    mask = on[:-1, :-1] & on[1:, :-1] & on[:-1, 1:] & on[1:, 1:]
    assert mask.sum() > 500
    m = np.asarray(light["shape"]["to_world"], dtype=np.float64)
    corners = np.array([m @ [x, y, 0.0, 1.0] for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))])[:, :3]
    rows, cols = np.nonzero(mask)
    factor = np.zeros(len(rows))
    for (ox, oy), weight in raycast.footprint_offsets(4):
        o, d = raycast.camera_rays_at(cam, w, h, cols + ox, rows + oy)
        t = raycast.hit_plane(sc["objects"][0]["shape"], o, d)
        factor += weight * _polygon_factor(o + t[:, None] * d, np.array([0.0, 0.0, 1.0]), corners)
    expected = (WHITE["value"] / np.pi) * factor[:, None] * box_rgb(light["emitter"]["radiance"])[None, :]
    assert expected[:, 1].max() / expected[:, 1].min() > 1.5  # the irradiance varies over the plate

    def judge(image):
        return stats.region_mean_test((image[rows, cols] - expected) / expected, tests=3)

    names, image, _stderr = render(sc, tmp_path / "ok")
    result = judge(image)
    assert result["pass"], result
    # power: the relative shift the test resolves (its threshold times the relative standard error)
    resolved = stats.z_critical(result["threshold"]) * max(result["se"])
    assert resolved < (PLANTED - 1) / 3, resolved
    names, image, _stderr = render(sc, tmp_path / "planted", planted=PLANTED)
    assert not judge(image)["pass"]


def test_ggx_copper_plate_under_an_area_light_matches_the_ggx_probe_with_pbrts_shadowing(golden, tmp_path):
    """ggx_copper_50_isolated at 64 x 64: the GGX probe's quadrature of the microfacet BRDF with the
    IR's eta, k and alpha and pbrt's height-correlated shadowing-masking judges the copper plate's
    pixels (blocks and the luminance scale) on the render's own noise; alpha is alpha
    (remaproughness false), the light's radiance absolute. The planted 2 % fails its scale test."""
    sc = copy.deepcopy(golden["ggx_copper_50_isolated"])
    sc["render"].update(width=64, height=64, spp=128)
    form = "height-correlated"

    def probe(image, stderr):
        return ggx.plates(common.Measurement(sc, ["R", "G", "B"], image, stderr, None, 4), form=form)

    names, image, stderr = render(sc, tmp_path / "ok")
    records = probe(image, stderr)
    assert len(records) == 2 and all(r["pass"] for r in records), records
    scale = next(r for r in records if r["name"].endswith("luminance scale"))
    resolved = stats.z_critical(scale["stat"]["threshold"]) * scale["stat"]["se"][0]
    assert resolved < (PLANTED - 1) / 2, resolved
    names, image, stderr = render(sc, tmp_path / "planted", planted=PLANTED)
    planted = probe(image, stderr)
    assert not next(r for r in planted if r["name"].endswith("luminance scale"))["pass"], planted
