"""What spectral rendering changes for a scene (``--study spectral-vs-rgb``): the scene rendered
spectrally and in RGB by the same renderer (Mitsuba's spectral and RGB variants; Cycles too when
the run has it), no reference needed, and where and how much the two differ, under the scene's own
light and, on request (``--illuminants``), with every light's spectrum swapped for a CIE
illuminant of the same luminance.

The comparison, per render pair (the spectral render is the one compared against):
- **beyond noise**: the noise test of batch/verdict/compare.py (blocks, Sidak, alpha 0.01) with
  both renders' own noise (independent passes), the spectral render in the reference's role;
- **how much**: CIEDE2000 (CIE 142-2001, via colour-science) per block of the same test, between
  the two renders' block means, in CIELAB relative to a white of the light's chromaticity and the
  spectral image's 99th-percentile luminance (for a scene lit by a uniform sky, the sky seen
  directly); its mean, 95th percentile and maximum over the blocks, and a map;
- **how much noise alone could show**: per block, the dE00 of a shift of two standard errors of
  the difference (per channel, in the measured direction), its 95th percentile.

Words, not ``failed``: "differs visibly (dE00 p95 3.2)" when the difference is beyond noise and
its 95th percentile reaches VISIBLE_DE00 (1.0, the conventional threshold of a just-noticeable
CIEDE2000 difference; ``--visible-de00``); "differs below visibility" when beyond noise but below
it; "too noisy to tell" when the difference reaches it but is not established beyond noise, or
noise alone could reach it (render more samples); "no visible difference" otherwise. A render that fails is ``failed``, and a route that cannot
render the scene (an RGB variant for a polarised, fluorescent, dispersive or thin-film scene) is
``unsupported``, as everywhere else. A pair with a pixel that is not finite (NaN or Inf) in either
render gets no verdict: it is ``failed``, its reason saying how many pixels of which render (a NaN
has no colour; folded into percentiles it would read as "dE00 p95 nan").
"""
import copy
from pathlib import Path

import numpy as np

from ...exporters import colorimetry, ir
from .. import exr

NAME = "spectral-vs-rgb"
FOLDER = Path("studies") / "spectral_vs_rgb"
VISIBLE_DE00 = 1.0
ALPHA = 0.01
PASSES = 2
MAP_SAMPLES = 65536  # samples per render pooled in one block of the dE00 map (the noise test's own minimum)
# statuses of a study row: the words above (batch/report shows them as they are)
VERDICTS = {"visible": "differs visibly", "below": "differs below visibility", "noisy": "too noisy to tell",
            "same": "no visible difference"}
# --illuminants: the project's CIE tables (exporters/data/cie_illuminants.json) and colour-science's
# CIE LED series (CIE 015:2018, Table 11.1; colour.SDS_ILLUMINANTS), every one normalised to 1.0 at
# 560 nm as the scene format's named illuminants are
PROJECT_ILLUMINANTS = {"A": "cie_a", "D50": "cie_d50", "D55": "cie_d55", "D65": "cie_d65", "D75": "cie_d75",
                       "E": "cie_e", "F2": "cie_fl2", "F7": "cie_fl7", "F8": "cie_fl8", "F11": "cie_fl11"}
LED_SERIES = ("LED-B1", "LED-B2", "LED-B3", "LED-B4", "LED-B5", "LED-BH1", "LED-RGB1", "LED-V1", "LED-V2")
ILLUMINANTS = tuple(PROJECT_ILLUMINANTS) + LED_SERIES
LIGHT_KEYS = ("radiance", "irradiance", "intensity")  # an emitter's spectrum, whatever its kind
RGB_ROUTES = ("mitsuba", "cycles", "luxcore")  # the renderers with an RGB side: Mitsuba's RGB variant, the RGB backends


def illuminant_spectrum(key):
    """The IR spectrum of --illuminants ``key``: a named table of the project, or a CIE LED
    illuminant from colour-science as a sampled spectrum (1.0 at 560 nm)."""
    if key in PROJECT_ILLUMINANTS:
        return {"type": "named", "name": PROJECT_ILLUMINANTS[key], "scale": 1.0}
    import colour
    sd = colour.SDS_ILLUMINANTS[key]
    wl, values = np.asarray(sd.wavelengths, float), np.asarray(sd.values, float)
    values = values / np.interp(560.0, wl, values)
    return {"type": "sampled", "wavelengths": [float(w) for w in wl], "values": [float(v) for v in values]}


