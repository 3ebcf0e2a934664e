"""Stability case: parameter sweeps where implementations typically break, each rendered as a
strip of small images and checked for NaN, Inf, negative values, energy gain in a white furnace,
and jumps at the limits. Every render is judged on its own; failures are reported per value.

Sweeps (built from the canonical scenes' IR, so they follow scenes.blend):
- ggx_grazing: the copper plate of ggx_copper_80 turned 80..89 degrees (grazing view and light).
- roughness_furnace: a rough GGX dielectric sphere (n = 1.5) alone in a uniform environment of
  radiance 1, alpha 0.001..1: a non-absorbing object can only lose energy (single-scattering
  microfacets lose some at high alpha), so no pixel may exceed 1 beyond noise; alpha -> 0 must
  approach the smooth sphere (which is exactly 1 everywhere: lossless).
- ior_furnace: a smooth dielectric sphere in the same furnace, n = 1.0001..3: exactly 1 at every
  pixel for every n (the limit n -> 1 is an invisible sphere).
- polarizer_malus: the Brewster plane seen through the polariser at 0..90 degrees: the Fresnel
  probe (Malus' law) at every angle.
- dispersion_ior, dispersion_abbe (with dispersion_fringes in the input; DISPERSION_STRIPS): the
  N-SF11 sphere before the stripes with its Sellmeier B scaled so that n_d runs 1.7847..1.0001
  (n^2 - 1 scales at every wavelength), and a Cauchy glass of n_d 1.7847 whose Abbe number runs
  20..1e6. Every render is checked for NaN, Inf and negative values; the last of each strip must
  equal its limit within noise: n_d 1.0001 the scene without the sphere (the sphere vanishes), the
  largest Abbe number the native, non-dispersive dielectric of the same n_d.
"""
import copy

import numpy as np

from ...exporters import colorimetry, dispersion, ir
from ..verdict import compare, probes
from .. import exr

Z = 5.0  # the furnace sphere's mean may exceed 1 by this many standard errors before it counts as gain


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


# data: strip name -> (parameter values, last value's limit); the scenes come from dispersion_fringes
DISPERSION_STRIPS = {
    "dispersion_ior": ((1.7847, 1.5, 1.3, 1.1, 1.01, 1.001, 1.0001), "the scene without the sphere"),
    "dispersion_abbe": ((20.0, 40.0, 80.0, 160.0, 1e3, 1e4, 1e6), "the native dielectric of the same n_d"),
}
DISPERSION_SIZE, DISPERSION_SPP = 48, 64


def _dispersive_sphere(scene):
    return next(o for o in scene["objects"] if (o.get("bsdf") or {}).get("type") == "dielectric")


def dispersion_scene(base, strip, value):
    """The fringes scene with its sphere's IOR set by one value of a dispersion strip; value None:
    the strip's limit (no sphere, or the native dielectric of n_d)."""
    sc = copy.deepcopy(base)
    sphere = _dispersive_sphere(sc)
    glass = sphere["bsdf"]["int_ior"]
    n_d = dispersion.abbe_number(glass)[0]
    if strip == "dispersion_ior":
        if value is None:
            sc["objects"] = [o for o in sc["objects"] if o is not sphere]
        else:  # scale n^2 - 1 at every wavelength: n_d becomes ``value``
            b, c = dispersion.sellmeier(glass)
            k = (value ** 2 - 1.0) / (n_d ** 2 - 1.0)
            sphere["bsdf"]["int_ior"] = {"type": "sellmeier", "B": [k * x for x in b], "C": c}
    else:
        if value is None:
            sphere["bsdf"]["int_ior"] = round(n_d, 6)
        else:  # Cauchy n = A + B / l^2 with n_d fixed and (n_d - 1) / (n_F - n_C) = value
            lf, ld, lc = (dispersion.FRAUNHOFER_NM[k] * 1e-3 for k in "FdC")
            bb = (n_d - 1.0) / (value * (1 / lf ** 2 - 1 / lc ** 2))
            sphere["bsdf"]["int_ior"] = {"type": "cauchy", "A": n_d - bb / ld ** 2, "B": bb, "C": 0.0}
    sc["render"].update(width=DISPERSION_SIZE, height=DISPERSION_SIZE, spp=DISPERSION_SPP)
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    return sc


