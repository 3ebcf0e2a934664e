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
  channel_scale=1.01,1,0.99   R, G and B each times its own factor (output)
  offset=0.001       a constant added to R, G and B (output)
  srgb=missing       the sRGB decode applied to the linear output (output)
  gamma=2.2          the power 1/2.2 applied to the output (sign kept; output)
  space=SRC>DST      linear RGB converted from colour space SRC to DST (colour-science names,
                     XYZ for CIE XYZ; output)
  bgr=yes            red and blue swapped; transpose=yes: rows and columns swapped (output)
  clamp=0.5          the intensity channels cut at 0.5 (output)
  s3=flip            S3 of every colour negated; depolarise=yes: S1..S3 set to 0 (output)
  zoom=1.05          the sensor's fov narrowed so the image is magnified 1.05 times (scene)
  shift=0.5,0        the principal point moved by (dx, dy) pixels (scene)
  beckmann=yes       GGX distributions rendered as Beckmann (scene)
  no_k=yes           a named conductor's k dropped, its eta kept (scene)
  ior=1.55           every plain dielectric's int_ior (scene)
  dispersion=none    the dispersive dielectric as one IOR, its n at the d line (scene)
  film=600           the thin film's thickness in nm, 0: no film (scene)
  fluorescence=dropped  the fluorescent diffuse rendered as its plain reflectance (scene)
  correlated=0.5     each pass the mix 0.5 x a render of one fixed seed + 0.5 x its own: passes
                     that share half their noise, so their spread under-reports the standard error
  wl_shift=2         (--format spectral) every spectrum evaluated 2 nm longer: the bands written
                     labelled 2 nm shorter than rendered