def lights(scene):
    """[(holder dict, key)] of every light spectrum in ``scene``, every kind of light the IR has
    (exporters/ir.py): the environment's radiance, each object's emitter (area ``radiance``,
    collimated ``irradiance``) and each delta light of ``lights`` (point and spot ``intensity``,
    directional ``irradiance``). An environment map is not among them: its light is its image's
    RGB texels, which the renderer uplifts itself (its ``radiance`` is only their mean), so no
    illuminant replaces it and it stays as it is under --illuminants."""
    out = []
    env = scene.get("environment")
    if isinstance(env, dict) and isinstance(env.get("radiance"), dict) and env.get("type") != "map":
        out.append((env, "radiance"))
    holders = [obj.get("emitter") for obj in scene.get("objects") or [] if isinstance(obj, dict)]
    holders += list(scene.get("lights") or [])
    for holder in holders:
        if isinstance(holder, dict):
            out += [(holder, k) for k in LIGHT_KEYS if isinstance(holder.get(k), dict)]
    return out


def under(scene, key):
    """``scene`` with every light's spectrum replaced by illuminant ``key``, each scaled to the
    luminance (CIE 1931 Y) the light had: the same exposure, another spectrum. None when the scene
    has no light spectrum to swap."""
    out = copy.deepcopy(scene)
    found = lights(out)
    if not found:
        return None
    new = illuminant_spectrum(key)
    y_new = float(colorimetry.spectrum_xyz(new)[1])
    for holder, k in found:
        y_old = float(colorimetry.spectrum_xyz(holder[k])[1])
        holder[k] = dict(new, scale=y_old / y_new) if new["type"] == "named" else \
            dict(new, values=[v * y_old / y_new for v in new["values"]])
    out["needs"] = ir.derived_needs({k: v for k, v in out.items() if k != "needs"})
    return out


def white_of(scene):
    """XYZ (Y = 1) of the scene's light: the environment's, else the brightest (greatest Y) of its
    emitters and delta lights (their units differ, radiance against intensity, but after a swap
    every light has one chromaticity: the choice matters only among a scene's own lights); D65
    when the scene has no light."""
    found = lights(scene)
    if not found:
        return np.asarray(colorimetry.spectrum_xyz({"type": "named", "name": "cie_d65"}), float) / 0.989
    xyz = max((np.asarray(colorimetry.spectrum_xyz(h[k]), float) for h, k in found), key=lambda x: x[1])
    return xyz / max(xyz[1], 1e-12)


def rgb_mode(backend, scene):
    """(the RGB mode of ``backend`` for ``scene``, None) or (None, why not)."""
    needs = set(scene.get("needs", [])) - {"spectral"}
    if backend.name == "mitsuba":
        if needs:
            return None, (f"Mitsuba's RGB variants cannot model {', '.join(sorted(needs))} "
                          "(no RGB polarised variant; fluorescence, dispersion and thin film are spectral plugins)")
        spectral, why = backend.mode_for(scene)
        return (spectral.replace("spectral", "rgb"), None) if spectral else (None, why)
    return backend.mode_for(scene)  # an RGB renderer (Cycles, LuxCore): its one mode


# -- planning -------------------------------------------------------------------------------------
def jobs(scenes, made, opts, out, make, for_run):
    """(jobs, rows decided without rendering) of the study: per scene and light, Mitsuba's
    spectral render and each RGB route the run has (Mitsuba's RGB variant; Cycles, LuxCore).
    ``make``: the runner's job maker (batch/jobs/job.py make), ``for_run``: its scene settings
    (batch/jobs/plan.py for_run): the runner hands them over, studies never import jobs."""
    job_list, rows = [], []
    lights_wanted = ["own"] + list(opts.get("illuminants") or [])
    for name, scene in scenes:
        if isinstance(scene, Exception):
            rows.append({"scene": name, "light": "own", "status": "failed", "reason": str(scene)})
            continue
        spectral_backend = made.get("mitsuba")
        if spectral_backend is None or not spectral_backend.availability()[0]:
            rows.append({"scene": name, "light": "own", "status": "skipped",
                         "reason": "the study renders the spectral side with Mitsuba: "
                                   + (spectral_backend.availability()[1] if spectral_backend else "add -r mitsuba")})
            continue
        base = for_run(scene, opts, judged=False)
        for light in lights_wanted:
            sc = base if light == "own" else under(base, light)
            if sc is None:
                rows.append({"scene": name, "light": light, "status": "unsupported",
                             "reason": "the scene has no light spectrum to swap"})
                continue
            spectral, why = spectral_backend.mode_for(sc)
            if spectral is None:
                rows.append({"scene": name, "light": light, "status": "unsupported", "reason": why})
                continue
            routes = [("mitsuba", spectral, "spectral")]
            for bname, backend in made.items():
                if bname not in RGB_ROUTES or not backend.availability()[0]:
                    continue  # a spectral renderer (ART, a declared one) is no RGB side of this study
                mode, why = rgb_mode(backend, sc)
                if mode is None:
                    rows.append({"scene": name, "light": light, "rgb": bname, "status": "unsupported", "reason": why})
                    continue
                routes.append((bname, mode, "rgb"))
            if len(routes) == 1:
                continue
            for bname, mode, role in routes:
                folder = FOLDER / name / light / f"{bname}-{mode}"
                job_list.append(make(
                    "study", name, sc, bname, mode, sc["render"]["spp"], out, folder,
                    backend_options=made[bname].options, passes=PASSES, seed=opts.get("seed") or 0,
                    timeout=opts.get("timeout") or 1800, source_scene=scene,
                    extra={"study": NAME, "light": light, "role": role},
                    label=f"{name} {role} {mode} under {light} light ({bname})"))
    return job_list, rows