def definitions(golden):
    """{sweep name: [(parameter value, IR scene)]}."""
    out = {}
    base = golden["ggx_copper_80"]
    strip = []
    for angle in range(80, 90):
        sc = copy.deepcopy(base)
        a = np.radians(angle)
        plate = next(o for o in sc["objects"] if o["name"].startswith("copper_plate"))
        plate["shape"]["to_world"] = [[1, 0, 0, 0], [0, np.cos(a), -np.sin(a), 0], [0, np.sin(a), np.cos(a), 0], [0, 0, 0, 1]]
        strip.append((angle, sc))
    out["ggx_grazing"] = strip
    out["roughness_furnace"] = [(alpha, _furnace_sphere(
        {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0, "roughness": {"distribution": "ggx", "alpha": alpha}}))
        for alpha in (0.001, 0.01, 0.05, 0.1, 0.2, 0.4, 0.7, 1.0)]
    out["ior_furnace"] = [(n, _furnace_sphere({"type": "dielectric", "int_ior": n, "ext_ior": 1.0}))
                          for n in (1.0001, 1.01, 1.1, 1.33, 1.5, 2.0, 2.5, 3.0)]
    out["polarizer_malus"] = []
    for angle in (0, 15, 30, 45, 60, 75, 90):
        sc = copy.deepcopy(golden["polarizing_plane_0"])
        sc["camera"]["polarizer"]["angle"] = float(angle)
        out["polarizer_malus"].append((angle, sc))
    for strip in out.values():
        for _, sc in strip:
            sc["render"]["width"] = sc["render"]["height"] = 32 if sc["name"] == "furnace" else 64
            sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    if "dispersion_fringes" in golden:
        for name, (values, _limit) in DISPERSION_STRIPS.items():
            out[name] = [(v, dispersion_scene(golden["dispersion_fringes"], name, v)) for v in values]
    return out