--format spectral writes the example renderer's 5 nm box bands (a spectral EXR); --format stokes renders with Mitsuba's polarised spectral variant (stokes_mono: the monochrome
one, for a scene of flat spectra, as the references of such scenes are made) and writes R, G, B
and S0.R ... S3.B (the benchmark's RGB layout with Stokes channels); the film and the camera
polariser the export asks for (camera_filter.json beside the scene) are read as the benchmark's
Mitsuba backend reads them.

    python tests/plant_renderer.py scene.xml --out pass.exr --spp 16 --seed 0 --plant flip=y
"""
import argparse
import os
import re
import sys
from pathlib import Path

import numpy as np
import OpenEXR

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "examples" / "your_renderer"))
sys.path.insert(0, str(HERE))
import render_cache  # noqa: E402 - with SPECTRAL_BENCH_TEST_RENDER_CACHE set, each base render is made once
import toy_renderer  # noqa: E402

VERSION = "plant_renderer 1.0"
OUTPUT = ("scale", "channel_scale", "offset", "srgb", "gamma", "space", "bgr", "flip", "transpose", "clamp", "emitter",
          "stokes_rotate", "s3", "depolarise", "stain")
SCENE = ("alpha", "zoom", "shift", "beckmann", "no_k", "ior", "dispersion", "film", "fluorescence")
PLANTS = OUTPUT + SCENE + ("polariser", "correlated", "wl_shift")
SHARED_SEED = 999_983  # the seed every pass of a correlated plant shares


def parse_plant(text):
    name, sep, value = text.partition("=")
    if not sep or name not in PLANTS:
        raise argparse.ArgumentTypeError(f"--plant {text!r}: expected MODEL=VALUE with MODEL one of {', '.join(PLANTS)}")
    return name, value


def _sub(text, pattern, repl, what, xml):
    text, n = re.subn(pattern, repl, text)
    if not n:
        raise SystemExit(f"plant_renderer: {xml} has no {what} to plant")
    return text


def _project():
    sys.path.insert(0, str(HERE.parent))
    import pkg_bootstrap
    pkg_bootstrap.package()


def plant_scene(xml, plants):
    """A copy of the scene file (beside it: spectra and meshes resolve) with the scene plants
    applied, or ``xml`` itself when there are none."""
    todo = {k: v for k, v in plants.items() if k in SCENE}
    if not todo:
        return xml
    text = Path(xml).read_text()
    for name, value in todo.items():
        if name == "alpha":
            text = _sub(text, r'(<float name="alpha" value=")[^"]*(")', lambda m: f"{m.group(1)}{float(value)!r}{m.group(2)}",
                        "alpha", xml)
        elif name == "beckmann":
            text = _sub(text, r'(<string name="distribution" value=")ggx(")', r"\1beckmann\2", "GGX distribution", xml)
        elif name == "no_k":
            _project()
            from spectral_bench.exporters import spectra

            def eta_only(m):
                eta, _k = spectra.named_conductor(m.group(1))
                pairs = ", ".join(f"{w:g}:{v:g}" for w, v in zip(eta["wavelengths"], eta["values"]))
                return f'<spectrum name="eta" value="{pairs}" />\n      <spectrum name="k" value="0.0" />'
            text = _sub(text, r'<string name="material" value="([A-Za-z0-9_-]+)" />', eta_only, "named conductor", xml)
        elif name == "ior":
            text = _sub(text, r'(<bsdf type="dielectric">\s*<float name="int_ior" value=")[^"]*(")',
                        lambda m: f"{m.group(1)}{float(value)!r}{m.group(2)}", "plain dielectric", xml)
        elif name == "dispersion":
            text = _sub(text, r'(?s)<bsdf type="sb_dispersive_dielectric">.*?</bsdf>', _one_ior, "dispersive dielectric", xml)
        elif name == "film":
            text = _sub(text, r'(<float name="film_thickness" value=")[^"]*(")',
                        lambda m: f"{m.group(1)}{float(value)!r}{m.group(2)}", "thin film", xml)
        elif name == "fluorescence":
            text = _sub(text, r'(?s)<bsdf type="sb_fluorescent_diffuse">(.*?)\s*<string name="reradiation"[^>]*/>',
                        r'<bsdf type="diffuse">\1', "fluorescent diffuse", xml)
        elif name == "zoom":
            def narrower(m):
                import math
                fov = math.degrees(2 * math.atan(math.tan(math.radians(float(m.group(2))) / 2) / float(value)))
                return f"{m.group(1)}{fov!r}{m.group(3)}"
            text = _sub(text, r'(<float name="fov" value=")([^"]*)(")', narrower, "fov", xml)
        elif name == "shift":
            dx, dy = (float(v) for v in value.split(","))
            w = int(re.search(r'<integer name="width" value="(\d+)"', text).group(1))
            h = int(re.search(r'<integer name="height" value="(\d+)"', text).group(1))
            text = _sub(text, r'(<sensor type="perspective">)',
                        lambda m: f'{m.group(1)}\n    <float name="principal_point_offset_x" value="{dx / w!r}" />'
                                  f'\n    <float name="principal_point_offset_y" value="{dy / h!r}" />', "perspective sensor", xml)
    out = Path(xml).parent / f".plant_{os.getpid()}.xml"
    out.write_text(text)
    return out


def _one_ior(m):
    """The dispersive dielectric's block as a one-term Sellmeier of its n at the d line (exact: B1 = n^2 - 1)."""
    block = m.group(0)
    coef = {k: float(v) for k, v in re.findall(r'<float name="([BC][123])" value="([^"]*)"', block)}
    lam2 = (587.5618 / 1000) ** 2
    n2 = 1 + sum(coef.get(f"B{i}", 0.0) * lam2 / (lam2 - coef.get(f"C{i}", 0.0)) for i in (1, 2, 3))
    for i in (1, 2, 3):
        block = re.sub(rf'(<float name="B{i}" value=")[^"]*(")', lambda mm: f"{mm.group(1)}{(n2 - 1) if i == 1 else 0.0!r}{mm.group(2)}", block)
        block = re.sub(rf'(<float name="C{i}" value=")[^"]*(")', lambda mm: f"{mm.group(1)}0.0{mm.group(2)}", block)
    return block


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
    _project()
    from spectral_bench.batch.backends.mitsuba.backend import film_to_ir
    from spectral_bench.exporters import camera_filter
    names, img = film_to_ir(names, img, Path(export_dir) / ".no_camera_filter")
    spec = camera_filter.read(export_dir)
    if not spec:
        return names, img
    spec = dict(spec, ideal_linear_polarizer_deg=angle_of(spec["ideal_linear_polarizer_deg"]))
    names, out = camera_filter.apply(spec, names, img[None])
    return list(names), out[0]


def _colour_channels(names):
    return [names.index(c) for c in "RGB"]


def plant_output(names, img, plants):
    for name, value in plants:
        if name == "scale":
            img = img * float(value)
        elif name == "emitter":
            img = img * (np.pi if value == "pi" else float(value))
        elif name == "srgb" and value == "applied":
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
        elif name == "channel_scale":
            f = np.ones(img.shape[-1])
            for i, v in zip(_colour_channels(names), value.split(",")):
                f[i] = float(v)
            img = img * f
        elif name == "offset":
            img = img.copy()
            img[..., _colour_channels(names)] += float(value)
        elif name == "srgb" and value == "missing":
            a = np.abs(img)
            img = np.sign(img) * np.where(a <= 0.04045, a / 12.92, np.power((a + 0.055) / 1.055, 2.4))
        elif name == "gamma":
            img = np.sign(img) * np.power(np.abs(img), 1 / float(value))
        elif name == "space":
            import colour
            src, dst = value.split(">")
            if src == "XYZ":
                m = colour.RGB_COLOURSPACES[dst].matrix_XYZ_to_RGB
            elif dst == "XYZ":
                m = colour.RGB_COLOURSPACES[src].matrix_RGB_to_XYZ
            else:
                m = colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES[src], colour.RGB_COLOURSPACES[dst])
            img = img.copy()
            idx = _colour_channels(names)
            img[..., idx] = img[..., idx] @ np.asarray(m, dtype=np.float64).T
        elif name == "bgr":
            img = img.copy()
            img[..., [names.index("R"), names.index("B")]] = img[..., [names.index("B"), names.index("R")]]
        elif name == "transpose":
            img = np.swapaxes(img, 0, 1)
        elif name == "clamp":
            img = img.copy()
            idx = [i for i, n in enumerate(names) if n in "RGB" or n.startswith("S0.")]
            img[..., idx] = np.minimum(img[..., idx], float(value))
        elif name == "s3":
            img = img.copy()
            for colour_ in "RGB":
                img[..., names.index(f"S3.{colour_}")] *= -1
        elif name == "depolarise":
            img = img.copy()
            for k in (1, 2, 3):
                for colour_ in "RGB":
                    img[..., names.index(f"S{k}.{colour_}")] = 0.0
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


