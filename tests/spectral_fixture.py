"""A run folder with one spectral job, from real data, for the report's spectra (issue 33 item 3).

``spectral_run(out)`` renders a tiny scene with the example renderer's spectral route
(examples/your_renderer/toy_renderer.py --format spectral: Mitsuba 3, 5 nm box bands, the Fichet
2021 layout), writes the job's ``spectral_preview.exr`` (half floats) with the project's EXR code,
its render.exr (the spectrum's colour, batch/spectral_exr.py to_rgb), and a metrics.json whose
``bands`` record follows the contract: each patch's measured spectrum (the mean over its pixels,
the standard error from their scatter: the renderer's pixels are independent), the expected one
(the patch's reflectance, box-averaged over each band: a Lambertian plate under a uniform
environment of radiance 1 reflects radiance rho(lambda)), z, the Sidak threshold over bands and
regions, pass and worst band.

The scene: four Lambertian patches, each a rectangle, under Mitsuba's constant environment. One
patch ("planted") is rendered with its reflectance 15 % higher between 480 and 500 nm than its
truth: a planted band error whose bands must fail. When the verdict side's band checks land,
this whole module is replaced by one call that runs the batch on toy_spectral (the record is
then the verdict's own)."""
import json
import math
import subprocess
import sys
from pathlib import Path
from statistics import NormalDist

import numpy as np

from conftest import ROOT, write_hand_made_metrics

TOY = ROOT / "examples" / "your_renderer" / "toy_renderer.py"
W, H, SPP, ALPHA = 48, 32, 1024, 0.01
BAND_NM = 5.0  # toy_renderer's box bands
# patch: (reflectance as wavelength:value knots over 360-830 nm, pixel box x0, y0, x1, y1 of the
# measured region inside the patch)
PATCHES = {
    "red": ("360:0.05, 560:0.06, 600:0.5, 830:0.7", (4, 4, 18, 12)),
    "green": ("360:0.05, 480:0.1, 530:0.6, 580:0.15, 830:0.1", (30, 4, 44, 12)),
    "blue": ("360:0.3, 450:0.7, 520:0.2, 830:0.05", (4, 20, 18, 28)),
    "planted": ("360:0.4, 830:0.4", (30, 20, 44, 28)),
}
PLANT = (480.0, 500.0, 1.15)  # the planted patch's reflectance x 1.15 on [480, 500] nm


def _knots(text):
    pairs = [tuple(map(float, p.split(":"))) for p in text.split(",")]
    return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])


def _planted(text):
    """The planted patch's rendered reflectance: its truth x PLANT[2] on [PLANT[0], PLANT[1]]."""
    wl, v = _knots(text)
    lo, hi, f = PLANT
    grid = np.unique(np.concatenate([wl, [lo - 0.01, lo, hi, hi + 0.01]]))
    vals = np.interp(grid, wl, v) * np.where((grid >= lo) & (grid <= hi), f, 1.0)
    return ", ".join(f"{a:g}:{b:.6g}" for a, b in zip(grid, vals))


def scene_xml():
    """A Mitsuba 3 scene: an orthographic camera over four coplanar patches, W x H pixels, each
    patch's pixels inside its rectangle (one pixel = 0.1 scene units)."""
    shapes = []
    for name, (knots, (x0, y0, x1, y1)) in PATCHES.items():
        spectrum = _planted(knots) if name == "planted" else knots
        # the rectangle covers the measured box with 2 px to spare; scene x right, y up, z toward the camera
        cx, cy = ((x0 + x1) / 2 - W / 2) * 0.1, (H / 2 - (y0 + y1) / 2) * 0.1
        sx, sy = ((x1 - x0) / 2 + 2) * 0.1, ((y1 - y0) / 2 + 2) * 0.1
        shapes.append(f"""<shape type="rectangle"><transform name="to_world"><scale x="{sx}" y="{sy}"/><translate x="{cx}" y="{cy}"/></transform>
<bsdf type="diffuse"><spectrum name="reflectance" value="{spectrum}"/></bsdf></shape>""")
    return f"""<scene version="3.0.0">
<sensor type="orthographic"><transform name="to_world"><scale x="{W * 0.05}" y="{W * 0.05}"/><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
<sampler type="independent"><integer name="sample_count" value="{SPP}"/></sampler>
<film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" value="{H}"/><rfilter type="box"/></film></sensor>
<integrator type="path"><integer name="max_depth" value="2"/></integrator>
<emitter type="constant"><spectrum name="radiance" value="1"/></emitter>
{chr(10).join(shapes)}
</scene>
"""