# -- judging --------------------------------------------------------------------------------------
def to_lab(rgb, white):
    return colorimetry._colour().XYZ_to_Lab(colorimetry.srgb_to_xyz(rgb) / white[1], colorimetry._colour().XYZ_to_xy(white))


def de00(a, b):
    return np.asarray(colorimetry._colour().delta_E(a, b, method="CIE 2000"), float)


def map_block(spp, passes):
    """The side of the dE00 map's blocks in pixels: each pools at least MAP_SAMPLES samples per
    render, so the map shows where the renders differ, not where one pixel's noise is."""
    return max(1, int(np.ceil(np.sqrt(MAP_SAMPLES / max(spp, 1)))))


def non_finite(mean, se):
    """{pixels, nan, inf, of}: how many pixels of a (mean, standard error) render have a
    non-finite value in any channel of either, how many of those a NaN and an Inf, of how many."""
    mean = np.asarray(mean, float)
    both = mean if se is None else np.concatenate([mean, np.asarray(se, float)], axis=-1)
    nan, inf = np.isnan(both).any(axis=-1), np.isinf(both).any(axis=-1)
    return {"pixels": int((nan | inf).sum()), "nan": int(nan.sum()), "inf": int(inf.sum()), "of": int(nan.size)}


def compare(scene, spectral, rgb, spp, passes=PASSES, visible=VISIBLE_DE00):
    """The comparison of one pair: ``spectral`` and ``rgb`` are (mean, stderr) linear sRGB images
    of the same size, ``spp`` samples per pixel each. Returns (row fields, dE00 map at full
    resolution). Beyond noise: the noise test's blocks (batch/verdict/compare.py); how much and
    where: blocks of ``map_block`` pixels. A pixel that is not finite (NaN or Inf, in its mean or
    standard error, in either render) is counted and said, never compared: the row is ``failed``
    with ``non_finite`` (per render: pixels, nan, inf, of) and no map (None)."""
    from ..verdict import compare as cmp
    s_mean, s_se = (np.asarray(x, float)[..., :3] for x in spectral)
    r_mean, r_se = (np.asarray(x, float)[..., :3] for x in rgb)
    bad = {"spectral": non_finite(s_mean, s_se), "rgb": non_finite(r_mean, r_se)}
    if any(b["pixels"] for b in bad.values()):  # a NaN or Inf has no colour: no verdict, the pixels said
        said = "; ".join(f"{b['pixels']} of {b['of']} pixels of the {role} render are not finite "
                         f"(NaN in {b['nan']}, Inf in {b['inf']})" for role, b in zip(("spectral", "RGB"), bad.values())
                         if b["pixels"])
        return {"status": "failed", "non_finite": bad,
                "reason": f"no verdict: {said}; a non-finite pixel has no colour to compare (render again, "
                          "or find what makes the renderer write NaN or Inf)"}, None
    ref = cmp.reference_at(s_mean, s_se, spp, s_mean.shape, ref_passes=passes)
    test = cmp.z_test(r_mean, ref, spp, own_var_of_mean=r_se ** 2, own_passes=passes, alpha=ALPHA, scale_test=False)
    b = map_block(spp, passes)
    ey, ex = cmp.block_edges(s_mean.shape[0], b), cmp.block_edges(s_mean.shape[1], b)
    n = cmp.block_sums(np.ones(s_mean.shape[:2] + (1,)), ey, ex)
    a_blk, r_blk = cmp.block_sums(s_mean, ey, ex) / n, cmp.block_sums(r_mean, ey, ex) / n
    se = np.sqrt(cmp.block_sums(s_se ** 2 + r_se ** 2, ey, ex)) / n
    y = colorimetry.srgb_to_xyz(s_mean)[..., 1]
    white = white_of(scene) * max(float(np.percentile(y, 99)), 1e-12)
    lab_a = to_lab(a_blk, white)
    d = de00(lab_a, to_lab(r_blk, white))
    noise = de00(lab_a, to_lab(a_blk + np.sign(r_blk - a_blk) * 2.0 * se, white))
    beyond = not test.block_passed
    p95, n95 = float(np.percentile(d, 95)), float(np.percentile(noise, 95))
    if not beyond:  # a visible-sized difference the test cannot establish, or noise that could hide one
        kind = "noisy" if max(n95, p95) >= visible else "same"
    elif p95 >= visible:
        kind = "visible" if p95 > n95 else "noisy"
    else:
        kind = "below"
    row = {"status": kind, "verdict": f"{VERDICTS[kind]} (dE00 p95 {p95:.2g})",
           "de00": {"mean": float(d.mean()), "p95": p95, "max": float(d.max()), "noise_p95": n95,
                    "visible": visible, "blocks": int(d.size), "block": b},
           "test": {"p_min": test.p_min, "threshold": test.threshold, "z_max": test.z_max, "block": test.block,
                    "alpha": ALPHA, "beyond_noise": beyond}}
    return row, cmp.expand_blocks(d[..., None], ey, ex)[..., 0]