def check(sweep, value, scene, names, img, stderr=None):
    """Problems of one render of a sweep: a list of strings (empty: stable)."""
    rgb = img[..., :3]
    s = compare.image_sanity(rgb)
    problems = [f"{s['nan']} NaN" if s["nan"] else "", f"{s['inf']} Inf" if s["inf"] else ""]
    noise = stderr[..., :3] if stderr is not None else np.zeros_like(rgb)
    if (rgb < -Z * noise - 1e-6).any() and sweep.endswith("furnace"):
        problems.append(f"{int((rgb < -Z * noise - 1e-6).sum())} negative values")
    if sweep.endswith("furnace"):
        # "1" is the environment as this render shows it: the image corners see only the
        # environment (a flat spectrum of 1 is not RGB (1, 1, 1): equal-energy white is not D65)
        corners = np.concatenate([rgb[:3, :3], rgb[:3, -3:], rgb[-3:, :3], rgb[-3:, -3:]]).reshape(-1, 3)
        white = corners.mean(axis=0)
        ratio = rgb / white
        # energy gain is a property of the expectation: judge the sphere's mean against its own
        # standard error (independent pixels); single pixels are heavy-tailed (caustic paths)
        h, w = ratio.shape[:2]
        centre = ratio[h // 4: 3 * h // 4, w // 4: 3 * w // 4].reshape(-1, 3)
        m, se = centre.mean(axis=0), centre.std(axis=0, ddof=1) / np.sqrt(len(centre))
        if (m > 1.0 + Z * se + 1e-3).any():
            problems.append(f"energy gain: the sphere's mean is {float(m.max()):.4f}x the environment "
                            f"(+{float(((m - 1) / np.maximum(se, 1e-12)).max()):.1f} standard errors)")
        if sweep == "ior_furnace" and abs(float(ratio.mean()) - 1.0) > 0.02:
            problems.append(f"a lossless sphere in a furnace must equal the environment; mean {float(ratio.mean()):.4f}x")
    if sweep in DISPERSION_STRIPS:
        # a path that keeps one wavelength has an out-of-gamut colour (a negative sRGB component
        # is legitimate), but its luminance Y, an integral against y_bar >= 0, never is negative
        y = colorimetry.srgb_to_xyz(rgb)[..., 1]
        if (y < -1e-6 * max(float(np.abs(y).max()), 1.0)).any():
            problems.append(f"{int((y < 0).sum())} pixels of negative luminance")
    if sweep == "polarizer_malus":
        p = next((p for p in probes.evaluate(scene, names, img) if p["name"].startswith("brewster")), None)
        if p is None or p["pass"] is False:
            problems.append(f"Fresnel/Malus probe failed: {p and p['error']}")
    return [p for p in problems if p]


def strip_image(path, images):
    """The sweep's renders side by side (sRGB previews), labelled by order."""
    from ..report.previews import srgb_encode
    from PIL import Image
    h = max(i.shape[0] for _, i in images)
    tiles = [np.pad(srgb_encode(i[..., :3]), ((0, h - i.shape[0]), (0, 2), (0, 0))) for _, i in images]
    Image.fromarray((np.concatenate(tiles, axis=1) * 255 + 0.5).astype(np.uint8)).save(path)


def _limit_problem(backend, strip, golden, row, img, stderr, folder, passes, seed, timeout):
    """Compare a dispersion strip's last render with its limit, each channel's image mean against
    both renders' standard errors (independent pixels and passes)."""
    limit = dispersion_scene(golden["dispersion_fringes"], strip, None)
    mode, why = backend.mode_for(limit)
    if mode is None:
        return None
    path = backend.export(limit, folder / "scene")
    backend.render(path, mode, limit["render"]["spp"], folder / "render.exr", passes=passes, seed=seed + 1000,
                   timeout=timeout)
    _, ref, ref_se = exr.read_image_and_stderr(folder / "render.exr")
    n = img.shape[0] * img.shape[1]
    diff = img[..., :3].mean(axis=(0, 1)) - ref[..., :3].mean(axis=(0, 1))
    se = np.sqrt((stderr[..., :3] ** 2).sum(axis=(0, 1)) + (ref_se[..., :3] ** 2).sum(axis=(0, 1))) / n
    z = float(np.max(np.abs(diff) / np.maximum(se, 1e-12)))
    row["limit_z"] = z
    if z > Z:
        return (f"differs from its limit ({DISPERSION_STRIPS[strip][1]}) by {z:.1f} standard errors "
                f"(image means {img[..., :3].mean():.4f} vs {ref[..., :3].mean():.4f})")
    return None


def run(backend, golden, out_dir, passes=4, seed=0, timeout=600, sweeps=None):
    """Render every sweep (or those named in ``sweeps``) with ``backend``; returns the result rows
    and writes strip images."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, strip in definitions(golden).items():
        if sweeps is not None and name not in sweeps:
            continue
        images = []
        for value, sc in strip:
            mode, why = backend.mode_for(sc)
            row = {"sweep": name, "value": value, "backend": backend.name, "mode": mode, "problems": []}
            if mode is None:
                row.update(status="unsupported", reason=why)
                rows.append(row)
                continue
            folder = out_dir / name / f"{value:g}"
            try:
                path = backend.export(sc, folder / "scene")
                backend.render(path, mode, sc["render"]["spp"], folder / "render.exr", passes=passes, seed=seed,
                               timeout=timeout)
                names, img, stderr = exr.read_image_and_stderr(folder / "render.exr")
                row["problems"] = check(name, value, sc, names, img, stderr)
                row["status"] = "failed" if row["problems"] else "ok"
                row["mean"] = float(img[..., :3].mean())
                if name.endswith("furnace"):
                    corners = np.concatenate([img[:3, :3, :3], img[-3:, -3:, :3]]).reshape(-1, 3).mean(axis=0)
                    row["mean"] = float((img[..., :3] / corners).mean())  # relative to the environment
                images.append((value, img))
            except Exception as exc:  # noqa: BLE001 - report per value, go on
                row.update(status="failed", problems=[f"render failed: {exc}"])
            rows.append(row)
        if name == "roughness_furnace" and images:
            smooth = _furnace_sphere({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0})
            smooth["render"]["width"] = smooth["render"]["height"] = 32
            path = backend.export(smooth, out_dir / name / "smooth" / "scene")
            backend.render(path, backend.mode_for(smooth)[0], 64, out_dir / name / "smooth" / "render.exr",
                           passes=passes, seed=seed, timeout=timeout)
            _, limit = exr.read_image(out_dir / name / "smooth" / "render.exr")
            first = next(r for r in rows if r["sweep"] == name and r["value"] == images[0][0])
            jump = abs(float(images[0][1][..., :3].mean()) - float(limit[..., :3].mean()))
            first["limit_jump"] = jump
            if jump > 0.01:
                first["problems"].append(f"alpha {images[0][0]} differs from the smooth limit by {jump:.4f}")
                first["status"] = "failed"
        if name in DISPERSION_STRIPS and images and images[-1][0] == strip[-1][0]:
            last = next(r for r in rows if r["sweep"] == name and r["value"] == strip[-1][0])
            _, img, stderr = exr.read_image_and_stderr(out_dir / name / f"{strip[-1][0]:g}" / "render.exr")
            problem = _limit_problem(backend, name, golden, last, img, stderr, out_dir / name / "limit", passes,
                                     seed, timeout)
            if problem:
                last["problems"].append(problem)
                last["status"] = "failed"
        if images:
            strip_image(out_dir / f"{name}.png", images)
    return rows
