"""The pbrt writer's exports rendered by pbrt-v4 and judged by closed forms (shared by
tests/exporters/test_pbrt_renders.py and benchmarks/pbrt_writer_checks.py):

- ``env_plate``: a white Lambertian plate under a uniform D65 environment: rho L(l) everywhere on
  it (the Lambert probe, batch/verdict/probes/lambert.py);
- ``area_plate``: the same plate under a square D65 area light: rho / pi E per pixel, E from
  Lambert's polygon formula averaged over the pixel's footprint (stats.region_mean_test);
- ``ggx_plate``: a canonical GGX copper scene (area lights only): the GGX probe with pbrt's
  height-correlated shadowing-masking and, for comparison, the IR's separable one.

pbrt is found as the backend finds it: the env file scripts/build_pbrt.sh writes (.pbrt/env.json,
or SPECTRAL_BENCH_PBRT_ENV), else ``pbrt`` on PATH. The spectral film is read as the backend reads
it: buckets as box bands, each divided by its expected occupancy 1 - (1 - 4 / N)^n (an empty bucket
reads 0; n samples of 4 wavelengths each, N buckets). Passes use seeds 0, 1, ...; pbrt's pixels are
bit-identical for a seed whatever the thread count (measured at 1, 2 and 7 threads), so a check has
one outcome per build."""
import json
import os
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

from conftest import ROOT
from spectral_bench.batch import spectral_exr
from spectral_bench.batch.verdict import raycast, stats
from spectral_bench.batch.verdict.probes import common, ggx, lambert
from spectral_bench.exporters import ir, pbrt_writer, spectra

WAVELENGTHS_PER_SAMPLE = 4  # pbrt-v4 NSpectrumSamples
D65 = {"type": "named", "name": "cie_d65", "scale": 1.0}
WHITE = {"type": "constant", "value": 0.9}
SIZE, SPP, PASSES = 64, 128, 4  # the checks' own scenes


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
MISSING = ("no pbrt-v4: no .pbrt/env.json (scripts/build_pbrt.sh SRC builds pbrt from its source) and no pbrt on PATH: "
           "the writer's exports are not rendered")


def render(scene, folder, passes=PASSES, spp=SPP, planted=None, threads=2):
    """(names, mean RGB image, its per-pixel standard error, pbrt's wall seconds) of ``passes`` pbrt
    runs of the export; ``planted``: the writer's test hook's factor on every light."""
    env = {k: v for k, v in os.environ.items() if k != pbrt_writer.TEST_HOOK}
    saved = os.environ.pop(pbrt_writer.TEST_HOOK, None)
    if planted:
        os.environ[pbrt_writer.TEST_HOOK] = repr(planted)
    try:
        path = pbrt_writer.write(scene, folder)
    finally:
        os.environ.pop(pbrt_writer.TEST_HOOK, None)
        if saved is not None:
            os.environ[pbrt_writer.TEST_HOOK] = saved
    images, wall = [], 0.0
    for seed in range(passes):
        out = Path(folder) / f"pass{seed}.exr"
        t0 = time.perf_counter()
        proc = subprocess.run([str(PBRT), "--seed", str(seed), "--spp", str(spp), "--nthreads", str(threads),
                               "--outfile", str(out), str(path)], capture_output=True, text=True, timeout=1800,
                              cwd=folder, env=env)
        wall += time.perf_counter() - t0
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        image = spectral_exr.read(out)
        centres = np.asarray(image.wavelengths_nm, dtype=np.float64)
        assert centres.size == pbrt_writer.FILM["nbuckets"]
        width = (centres[-1] - centres[0]) / (centres.size - 1)
        image.stokes[0] = image.stokes[0] / (1.0 - (1.0 - WAVELENGTHS_PER_SAMPLE / centres.size) ** spp)
        names, rgb = spectral_exr.to_rgb(image, bands="box", band_width_nm=width)
        images.append(rgb)
    stack = np.stack(images)
    return names, stack.mean(axis=0), stack.std(axis=0, ddof=1) / np.sqrt(passes), wall


def _camera(eye, target, fov=40.0):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    back = (eye - target) / np.linalg.norm(eye - target)
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, np.cross(back, right), back, eye
    return {"name": "cam", "fov": fov, "fov_axis": "x", "to_world": m.tolist()}


def _scene(name, objects, environment=None, size=SIZE, spp=SPP):
    sc = {"format": ir.FORMAT, "version": ir.VERSION, "name": name, "case": "custom",
          "render": {"width": size, "height": size, "spp": spp, "max_depth": 64, "filter": "box"},
          "camera": _camera([0.0, -3.0, 3.0], [0.0, 0.0, 0.0]), "environment": environment, "objects": objects}
    return ir.with_derived_needs(sc)


def _plate():
    return {"name": "plate", "shape": {"type": "rectangle", "to_world": ir.identity()},
            "bsdf": {"type": "diffuse", "reflectance": WHITE}, "emitter": None}


