"""Stability case: parameter strips where implementations typically break, each value rendered as a
small image and checked for NaN, Inf, negative values, energy gain in a white furnace, and jumps
at the limits. Every check is a test against the render's own noise (its per-pixel standard error
from independent passes, and the spread of a region's pixels), with the tests of one strip sharing
the false-alarm rate stats.ALPHA (Sidak): no tolerance is asserted.

A strip is data (STRIPS): a name, the base scene (a canonical scene by name, or a generated
furnace), the parameter values, a function that sets the value on a copy of the base, and the
checks that apply:
- ggx_grazing: the copper plate of ggx_copper_80 turned 80..89 degrees (grazing view and light).
- roughness_furnace: a rough GGX dielectric sphere (n = 1.5) alone in a uniform environment of
  radiance 1, alpha 0.001..1: a non-absorbing object can only lose energy (single-scattering
  microfacets lose some at high alpha), so the sphere may not be brighter than the environment
  beyond its noise; alpha -> 0 must approach the smooth sphere.
- ior_furnace: a smooth dielectric sphere in the same furnace, n = 1.0001..3: lossless, so exactly
  the environment for every n (the limit n -> 1 is an invisible sphere).
- polarizer_malus: the Brewster plane seen through the polariser at 0..90 degrees: the Fresnel
  probe (Malus' law) at every angle.
- film_thickness_furnace, film_ior_furnace: a rough thin-film conductor sphere in the furnace, film
  thickness 0..2000 nm and film index 1.0001..2.8: a passive film can only lose energy; thickness
  -> 0 and film index -> the exterior's (1) must meet the bare conductor (the same sphere without a
  film, Mitsuba's own roughconductor) within noise, without a jump.
"""
import copy
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...exporters import ir
from .. import exr
from ..verdict import probes, raycast, stats


