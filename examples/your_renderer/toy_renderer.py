#!/usr/bin/env python3
"""A stand-alone "your renderer" for the benchmark's declared-renderer contract (docs/backends.md, "Add your
renderer"). It imports nothing from the benchmark: it reads the scene the benchmark exported for it
(here the Mitsuba 3 XML: ``reads = "mitsuba"``), renders one pass with the seed and samples it is
given, and writes the EXR the benchmark reads back:

  --format rgb       channels R, G, B: linear sRGB (D65 white), CIE 1931 2-degree observer, in the
                     scene's radiance units
  --format spectral  the spectral OpenEXR layout of Fichet, Pacanowski and Wilkie (JCGT 10(3),
                     2021): one channel per wavelength band, "S0.<nm with a comma>nm", with the
                     header attributes spectralLayoutVersion = "1.0" and emissiveUnits =
                     "W.m^-2.sr^-1"; the benchmark integrates the bands with the observer

The rendering itself is Mitsuba 3 (the ``mitsuba`` Python package) standing in for a renderer of
your own: replace ``render_rgb`` / ``render_bands`` with your renderer and keep the rest.
``--gain`` multiplies the image: a way to see the benchmark catch a renderer that is 1 % too
bright (tests/backends/test_declared_renderer.py does exactly that). ``--band-swap NM`` makes the spectral
output 2 % brighter in the band holding NM and 2 % darker in the next: a metamer, the same R, G, B
within noise, which only the benchmark's band checks see (tests/verdict/test_bands.py).

    python toy_renderer.py scene.xml --out pass.exr --spp 64 --seed 0 [--format spectral] [--gain 1.0]
                           [--band-swap NM]
    python toy_renderer.py --version
"""
import argparse
import os
import sys

import numpy as np
import OpenEXR

VERSION = "toy_renderer 1.0"
# libLLVM for Mitsuba's JIT variants (Debian/Ubuntu: apt-get install libllvm19); scalar otherwise
LLVM = ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", "/usr/lib/llvm-19/lib/libLLVM.so",
        "/usr/lib/aarch64-linux-gnu/libLLVM-19.so")
BAND_NM = 5.0                      # spectral output: 5 nm bands over Mitsuba's 360-830 nm
FIRST_NM, LAST_NM = 360.0, 830.0


def set_variant(mi, kind):
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        for path in LLVM:
            if os.path.exists(path):
                os.environ["DRJIT_LIBLLVM_PATH"] = path
                break
    for variant in (f"llvm_ad_{kind}", f"scalar_{kind}"):
        try:
            mi.set_variant(variant)
            return variant
        except Exception:  # noqa: BLE001 - a variant this build or machine cannot run: try the next
            continue
    raise SystemExit(f"toy_renderer: no Mitsuba variant for {kind}")


def render_rgb(scene_xml, spp, seed):
    """H x W x 3 linear sRGB."""
    import mitsuba as mi
    set_variant(mi, "spectral")
    scene = mi.load_file(scene_xml)
    return np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)[..., :3]


def render_bands(scene_xml, spp, seed):
    """(band centres in nm, H x W x N spectral radiance): the scene's film replaced by Mitsuba's
    specfilm with one box band per channel, of height 1 / width: a channel is the band's mean
    radiance."""
    import xml.etree.ElementTree as ET
    import mitsuba as mi
    set_variant(mi, "spectral")
    centres = np.arange(FIRST_NM + BAND_NM / 2, LAST_NM, BAND_NM)
    tree = ET.parse(scene_xml)
    film = tree.getroot().find("sensor/film")
    film.set("type", "specfilm")
    for child in list(film):
        if child.get("name") == "pixel_format":
            film.remove(child)
    for i, c in enumerate(centres):
        lo, hi, h = c - BAND_NM / 2, c + BAND_NM / 2, 1 / BAND_NM
        ET.SubElement(film, "spectrum", name=f"band{i:03d}",
                      value=f"{lo - 1e-3}:0, {lo}:{h}, {hi}:{h}, {hi + 1e-3}:0")
    spectral_xml = os.path.join(os.path.dirname(os.path.abspath(scene_xml)), f".specfilm_{os.getpid()}.xml")
    tree.write(spectral_xml)
    try:
        scene = mi.load_file(spectral_xml)
    finally:
        os.unlink(spectral_xml)
    img = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)
    return centres, img[..., :len(centres)]


def write_rgb(path, img):
    channels = {c: np.ascontiguousarray(img[..., i], dtype=np.float32) for i, c in enumerate("RGB")}
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, channels) as f:
        f.write(path)


def write_spectral(path, centres, img):
    """The Fichet 2021 layout: emissive channels S0.<wavelength>nm, comma as decimal separator."""
    channels = {f"S0.{c:.6f}".replace(".", ",").replace("S0,", "S0.") + "nm": np.ascontiguousarray(img[..., i], dtype=np.float32)
                for i, c in enumerate(centres)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "spectralLayoutVersion": "1.0", "emissiveUnits": "W.m^-2.sr^-1"}
    with OpenEXR.File(header, channels) as f:
        f.write(path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?")
    ap.add_argument("--out")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--format", choices=("rgb", "spectral"), default="rgb")
    ap.add_argument("--gain", type=float, default=1.0)
    ap.add_argument("--band-swap", type=float, metavar="NM",
                    help="spectral output: the band holding NM 2 %% brighter and the next one 2 %% darker (a metamer)")
    ap.add_argument("--version", action="store_true")
    args = ap.parse_args(argv)
    if args.version:
        print(VERSION)
        return 0
    if not args.scene or not args.out:
        ap.error("scene and --out are required")
    if args.format == "rgb":
        write_rgb(args.out, render_rgb(args.scene, args.spp, args.seed) * args.gain)
    else:
        centres, img = render_bands(args.scene, args.spp, args.seed)
        if args.band_swap is not None:
            k = int(np.argmin(np.abs(centres - args.band_swap)))
            img[..., k] *= 1.02
            img[..., k + 1] *= 0.98
        write_spectral(args.out, centres, img * args.gain)
    return 0


if __name__ == "__main__":
    sys.exit(main())