def box_rgb(spec):
    """Linear sRGB of a spectrum as the film's buckets hold it: its mean over each bucket, read as
    box bands (what ``render`` does to an image). The exact CMF integral differs from it by up to
    1.1e-4 (blue, for D65 and D50): visible at the area check's noise, and no part of the writer."""
    edges = np.linspace(pbrt_writer.FILM["lambdamin"], pbrt_writer.FILM["lambdamax"], pbrt_writer.FILM["nbuckets"] + 1)
    fine = np.arange(edges[0], edges[-1], 0.01) + 0.005
    values = spectra.evaluate(spec, fine)
    means = np.array([values[(fine >= a) & (fine < b)].mean() for a, b in zip(edges[:-1], edges[1:])])
    centres = tuple((edges[:-1] + edges[1:]) / 2)
    return means @ spectral_exr.rgb_weights(centres, "cie1931", "box", float(edges[1] - edges[0]))


def polygon_factor(points, normal, corners):
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


def env_plate(folder, planted=None):
    """The white plate under D65: {records (the Lambert probe's judged ones), measured, expected
    (linear sRGB over the patch's pixels), rel_se (the patch mean's relative standard error, G),
    seconds}."""
    sc = _scene("plate_d65_env", [_plate()], {"type": "uniform", "radiance": D65})
    names, image, stderr, wall = render(sc, Path(folder), planted=planted)
    records = [r for r in lambert.patches(common.Measurement(sc, names, image, stderr, None, PASSES))
               if r["pass"] is not None]
    patch = next(r for r in records if "plate" in r["name"])
    mask = raycast.pixels_inside(sc["camera"], SIZE, SIZE, sc["objects"], 0)
    expected = np.asarray(patch["expected"])
    rel_se = float(np.sqrt((stderr[mask][:, 1] ** 2).sum()) / mask.sum() / expected[1])
    return {"records": records, "measured": image[mask].mean(axis=0), "expected": expected, "rel_se": rel_se,
            "seconds": wall}


def area_plate(folder, planted=None):
    """The white plate under a square D65 light of radiance 5 (at 560 nm) 1.5 above it, facing
    down (no environment, nothing else to reflect light): {result (stats.region_mean_test of the
    relative residuals per channel), resolved (the relative shift it resolves), variation (the
    irradiance's max / min over the judged pixels), seconds}."""
    s = 0.4
    light = {"name": "lamp", "shape": {"type": "rectangle", "to_world": [[s, 0, 0, 0], [0, -s, 0, 0], [0, 0, -1, 1.5],
                                                                          [0, 0, 0, 1]]},
             "bsdf": None, "emitter": {"type": "area", "radiance": dict(D65, scale=5.0)}}
    sc = _scene("plate_d65_area", [_plate(), light])
    cam = sc["camera"]
    origin, dirs = raycast.camera_rays(cam, SIZE, SIZE, "corners")
    who, _ = raycast.nearest(sc["objects"], origin, dirs)
    on = who == 0
    mask = on[:-1, :-1] & on[1:, :-1] & on[:-1, 1:] & on[1:, 1:]
    m = np.asarray(light["shape"]["to_world"], dtype=np.float64)
    corners = np.array([m @ [x, y, 0.0, 1.0] for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))])[:, :3]
    rows, cols = np.nonzero(mask)
    factor = np.zeros(len(rows))
    for (ox, oy), weight in raycast.footprint_offsets(4):
        o, d = raycast.camera_rays_at(cam, SIZE, SIZE, cols + ox, rows + oy)
        t = raycast.hit_plane(sc["objects"][0]["shape"], o, d)
        factor += weight * polygon_factor(o + t[:, None] * d, np.array([0.0, 0.0, 1.0]), corners)
    expected = (WHITE["value"] / np.pi) * factor[:, None] * box_rgb(light["emitter"]["radiance"])[None, :]
    _names, image, _stderr, wall = render(sc, Path(folder), planted=planted)
    result = stats.region_mean_test((image[rows, cols] - expected) / expected, tests=3)
    return {"result": result, "resolved": stats.z_critical(result["threshold"]) * max(result["se"]),
            "pixels": int(mask.sum()), "variation": float(expected[:, 1].max() / expected[:, 1].min()), "seconds": wall}


def ggx_plate(scene, folder, planted=None, passes=PASSES, forms=("height-correlated", "separable")):
    """A GGX scene of rough conductor plates and area lights (ggx.plates applies) at its own
    settings: {form: the GGX probe's records}, and pbrt's seconds."""
    names, image, stderr, wall = render(scene, Path(folder), passes=passes, spp=scene["render"]["spp"], planted=planted)
    m = common.Measurement(scene, names, image, stderr, None, passes)
    return {form: ggx.plates(m, form=form) for form in forms}, wall