def _furnace_sphere(bsdf):
    cam = np.eye(4)
    cam[:3, 3] = [0, -4, 0]
    cam[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # look along +y, z up
    return {"format": ir.FORMAT, "version": ir.VERSION, "name": "furnace", "case": "stability", "needs": [],
            "render": {"spp": 64, "width": 32, "height": 32, "max_depth": 64, "filter": "box", "integrator": "path"},
            "camera": {"name": "furnace_camera", "to_world": cam.tolist(), "fov": 35.0, "fov_axis": "x"},
            "environment": {"type": "uniform", "radiance": {"type": "constant", "value": 1.0}},
            "objects": [{"name": "sphere", "shape": {"type": "sphere", "center": [0, 0, 0], "radius": 1.0},
                         "bsdf": bsdf, "emitter": None}]}


def _turn_plate(sc, angle):
    a = np.radians(angle)
    plate = next(o for o in sc["objects"] if o["name"].startswith("copper_plate"))
    plate["shape"]["to_world"] = [[1, 0, 0, 0], [0, np.cos(a), -np.sin(a), 0], [0, np.sin(a), np.cos(a), 0], [0, 0, 0, 1]]


def _set_alpha(sc, alpha):
    sc["objects"][0]["bsdf"]["roughness"]["alpha"] = alpha


def _set_ior(sc, n):
    sc["objects"][0]["bsdf"]["int_ior"] = n


def _set_polariser(sc, angle):
    sc["camera"]["polarizer"]["angle"] = float(angle)


def _set_film(field):
    def apply(sc, value):
        sc["objects"][0]["bsdf"]["thin_film"][field] = value
    return apply


def _without(key):
    """The limit scene: the strip's first scene without its bsdf's ``key`` (roughness, thin film)."""
    def limit(sc):
        out = copy.deepcopy(sc)
        out["objects"][0]["bsdf"].pop(key, None)
        return out
    return limit


@dataclass
class Strip:
    name: str
    base: object            # a canonical scene's name, or an IR scene
    values: tuple
    apply: Callable         # (scene copy, value) -> None
    checks: tuple           # of "finite", "negative", "gain", "lossless", "probes"
    size: int = 32
    limit: Callable = None  # (the first value's scene) -> the scene it must meet within noise


ROUGH_GLASS = _furnace_sphere({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0,
                               "roughness": {"distribution": "ggx", "alpha": 0.1}})
SMOOTH_GLASS = _furnace_sphere({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0})
# a rough conductor (eta 1.9, k 1.5: the thesis' iridescence base) under a 550 nm film of index 1.33
FILMED = _furnace_sphere({"type": "conductor", "eta": {"type": "constant", "value": 1.9},
                          "k": {"type": "constant", "value": 1.5}, "roughness": {"distribution": "ggx", "alpha": 0.1},
                          "thin_film": {"ior": 1.33, "thickness": 550.0}})

STRIPS = [
    Strip("ggx_grazing", "ggx_copper_80", tuple(range(80, 90)), _turn_plate, ("finite",), 64),
    Strip("roughness_furnace", ROUGH_GLASS, (0.001, 0.01, 0.05, 0.1, 0.2, 0.4, 0.7, 1.0), _set_alpha,
          ("finite", "negative", "gain"), limit=_without("roughness")),
    Strip("ior_furnace", SMOOTH_GLASS, (1.0001, 1.01, 1.1, 1.33, 1.5, 2.0, 2.5, 3.0), _set_ior,
          ("finite", "negative", "gain", "lossless")),
    Strip("polarizer_malus", "polarizing_plane_0", (0, 15, 30, 45, 60, 75, 90), _set_polariser, ("finite", "probes"), 64),
    Strip("film_thickness_furnace", FILMED, (0.0, 1.0, 10.0, 50.0, 150.0, 300.0, 550.0, 1000.0, 1500.0, 2000.0),
          _set_film("thickness"), ("finite", "negative", "gain"), limit=_without("thin_film")),
    Strip("film_ior_furnace", FILMED, (1.0001, 1.001, 1.01, 1.1, 1.33, 1.5, 2.0, 2.8), _set_film("ior"),
          ("finite", "negative", "gain"), limit=_without("thin_film")),
]


def definitions(golden, strips=None):
    """{strip name: (Strip, [(value, IR scene)])} for the strips whose base scene is available."""
    out = {}
    for strip in strips or STRIPS:
        base = golden.get(strip.base) if isinstance(strip.base, str) else strip.base
        if base is None:
            continue
        scenes = []
        for value in strip.values:
            sc = copy.deepcopy(base)
            strip.apply(sc, value)
            sc["render"]["width"] = sc["render"]["height"] = strip.size
            sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
            scenes.append((value, sc))
        out[strip.name] = (strip, scenes)
    return out


def sphere_region(scene, w, h):
    """Whole pixels on the furnace sphere, and whole pixels of the environment alone."""
    objs = scene["objects"]
    origin, dirs = raycast.camera_rays(scene["camera"], w, h, "corners")
    who, _ = raycast.nearest(objs, origin, dirs)

    def whole(v):
        return v[:-1, :-1] & v[1:, :-1] & v[:-1, 1:] & v[1:, 1:]
    return whole(who == 0), whole(who == -1)


def _ratio(img, se, sphere, env):
    """Sphere mean over environment mean per channel, with its standard error (the region's pixel
    spread; both regions' noise)."""
    s_px, e_px = img[sphere][:, :3].astype(np.float64), img[env][:, :3].astype(np.float64)
    ms, me = s_px.mean(axis=0), e_px.mean(axis=0)
    ss, se_e = s_px.std(axis=0, ddof=1) / np.sqrt(len(s_px)), e_px.std(axis=0, ddof=1) / np.sqrt(len(e_px))
    r = ms / me
    return r, r * np.sqrt((ss / ms) ** 2 + (se_e / me) ** 2), min(len(s_px), len(e_px)) - 1


def check(strip, value, scene, names, img, stderr=None, tests=1):
    """Problems of one render of a strip ([] when stable) and whether anything could be judged.
    ``tests``: how many tests the strip makes in all (Sidak)."""
    checks = strip.checks if isinstance(strip, Strip) else next(s.checks for s in STRIPS if s.name == strip)
    threshold = stats.sidak_threshold(stats.ALPHA, tests)
    rgb = img[..., :3]
    problems, judged = [], False
    if "finite" in checks:
        judged = True
        nan, inf = int(np.isnan(rgb).sum()), int(np.isinf(rgb).sum())
        problems += [f"{nan} NaN"] * bool(nan) + [f"{inf} Inf"] * bool(inf)
    if "negative" in checks and stderr is not None:
        # a flat spectrum's sRGB has no negative component: a pixel below zero beyond its own
        # noise (one-sided, Sidak over the image's pixels and channels) is a bug
        z = -rgb / np.maximum(stderr[..., :3], 1e-300)
        p = stats.one_sided_p(z, 1)
        bad = int(np.sum(p < stats.sidak_threshold(stats.ALPHA, rgb.size)))
        judged = True
        if bad:
            problems.append(f"{bad} negative values beyond their noise")
    if {"gain", "lossless"} & set(checks):
        sphere, env = sphere_region(scene, img.shape[1], img.shape[0])
        if sphere.sum() >= 4 and env.sum() >= 4:
            judged = True
            r, r_se, dof = _ratio(img, stderr, sphere, env)
            if "gain" in checks:
                p = stats.one_sided_p((r - 1.0) / r_se, dof)
                if np.min(p) < threshold:
                    problems.append(f"energy gain: the sphere is {float(r.max()):.4f}x the environment "
                                    f"(+{float(((r - 1) / r_se).max()):.1f} standard errors)")
            if "lossless" in checks:
                p = stats.two_sided_p((r - 1.0) / r_se, dof)
                if np.min(p) < threshold:
                    problems.append(f"a lossless sphere must equal the environment: {float(r.mean()):.4f}x "
                                    f"({float(np.abs((r - 1) / r_se).max()):.1f} standard errors)")
    if "probes" in checks:
        p = next((p for p in probes.evaluate(scene, names, img, stderr=stderr) if p["name"].startswith("brewster")), None)
        if p is not None and p["pass"] is not None:
            judged = True
            if p["pass"] is False:
                problems.append(f"Fresnel/Malus probe failed: z = {p['z']:.1f}")
    return problems, judged


def strip_image(path, images):
    """The strip's renders side by side (sRGB previews), labelled by order."""
    from ..report.previews import srgb_encode
    from PIL import Image
    h = max(i.shape[0] for _, i in images)
    tiles = [np.pad(srgb_encode(i[..., :3]), ((0, h - i.shape[0]), (0, 2), (0, 0))) for _, i in images]
    Image.fromarray((np.concatenate(tiles, axis=1) * 255 + 0.5).astype(np.uint8)).save(path)


def _render(backend, sc, folder, passes, seed, timeout):
    mode, why = backend.mode_for(sc)
    if mode is None:
        return mode, why, None
    path = backend.export(sc, folder / "scene")
    backend.render(path, mode, sc["render"]["spp"], folder / "render.exr", passes=passes, seed=seed, timeout=timeout)
    return mode, None, exr.read_image_and_stderr(folder / "render.exr")


def run(backend, golden, out_dir, passes=4, seed=0, timeout=600, only=None):
    """Render every strip (or those named in ``only``) with ``backend`` into out_dir/<backend>/;
    returns the result rows and writes the strip images out_dir/<backend>/<strip>.png."""
    out_dir = out_dir / backend.name
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, (strip, scenes) in definitions(golden).items():
        if only is not None and name not in only:
            continue
        images, strip_rows = [], []
        tests = len(scenes) * 3 + (3 if strip.limit else 0)
        for value, sc in scenes:
            row = {"sweep": name, "value": value, "backend": backend.name, "mode": None, "problems": []}
            try:
                mode, why, result = _render(backend, sc, out_dir / name / f"{value:g}", passes, seed, timeout)
                row["mode"] = mode
                if mode is None:
                    row.update(status="unsupported", reason=why)
                    strip_rows.append(row)
                    continue
                names, img, stderr = result
                row["problems"], judged = check(strip, value, sc, names, img, stderr, tests)
                row["status"] = "failed" if row["problems"] else ("ok" if judged else "unjudged")
                row["mean"] = float(img[..., :3].mean())
                if {"gain", "lossless"} & set(strip.checks):
                    sphere, env = sphere_region(sc, img.shape[1], img.shape[0])
                    row["mean"] = float(_ratio(img, stderr, sphere, env)[0].mean())  # sphere / environment
                images.append((value, img, stderr, sc))
            except Exception as exc:  # noqa: BLE001 - report per value, go on
                row.update(status="failed", problems=[f"render failed: {exc}"])
            strip_rows.append(row)
        if strip.limit and images:
            _limit(backend, strip, images[0], strip_rows, out_dir / name / "limit", passes, seed, timeout, tests)
        if images:
            strip_image(out_dir / f"{name}.png", [(v, i) for v, i, _, _ in images])
        rows += strip_rows
    return rows


def _limit(backend, strip, first, strip_rows, folder, passes, seed, timeout, tests):
    """The strip's first value must meet its limit (alpha -> 0: the smooth surface; film -> 0: the
    bare conductor): the difference of the sphere's means against both renders' noise."""
    value, img, stderr, sc = first
    limit_scene = strip.limit(sc)
    limit_scene["needs"] = ir.derived_needs({k: v for k, v in limit_scene.items() if k != "needs"})
    mode, why, result = _render(backend, limit_scene, folder, passes, seed + 1000, timeout)
    row = next(r for r in strip_rows if r["value"] == value)
    if result is None:
        row.setdefault("notes", []).append(f"limit not rendered: {why}")
        return
    _, limit, _ = result
    sphere, env = sphere_region(sc, img.shape[1], img.shape[0])
    a, b = img[sphere][:, :3].astype(np.float64), limit[sphere][:, :3].astype(np.float64)
    diff = a.mean(axis=0) - b.mean(axis=0)
    se = np.sqrt(a.var(axis=0, ddof=1) / len(a) + b.var(axis=0, ddof=1) / len(b))
    z = diff / np.maximum(se, 1e-300)
    row["limit_jump"] = float(np.abs(diff).max())
    row["limit_z"] = float(np.abs(z).max())
    if np.min(stats.two_sided_p(z, len(a) - 1)) < stats.sidak_threshold(stats.ALPHA, tests):
        row["problems"].append(f"{value:g} differs from its limit by {row['limit_jump']:.4f} "
                               f"({float(np.abs(z).max()):.1f} standard errors)")
        row["status"] = "failed"
