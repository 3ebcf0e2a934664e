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
- dispersion_ior, dispersion_abbe (with dispersion_fringes in the input): the N-SF11 sphere before
  the stripes with its Sellmeier B scaled so that n_d runs 1.7847..1.0001 (n^2 - 1 scales at every
  wavelength), and a Cauchy glass of n_d 1.7847 whose Abbe number runs 20..1e6. Luminance may not
  be negative beyond noise (a path that keeps one wavelength has an out-of-gamut colour, so a
  negative sRGB component is legitimate, but Y, an integral against y_bar >= 0, never is); the
  last value must meet its limit within noise: n_d 1.0001 the scene without the sphere (it
  vanishes), the largest Abbe number the native, non-dispersive dielectric of the same n_d.
"""
import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ...exporters import colorimetry, dispersion, ir
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


def _dispersive_sphere(scene):
    return next(o for o in scene["objects"] if (o.get("bsdf") or {}).get("type") == "dielectric")


def _set_n_d(sc, value):
    """Scale the glass's Sellmeier B (n^2 - 1 at every wavelength) so that n_d becomes ``value``."""
    sphere = _dispersive_sphere(sc)
    glass = sphere["bsdf"]["int_ior"]
    n_d = dispersion.abbe_number(glass)[0]
    b, c = dispersion.sellmeier(glass)
    k = (value ** 2 - 1.0) / (n_d ** 2 - 1.0)
    sphere["bsdf"]["int_ior"] = {"type": "sellmeier", "B": [k * x for x in b], "C": c}


def _set_abbe(sc, value):
    """A Cauchy glass n = A + B / l^2 of the scene glass's n_d with Abbe number (n_d - 1)/(n_F - n_C) = value."""
    sphere = _dispersive_sphere(sc)
    n_d = dispersion.abbe_number(sphere["bsdf"]["int_ior"])[0]
    lf, ld, lc = (dispersion.FRAUNHOFER_NM[k] * 1e-3 for k in "FdC")
    bb = (n_d - 1.0) / (value * (1 / lf ** 2 - 1 / lc ** 2))
    sphere["bsdf"]["int_ior"] = {"type": "cauchy", "A": n_d - bb / ld ** 2, "B": bb, "C": 0.0}


def _no_sphere(sc):
    out = copy.deepcopy(sc)
    name = _dispersive_sphere(out)["name"]
    out["objects"] = [o for o in out["objects"] if o["name"] != name]
    return out


def _native_glass(sc):
    out = copy.deepcopy(sc)
    sphere = _dispersive_sphere(out)
    sphere["bsdf"]["int_ior"] = round(dispersion.abbe_number(sphere["bsdf"]["int_ior"])[0], 6)
    return out


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
    checks: tuple           # of "finite", "negative", "luminance", "gain", "lossless", "probes"
    size: int = 32
    limit: Callable = None  # (the limit value's scene) -> the scene it must meet within noise
    limit_at: int = 0       # which value is the limit: 0 the first, -1 the last
    region: str = "sphere"  # what the limit compares: the furnace "sphere" or the whole "image"
    spp: int = None         # samples per pixel (default: the base scene's)


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
    Strip("dispersion_ior", "dispersion_fringes", (1.7847, 1.5, 1.3, 1.1, 1.01, 1.001, 1.0001), _set_n_d,
          ("finite", "luminance"), 48, limit=_no_sphere, limit_at=-1, region="image", spp=64),
    Strip("dispersion_abbe", "dispersion_fringes", (20.0, 40.0, 80.0, 160.0, 1e3, 1e4, 1e6), _set_abbe,
          ("finite", "luminance"), 48, limit=_native_glass, limit_at=-1, region="image", spp=64),
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
            if strip.spp:
                sc["render"]["spp"] = strip.spp
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
    if "luminance" in checks and stderr is not None:
        y = colorimetry.srgb_to_xyz(rgb)[..., 1]
        y_se = np.sqrt(np.sum((colorimetry.srgb_to_xyz(np.eye(3))[:, 1] * stderr[..., :3]) ** 2, axis=-1))
        bad = int(np.sum(stats.one_sided_p(-y / np.maximum(y_se, 1e-300), 1) < stats.sidak_threshold(stats.ALPHA, y.size)))
        judged = True
        if bad:
            problems.append(f"{bad} pixels of negative luminance beyond their noise")
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
    from ..previews import srgb_encode
    from PIL import Image
    h = max(i.shape[0] for _, i in images)
    tiles = [np.pad(srgb_encode(i[..., :3]), ((0, h - i.shape[0]), (0, 2), (0, 0))) for _, i in images]
    Image.fromarray((np.concatenate(tiles, axis=1) * 255 + 0.5).astype(np.uint8)).save(path)


def jobs(backend, golden, out, folder, make, passes=4, seed=0, timeout=600, strips=None):
    """The stability case as jobs for one backend, each made by ``make`` (batch/jobs/job.py
    ``make``, given by the runner: a study imports no runner code): one per strip value, plus
    one for each strip's limit scene; and the rows decided without rendering (unsupported)."""
    job_list, rows = [], []
    for name, (strip, scenes) in definitions(golden, strips).items():
        tests = len(scenes) * 3 + (3 if strip.limit else 0)
        for k, (value, sc) in enumerate(scenes):
            mode, why = backend.mode_for(sc)
            if mode is None:
                rows.append({"sweep": name, "value": value, "backend": backend.name, "mode": None, "problems": [],
                             "status": "unsupported", "reason": why})
                continue
            where = Path(folder) / backend.name / name / f"{value:g}"
            job_list.append(make("stability", sc["name"], sc, backend.name, mode, sc["render"]["spp"], out,
                                          where, backend_options=backend.options, passes=passes,
                                          seed=seed, timeout=timeout, label=f"{name} {value:g} ({backend.name})",
                                          extra={"strip": name, "value": value, "tests": tests, "role": "value"}))
            if strip.limit and k == (strip.limit_at % len(scenes)):
                limit = strip.limit(sc)
                limit["needs"] = ir.derived_needs({key: v for key, v in limit.items() if key != "needs"})
                mode_l, _ = backend.mode_for(limit)
                if mode_l is not None:
                    job_list.append(make(
                        "stability", limit["name"], limit, backend.name, mode_l, limit["render"]["spp"], out,
                        Path(folder) / backend.name / name / "limit", backend_options=backend.options,
                        passes=passes, seed=seed + 1000, timeout=timeout, label=f"{name} limit ({backend.name})",
                        extra={"strip": name, "value": value, "tests": tests, "role": "limit"}))
    return job_list, rows


