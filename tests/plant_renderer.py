#!/usr/bin/env python3
"""A declared renderer with planted errors (issue 34: the diagnosis calibrated by planting): the
example renderer of examples/your_renderer/ (Mitsuba 3 behind a command line), plus Stokes output
and ``--plant MODEL=VALUE`` applying one catalogue error to the scene it renders or to its output:

  scale=1.03         every pixel times 1.03 (output)
  srgb=applied       the sRGB transfer curve applied to the linear output
  flip=y | flip=x    the image flipped vertically / horizontally
  alpha=0.22         every GGX/Beckmann alpha in the scene set to 0.22 (scene)
  emitter=pi         emitted radiance times pi: the output times pi, which is the same image for a
                     scene lit by its emitters alone (the copper scenes; output)
  polariser=other    the camera polariser's angle measured from the other axis: 90 - declared
                     (applied to the rendered Stokes vector like the benchmark's ideal polariser)
  stokes_rotate=90   the Stokes frame turned by 90 degrees (S1, S2 of every colour rotated; output)
  stain=0.2          a checkerboard stain (outside every model): 0.2 times the image's mean added
                     to alternate 4 x 4 pixel squares of the image's central quarter

--format stokes renders with Mitsuba's polarised spectral variant (stokes_mono: the monochrome
one, for a scene of flat spectra, as the references of such scenes are made) and writes R, G, B
and S0.R ... S3.B (the benchmark's RGB layout with Stokes channels); the film and the camera
polariser the export asks for (camera_filter.json beside the scene) are read as the benchmark's
Mitsuba backend reads them.

    python tests/plant_renderer.py scene.xml --out pass.exr --spp 16 --seed 0 --plant flip=y
"""
import argparse
import json
import os
import re
import sys
from pathlib import Path

import numpy as np
import OpenEXR

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "examples" / "your_renderer"))
import toy_renderer  # noqa: E402

VERSION = "plant_renderer 1.0"
PLANTS = ("scale", "srgb", "flip", "alpha", "emitter", "polariser", "stokes_rotate", "stain")


def parse_plant(text):
    name, sep, value = text.partition("=")
    if not sep or name not in PLANTS:
        raise argparse.ArgumentTypeError(f"--plant {text!r}: expected MODEL=VALUE with MODEL one of {', '.join(PLANTS)}")
    return name, value


def scene_with_alpha(xml, alpha):
    """A copy of the scene file with every microfacet alpha set to ``alpha`` (beside it: spectra and
    meshes resolve)."""
    text = Path(xml).read_text()
    text, n = re.subn(r'(<float name="alpha" value=")[^"]*(")', lambda m: f"{m.group(1)}{alpha!r}{m.group(2)}", text)
    if not n:
        raise SystemExit(f"plant_renderer: {xml} has no alpha to plant")
    out = Path(xml).parent / f".plant_{os.getpid()}.xml"
    out.write_text(text)
    return out


def render_stokes(scene_xml, spp, seed, kind):
    """(channel names, H x W x C) of Mitsuba's polarised variant ``kind`` (spectral_polarized, or
    mono_polarized for a scene of flat spectra: Y and S0..S3)."""
    import mitsuba as mi
    toy_renderer.set_variant(mi, kind)
    scene = mi.load_file(str(scene_xml))
    img = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)
    bitmap = scene.sensors()[0].film().bitmap()
    names = [bitmap.struct_()[i].name for i in range(bitmap.channel_count())]
    names = [n for n in names if n not in ("A", "W")]
    return names, img[..., :len(names)]


def polarise(names, img, export_dir, angle_of):
    """The film's channels as the benchmark's Mitsuba backend reads them (a monochrome Y as RGB:
    batch/backends/mitsuba/backend.py film_to_ir), then the ideal camera polariser
    (exporters/camera_filter.py) with its angle mapped by ``angle_of``."""
    sys.path.insert(0, str(HERE.parent))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch.backends.mitsuba.backend import film_to_ir
    from spectral_bench.exporters import camera_filter
    names, img = film_to_ir(names, img, Path(export_dir) / ".no_camera_filter")
    spec = camera_filter.read(export_dir)
    if not spec:
        return names, img
    spec = dict(spec, ideal_linear_polarizer_deg=angle_of(spec["ideal_linear_polarizer_deg"]))
    names, out = camera_filter.apply(spec, names, img[None])
    return list(names), out[0]


def plant_output(names, img, plants):
    for name, value in plants:
        if name == "scale":
            img = img * float(value)
        elif name == "emitter":
            img = img * (np.pi if value == "pi" else float(value))
        elif name == "srgb":
            a = np.abs(img)
            img = np.sign(img) * np.where(a <= 0.0031308, 12.92 * a, 1.055 * np.power(a, 1 / 2.4) - 0.055)
        elif name == "flip":
            img = np.flip(img, axis={"y": 0, "x": 1}[value])
        elif name == "stokes_rotate":
            c, s = np.cos(np.radians(2 * float(value))), np.sin(np.radians(2 * float(value)))
            img = img.copy()
            for colour in "RGB":
                i1, i2 = names.index(f"S1.{colour}"), names.index(f"S2.{colour}")
                s1, s2 = img[..., i1].copy(), img[..., i2].copy()
                img[..., i1], img[..., i2] = c * s1 + s * s2, -s * s1 + c * s2
        elif name == "stain":
            h, w = img.shape[:2]
            yy, xx = np.mgrid[0:h, 0:w]
            board = ((yy // 4 + xx // 4) % 2 == 0) & (abs(yy - h / 2) < h / 4) & (abs(xx - w / 2) < w / 4)
            img = img + board[..., None] * float(value) * float(np.mean(img[..., :3]))
    return img


def write(path, names, img):
    channels = {n: np.ascontiguousarray(img[..., i], dtype=np.float32) for i, n in enumerate(names)}
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as f:
        f.write(path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?")
    ap.add_argument("--out")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--format", choices=("rgb", "stokes", "stokes_mono"), default="rgb")
    ap.add_argument("--plant", type=parse_plant, action="append", default=[])
    ap.add_argument("--version", action="store_true")
    args = ap.parse_args(argv)
    if args.version:
        print(VERSION)
        return 0
    if not args.scene or not args.out:
        ap.error("scene and --out are required")
    plants = dict(args.plant)
    xml = Path(args.scene)
    planted_xml = scene_with_alpha(xml, float(plants["alpha"])) if "alpha" in plants else xml
    try:
        if args.format.startswith("stokes"):
            kind = "mono_polarized" if args.format == "stokes_mono" else "spectral_polarized"
            names, img = render_stokes(planted_xml, args.spp, args.seed, kind)
            other = plants.get("polariser") == "other"
            names, img = polarise(names, img, xml.parent, (lambda a: 90.0 - a) if other else (lambda a: a))
        else:
            names, img = list("RGB"), toy_renderer.render_rgb(str(planted_xml), args.spp, args.seed)
    finally:
        if planted_xml != xml:
            planted_xml.unlink()
    write(args.out, names, plant_output(names, img, args.plant))
    return 0


if __name__ == "__main__":
    sys.exit(main())