def render(planted_xml, xml, args, plants, seed):
    """(channel names, image) of one pass; for --format spectral (None, (band centres, bands)).
    The project's Python plugins the export carries (load_plugins.py beside the scene) are
    registered first, as the benchmark's Mitsuba backend does."""
    import mitsuba as mi
    kind = {"stokes": "spectral_polarized", "stokes_mono": "mono_polarized"}.get(args.format, "spectral")
    toy_renderer.set_variant(mi, kind)
    _project()
    from spectral_bench.exporters import mitsuba_plugins
    mitsuba_plugins.register_exported(xml.parent)
    if args.format.startswith("stokes"):
        kind = "mono_polarized" if args.format == "stokes_mono" else "spectral_polarized"
        names, img = render_stokes(planted_xml, args.spp, seed, kind)
        other = plants.get("polariser") == "other"
        return polarise(names, img, xml.parent, (lambda a: 90.0 - a) if other else (lambda a: a))
    if args.format == "spectral":
        return None, toy_renderer.render_bands(str(planted_xml), args.spp, seed)
    if args.film == "cmf":
        return list("RGB"), render_cmf(planted_xml, args.spp, seed)
    return list("RGB"), toy_renderer.render_rgb(str(planted_xml), args.spp, seed)


def render_cmf(scene_xml, spp, seed):
    """Linear sRGB through the benchmark's CMF film (the references' own: X, Y, Z against the 1 nm
    CIE 1931 CMFs, batch/backends/mitsuba/spectral.py): a correct render then differs from the
    reference by noise alone, where Mitsuba's RGB film is 0.1 % bright."""
    import mitsuba as mi
    from spectral_bench.batch.backends.mitsuba import spectral
    text = spectral.cmf_xml(Path(scene_xml).read_text(), str(scene_xml))
    tmp = Path(scene_xml).parent / f".cmf_{os.getpid()}.xml"
    tmp.write_text(text)
    try:
        scene = mi.load_file(str(tmp))
    finally:
        tmp.unlink()
    img = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)
    return spectral.cmf_to_srgb(img[..., :3])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?")
    ap.add_argument("--out")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--format", choices=("rgb", "spectral", "stokes", "stokes_mono"), default="rgb")
    ap.add_argument("--film", choices=("mitsuba", "cmf"), default="mitsuba",
                    help="rgb format: Mitsuba's RGB film, or the CMF film the references are made with")
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
    planted_xml = plant_scene(xml, plants)
    def base(seed):  # the render the output plants start from: the same for every renderer of that scene and seed
        return render_cache.memo(lambda: render(planted_xml, xml, args, plants, seed), planted_xml,
                                 args.format, args.film, args.spp, seed, plants.get("polariser"))
    try:
        names, img = base(args.seed)
        if "correlated" in plants:  # passes that share part of their noise
            a = float(plants["correlated"])
            img = a * base(SHARED_SEED)[1] + (1 - a) * img
    finally:
        if planted_xml != xml:
            planted_xml.unlink()
    if args.format == "spectral":
        centres, img = img
        toy_renderer.write_spectral(args.out, centres - float(plants.get("wl_shift", 0.0)), img)
        return 0
    write(args.out, names, plant_output(names, img, args.plant))
    return 0


if __name__ == "__main__":
    sys.exit(main())