def _box_mean(knots, lo, hi):
    wl, v = _knots(knots)
    grid = np.linspace(lo, hi, 2001)  # the mean of a piecewise-linear function on a fine grid
    return float(np.interp(grid, wl, v).mean())


def bands_record(centres, cube):
    """The contract's ``bands`` record of the patches in ``cube`` (H x W x N, the mean over passes)."""
    edges = [[float(c - BAND_NM / 2), float(c + BAND_NM / 2)] for c in centres]
    threshold = 1 - (1 - ALPHA) ** (1 / (len(centres) * len(PATCHES)))
    z_crit = NormalDist().inv_cdf(1 - threshold / 2)
    regions = []
    for name, (knots, (x0, y0, x1, y1)) in PATCHES.items():
        px = cube[y0:y1, x0:x1].reshape(-1, len(centres))
        m, se = px.mean(axis=0), px.std(axis=0, ddof=1) / math.sqrt(px.shape[0])
        e = np.array([_box_mean(knots, lo, hi) for lo, hi in edges])
        z = (m - e) / se
        k = int(np.argmax(np.abs(z)))
        regions.append({"probe": "lambert patches", "region": name, "check": f"bands lambert patches: {name}",
                        "measured": m.tolist(), "se": se.tolist(), "expected": e.tolist(), "z": z.tolist(),
                        "pass": bool(np.all(np.abs(z) <= z_crit)),
                        "worst": {"band_nm": edges[k], "relative": float(m[k] / e[k] - 1), "z": float(z[k])}})
    return {"model": "box", "source": "declared", "centres_nm": [float(c) for c in centres], "edges_nm": edges,
            "preview": "spectral_preview.exr", "regions": regions, "threshold": threshold, "alpha": ALPHA}


def spectral_run(out):
    """``out`` made a run folder with one spectral job (module doc); returns the job's folder."""
    from spectral_bench.batch import exr, spectral_exr
    out = Path(out)
    job = out / "patches" / "results" / "toy_spectral"
    job.mkdir(parents=True)
    xml, rendered = job / "scene.xml", job / "pass0.exr"
    xml.write_text(scene_xml())
    subprocess.run([sys.executable, str(TOY), str(xml), "--out", str(rendered), "--spp", str(SPP), "--seed", "0",
                    "--format", "spectral"], check=True, timeout=600, cwd=ROOT)
    img = spectral_exr.read(rendered)
    cube = img.stokes[0]
    spectral_exr.write(job / "spectral_preview.exr", img.wavelengths_nm, cube, rgb_preview=False, dtype=np.float16)
    cube = spectral_exr.read(job / "spectral_preview.exr").stokes[0]  # the record is of what the page shows
    exr.write(job / "render.exr", spectral_exr.to_rgb(img)[1])
    record = bands_record(img.wavelengths_nm, cube)
    probes = [{"name": r["check"], "pass": r["pass"], "unit": "", "error": None} for r in record["regions"]]
    status = "ok" if all(p["pass"] for p in probes) else "failed"
    write_hand_made_metrics(out, {"started": "fixture", "runs": [{
        "scene": "patches", "backend": "toy_spectral", "status": status, "image": str((job / "render.exr").relative_to(out)),
        "resolution": [W, H], "spp": SPP, "probes": probes, "bands": record,
        "reason": "; ".join(r["check"] for r in record["regions"] if not r["pass"])}]})
    return job


if __name__ == "__main__":  # python tests/spectral_fixture.py OUT: the folder, to look at its report
    print(json.dumps(str(spectral_run(sys.argv[1]))))