def finish(results, out, visible=VISIBLE_DE00):
    """The study's rows from its jobs' results [(job, record)]: one row per scene, light and RGB
    route, with its maps written beside the renders (``out``: the run folder)."""
    groups = {}
    for job, record in results:
        groups.setdefault((job["scene_name"], job["extra"]["light"]), []).append((job, record))
    rows = []
    for (name, light), items in sorted(groups.items()):
        spectral = next(((j, r) for j, r in items if j["extra"]["role"] == "spectral"), None)
        for job, record in (jr for jr in items if jr[0]["extra"]["role"] == "rgb"):
            row = {"scene": name, "light": light, "rgb": job["backend"], "rgb_mode": job["mode"],
                   "spectral_mode": spectral[0]["mode"] if spectral else None}
            if job["source_scene"].get("warnings"):  # what the export from Blender converted or lost
                row["scene_warnings"] = [dict(w) for w in job["source_scene"]["warnings"]]
            failed = [r for r in (record, spectral[1] if spectral else None) if r is None or r.get("status") != "rendered"]
            if failed:
                row.update(status="failed", reason="; ".join((r or {}).get("reason") or "the spectral render is missing"
                                                             for r in failed))
                rows.append(row)
                continue
            try:
                s_names, s_img, s_se = exr.read_image_and_stderr(out / spectral[1]["image"])
                r_names, r_img, r_se = exr.read_image_and_stderr(out / record["image"])
                fields, dmap = compare(job["scene"], (s_img, s_se), (r_img, r_se), job["spp"], job["passes"], visible)
            except Exception as exc:  # noqa: BLE001 - one pair that cannot be compared fails alone
                row.update(status="failed", reason=f"cannot compare: {type(exc).__name__}: {exc}")
                rows.append(row)
                continue
            row.update(fields)
            if dmap is None:  # no verdict (non-finite pixels): nothing to show beside the reason
                rows.append(row)
                continue
            folder = out / FOLDER / name / light
            row["images"] = write_images(folder, job["backend"], s_img, r_img, dmap, fields, out)
            row["time_s"] = {"spectral": spectral[1].get("time_s"), "rgb": record.get("time_s")}
            rows.append(row)
    return rows


def write_images(folder, rgb_name, spectral, rgb, dmap, fields, out):
    """The pair as PNGs for the report (both at one exposure: the white of the comparison), the dE00
    map as a false-colour PNG and as an EXR (float values for tev)."""
    from PIL import Image
    folder.mkdir(parents=True, exist_ok=True)
    y = colorimetry.srgb_to_xyz(np.asarray(spectral, float)[..., :3])[..., 1]
    expo = 1.0 / max(float(np.percentile(y, 99)), 1e-12)

    def srgb8(img):
        x = np.clip(np.asarray(img, float)[..., :3] * expo, 0.0, 1.0)
        x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
        return (x * 255 + 0.5).astype(np.uint8)

    top = max(float(fields["de00"]["max"]), 2 * VISIBLE_DE00)
    import matplotlib
    cmap = matplotlib.colormaps["magma"]
    names = {"spectral": "spectral.png", "rgb": f"rgb_{rgb_name}.png", "de00": f"de00_{rgb_name}.png"}
    Image.fromarray(srgb8(spectral)).save(folder / names["spectral"])
    Image.fromarray(srgb8(rgb)).save(folder / names["rgb"])
    Image.fromarray((cmap(np.clip(dmap / top, 0, 1))[..., :3] * 255 + 0.5).astype(np.uint8)).save(folder / names["de00"])
    exr.write(folder / f"de00_{rgb_name}.exr", np.repeat(dmap[..., None], 3, axis=-1).astype(np.float32))
    out_names = {k: str((folder / v).relative_to(out)) for k, v in names.items()}
    out_names["de00_top"] = top
    return out_names