def judge_value(job, record):
    """The row of one strip value (the limit scene's render is compared in finish())."""
    e = job["extra"]
    row = {"sweep": e["strip"], "value": e["value"], "backend": job["backend"], "mode": job["mode"], "problems": [],
           "role": e["role"], "image": record["image_path"]}
    if e["role"] == "limit":
        return row
    strip = next(s for s in STRIPS if s.name == e["strip"])
    names, img, stderr = exr.read_image_and_stderr(record["image_path"])
    row["problems"], judged = check(strip, e["value"], job["scene"], names, img, stderr, e["tests"])
    row["status"] = "failed" if row["problems"] else ("ok" if judged else "unjudged")
    row["mean"] = float(img[..., :3].mean())
    if {"gain", "lossless"} & set(strip.checks):
        sphere, env = sphere_region(job["scene"], img.shape[1], img.shape[0])
        row["mean"] = float(_ratio(img, stderr, sphere, env)[0].mean())  # sphere / environment
    return row


def finish(results, out_dir):
    """The rows of every strip from the jobs' results [(job, result)]: limits compared, strip
    images written to out_dir/<backend>/<strip>.png."""
    rows, by_strip = [], {}
    for job, result in results:
        by_strip.setdefault((job["backend"], job["extra"]["strip"]), []).append((job, result))
    for (backend, name), items in sorted(by_strip.items()):
        strip = next(s for s in STRIPS if s.name == name)
        values = [(j, r) for j, r in items if j["extra"]["role"] == "value"]
        limit = next(((j, r) for j, r in items if j["extra"]["role"] == "limit"), None)
        strip_rows = []
        for j, r in sorted(values, key=lambda jr: jr[0]["extra"]["value"]):
            row = r.get("row") or {"sweep": name, "value": j["extra"]["value"], "backend": backend, "mode": j["mode"],
                                   "status": "failed", "problems": [r.get("reason", "failed")]}
            strip_rows.append((j, row))
        if limit is not None:
            lj, lr = limit
            at = next(((j, row) for j, row in strip_rows if j["extra"]["value"] == lj["extra"]["value"]), None)
            if at is not None and lr.get("row") and at[1].get("image"):
                _limit(strip, at[0], at[1], lj, lr["row"])
        images = [(row["value"], exr.read_image(row["image"])[1]) for _, row in strip_rows if row.get("image")]
        if images:
            (Path(out_dir) / backend).mkdir(parents=True, exist_ok=True)
            strip_image(Path(out_dir) / backend / f"{name}.png", images)
        rows += [{k: v for k, v in row.items() if k not in ("image", "role")} for _, row in strip_rows]
    return rows


def _limit(strip, job, row, limit_job, limit_row):
    """The strip's limit value must meet its limit scene (see compare_to_limit); updates its row."""
    found = compare_to_limit(strip, job["scene"], row["image"], limit_row["image"], job["passes"],
                             job["extra"]["tests"])
    row.update(limit_jump=found["limit_jump"], limit_z=found["limit_z"])
    if found["problem"]:
        row["problems"].append(f"{row['value']:g} {found['problem']}")
        row["status"] = "failed"


def compare_to_limit(strip, scene, image, limit_image, passes, tests):
    """alpha -> 0 must meet the smooth surface, film -> 0 the bare conductor, n -> 1 the scene
    without the sphere, Abbe number -> infinity the native dielectric: the difference of the
    region's means (the furnace sphere, or the whole image) against both renders' own noise."""
    _, img, stderr = exr.read_image_and_stderr(image)
    _, limit, limit_se = exr.read_image_and_stderr(limit_image)
    if strip.region == "sphere":
        region, _ = sphere_region(scene, img.shape[1], img.shape[0])
    else:
        region = np.ones(img.shape[:2], dtype=bool)
    a, b = img[region][:, :3].astype(np.float64), limit[region][:, :3].astype(np.float64)
    diff = a.mean(axis=0) - b.mean(axis=0)
    n = len(a)
    if stderr is not None and limit_se is not None:
        # each render's own noise (pixels independent): the region's signal varies, its noise is known
        se = np.sqrt(np.sum(stderr[region][:, :3].astype(np.float64) ** 2, axis=0)
                     + np.sum(limit_se[region][:, :3].astype(np.float64) ** 2, axis=0)) / n
        dof = n * (passes - 1)
    else:
        se = np.sqrt(a.var(axis=0, ddof=1) / n + b.var(axis=0, ddof=1) / n)
        dof = n - 1
    z = diff / np.maximum(se, 1e-300)
    out = {"limit_jump": float(np.abs(diff).max()), "limit_z": float(np.abs(z).max()), "problem": None}
    if np.min(stats.two_sided_p(z, dof)) < stats.sidak_threshold(stats.ALPHA, tests):
        out["problem"] = f"differs from its limit by {out['limit_jump']:.4f} ({out['limit_z']:.1f} standard errors)"
    return out
