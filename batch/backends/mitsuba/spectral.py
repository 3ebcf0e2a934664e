"""Mitsuba 3 renders an exported scene.xml as a spectral image: Mitsuba 3.9.1's ``specfilm``
with box bands, written in the spectral OpenEXR layout of Fichet et al. 2021 (batch/spectral_exr.py).

    render(xml_path, out_exr, spp, seed)      # one pass, in a child process (this file as a script)

The exported film (hdrfilm, exporters/mitsuba_writer.py) is replaced by a specfilm of the same
size and reconstruction filter whose sensor response functions are boxes of ``band_nm`` over
``range_nm`` (default 10 nm over 360-830 nm, Mitsuba's spectral range: 47 bands). specfilm
(src/films/specfilm.cpp) samples wavelengths in proportion to the sum of the responses and stores
in each channel an estimate of the integral of the radiance times that band's response, so a box
of height 1 gives the integral over the band: divided by the band width it is the band average,
stored at the band centre (measured on a constant environment: every band within 1.8 standard
errors of the integral, benchmarks/SPECTRAL_EXR.md).

specfilm records unpolarised radiance only (Film::prepare_sample takes an UnpolarizedSpectrum),
so scenes that need polarisation (a polarised variant, the stokes integrator, a camera polariser)
are refused; a mono or RGB variant is replaced by its spectral twin.
"""
import argparse
import json
import math
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

BAND_NM = 10.0
RANGE_NM = (360.0, 830.0)  # Mitsuba 3's MI_CIE_MIN, MI_CIE_MAX
MAX_WAVEFRONT = 1 << 24  # samples per render call on the LLVM variants (as mitsuba/worker.py)
# the film parameters specfilm shares with hdrfilm (src/films/specfilm.cpp); the rest are dropped
FILM_KEEP = {"width", "height", "crop_offset_x", "crop_offset_y", "crop_width", "crop_height", "sample_border"}
HERE = Path(__file__).resolve()


class SpectralRenderError(RuntimeError):
    pass


def bands(band_nm=BAND_NM, range_nm=RANGE_NM):
    """[(lo, hi)] of the box bands tiling range_nm (the last one ends at range_nm[1])."""
    lo, hi = map(float, range_nm)
    count = math.ceil((hi - lo) / band_nm - 1e-9)
    if not (band_nm > 0 and hi > lo and count >= 2):
        raise ValueError(f"bands of {band_nm} nm over {lo}-{hi} nm: need at least 2")
    edges = [min(lo + band_nm * k, hi) for k in range(count + 1)]
    return list(zip(edges[:-1], edges[1:]))


def band_name(k):
    return f"band_{k:03d}"  # zero-padded: specfilm may order its channels by name


def spectral_variant(variant):
    """The spectral twin of a variant (llvm_ad_rgb -> llvm_ad_spectral); polarised ones refused."""
    if variant.endswith("_polarized"):
        raise SpectralRenderError(f"variant {variant}: specfilm records unpolarised radiance only "
                                  "(Film::prepare_sample takes an UnpolarizedSpectrum); a polarised scene has no spectral output here")
    prefix = variant.split("_ad_", 1)[0] + "_ad_" if "_ad_" in variant else "scalar_"  # llvm_ad_, cuda_ad_
    return prefix + "spectral"


def spectral_xml(xml_text, band_list, where="scene.xml"):
    """The scene XML with its sensor's film replaced by a specfilm of box bands ``band_list``."""
    return specfilm_xml(xml_text, [(band_name(k), (lo, hi), (1.0, 1.0)) for k, (lo, hi) in enumerate(band_list)], where)


# -- the IR's colour as a film (issue 33): three channels whose responses are the CIE 1931 2 degree
# colour-matching functions at 1 nm (exporters/data, colour-science's table), so each channel is
# the integral of L times x_bar, y_bar or z_bar, linearly interpolated between the 1 nm samples:
# the trapezoid rule of exporters/colorimetry.py exactly. Divided by the integral of y_bar (a flat
# spectrum of 1 has Y = 1) and mapped to linear sRGB by the IEC 61966-2-1 matrix, it is the colour
# docs/scene-format.md defines, without Mitsuba's 5 nm tables or its rounded matrix.
CMF_CHANNELS = ("X", "Y", "Z")
CMF_FILM = "specfilm, CIE 1931 2 degree CMFs at 1 nm (exporters/data/cie_1931_2deg_cmfs.json), IEC 61966-2-1 matrix"


def cmf_xml(xml_text, where="scene.xml"):
    """The scene XML with its film replaced by the X, Y, Z specfilm of the IR's observer."""
    return observers_xml(xml_text, (), where)


# -- observer layers (issue 33): beside the IR's X, Y, Z, the same paths seen through the CMFs of
# other observers (exporters/colorimetry.py: how a renderer's film integrates spectra, named by a
# recorded deviation), channels "<observer>_X", "_Y", "_Z". film_to_ir (backend.py) turns each
# triple into the difference of that observer's RGB from the IR's, per pass: a reference keeps those
# differences (batch/verdict/observer_layers.py) so that a render through another film can be
# re-judged against the reference as that film would have seen it.
LAYER_SEP = "_"


NEGATIVE = "n"  # suffix of the channel holding a response's negative part ("<observer>_Xn")


def layer_channels(observers):
    """[(name, wavelengths, response)] of the CMF film plus each observer's three CMFs. specfilm
    takes non-negative responses only: a CMF with negative parts (a box-band film read through its
    histospline, colorimetry.box_weights) is rendered as two channels, its positive part and its
    negative part negated ("<observer>_Xn"), which layers_to_ir subtracts."""
    import numpy as np

    from ....exporters import colorimetry
    out = []
    for obs in (colorimetry.GROUND_TRUTH, *observers):
        wl, xb, yb, zb, _norm, _matrix = colorimetry.film(obs)
        names = CMF_CHANNELS if obs == colorimetry.GROUND_TRUTH else [f"{obs}{LAYER_SEP}{c}" for c in CMF_CHANNELS]
        for n, c in zip(names, (xb, yb, zb)):
            c = np.asarray(c, dtype=np.float64)
            out.append((n, wl, np.maximum(c, 0.0)))
            if obs != colorimetry.GROUND_TRUTH and (c < 0).any():
                out.append((n + NEGATIVE, wl, np.maximum(-c, 0.0)))
    return out


def observers_xml(xml_text, observers, where="scene.xml"):
    """The scene XML with its film replaced by the CMF film plus ``observers``' CMF channels."""
    return specfilm_xml(xml_text, layer_channels(observers), where)


def layers_to_ir(names, img):
    """(names, image): each observer triple "<obs>_X, _Y, _Z" (after the CMF film's channels,
    already R, G, B) replaced by "<obs>.R, .G, .B", that observer's linear sRGB minus the IR's."""
    import numpy as np

    from ....exporters import colorimetry
    names, img = list(names), np.asarray(img, dtype=np.float64)
    index = {n: i for i, n in enumerate(names)}
    keep, layers = [], []
    for i, n in enumerate(names):
        obs, sep, c = n.rpartition(LAYER_SEP)
        if not (sep and obs in colorimetry.OBSERVERS):
            keep.append(i)
            continue
        if c != "X":
            continue  # the observer's other channels, taken with its X
        xyz = np.stack([img[..., index[f"{obs}{LAYER_SEP}{k}"]]
                        - (img[..., index[f"{obs}{LAYER_SEP}{k}{NEGATIVE}"]] if f"{obs}{LAYER_SEP}{k}{NEGATIVE}" in index else 0.0)
                        for k in CMF_CHANNELS], axis=-1)
        norm, matrix = colorimetry.film(obs)[4:]
        layers.append(([f"{obs}.{k}" for k in "RGB"], xyz / norm @ np.asarray(matrix).T - img[..., :3]))
    out_names = [names[i] for i in keep] + [n for ns, _ in layers for n in ns]
    return out_names, np.concatenate([img[..., keep]] + [d for _, d in layers], axis=-1)


def cmf_to_srgb(img):
    """A CMF film's X, Y, Z channels (integrals against the 1 nm CMFs) as the IR's linear sRGB."""
    import numpy as np

    from ....exporters import colorimetry
    norm = colorimetry.observer(colorimetry.GROUND_TRUTH)[4]
    return np.asarray(colorimetry.xyz_to_srgb(np.asarray(img, dtype=np.float64) / norm))


def specfilm_xml(xml_text, channels, where="scene.xml"):
    """The scene XML with its sensor's film replaced by a specfilm whose channels are ``channels``
    [(name, wavelengths, response values)], each response an irregular (piecewise-linear) spectrum."""
    root = ET.fromstring(xml_text)
    integrator = root.find("integrator")
    if integrator is not None and integrator.get("type") == "stokes":
        raise SpectralRenderError(f"{where}: the stokes integrator (a polarised scene): specfilm records unpolarised radiance only")
    films = root.findall("sensor/film")
    if len(films) != 1:
        raise SpectralRenderError(f"{where}: expected one <sensor><film>, found {len(films)}")
    film = films[0]
    for child in list(film):
        if child.tag != "rfilter" and child.get("name") not in FILM_KEEP:
            film.remove(child)
    film.set("type", "specfilm")
    ET.SubElement(film, "string", name="component_format", value="float32")
    for name, wavelengths, values in channels:
        srf = ET.SubElement(film, "spectrum", type="irregular", name=name)
        ET.SubElement(srf, "string", name="wavelengths", value=", ".join(repr(float(w)) for w in wavelengths))
        ET.SubElement(srf, "string", name="values", value=", ".join(repr(float(v)) for v in values))
    return ET.tostring(root, encoding="unicode")


def render(xml_path, out_exr, spp, seed=0, variant=None, band_nm=BAND_NM, range_nm=RANGE_NM, timeout=1800,
           log_path=None):
    """Render one pass of ``xml_path`` (an exported Mitsuba scene) into the Fichet 2021 EXR
    ``out_exr`` in a child process; returns its record (variant, spp, seed, time_s, bands,
    versions). ``variant``: a Mitsuba variant whose spectral twin renders (default
    llvm_ad_spectral where LLVM works, else scalar_spectral)."""
    import subprocess

    from .. import child

    from . import llvm
    xml_path = Path(xml_path)
    if (xml_path.parent / "camera_filter.json").is_file():
        raise SpectralRenderError(f"{xml_path.parent / 'camera_filter.json'}: a camera polariser needs Stokes output; "
                                  "specfilm records unpolarised radiance only")
    variant = spectral_variant(variant or ("llvm_ad_spectral" if llvm.find()[0] else "scalar_spectral"))
    result = Path(out_exr).with_suffix(".result.json")
    cmd = [sys.executable, str(HERE), "--xml", str(xml_path), "--out", str(out_exr), "--result", str(result),
           "--spp", str(int(spp)), "--seed", str(int(seed)), "--variant", variant, "--band-nm", repr(float(band_nm)),
           "--range-nm", repr(float(range_nm[0])), repr(float(range_nm[1]))]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=llvm.env(), **child.popen_kwargs())
    except subprocess.TimeoutExpired as exc:
        raise SpectralRenderError(f"spectral render of {xml_path} timed out after {timeout} s") from exc
    if log_path:
        Path(log_path).write_text(f"$ {' '.join(cmd)}\n{proc.stdout}\n{proc.stderr}")
    if proc.returncode != 0:
        tail = (proc.stderr.strip() or proc.stdout.strip()).splitlines()[-3:]
        raise SpectralRenderError(f"spectral render of {xml_path} exited with {proc.returncode}: {' | '.join(tail)[-600:]}")
    return json.loads(result.read_text())


def main(argv=None):
    ap = argparse.ArgumentParser(description="Render an exported Mitsuba scene.xml to a Fichet 2021 spectral EXR.")
    ap.add_argument("--xml", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--result", required=True)
    ap.add_argument("--spp", type=int, required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--variant", default="scalar_spectral")
    ap.add_argument("--band-nm", type=float, default=BAND_NM)
    ap.add_argument("--range-nm", type=float, nargs=2, default=RANGE_NM)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    sys.path.insert(0, str(HERE.parents[3]))
    import pkg_bootstrap
    pkg_bootstrap.package()
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    from spectral_bench.batch import spectral_exr
    from spectral_bench.exporters import mitsuba_plugins

    xml = Path(args.xml)
    band_list = bands(args.band_nm, args.range_nm)
    mi.set_variant(args.variant)
    mitsuba_plugins.register_exported(xml.parent)
    mi.Thread.thread().file_resolver().prepend(str(xml.parent.resolve()))  # spectra/*.spd, meshes/
    scene = mi.load_string(spectral_xml(xml.read_text(), band_list, str(xml)))
    film = scene.sensors()[0].film()
    width, height = film.size()
    chunks = max(1, math.ceil(args.spp * width * height / MAX_WAVEFRONT)) if "_ad_" in args.variant else 1
    while args.spp % chunks:
        chunks += 1
    acc, render_s = None, 0.0
    for j in range(chunks):
        t = time.perf_counter()
        img = mi.render(scene, spp=args.spp // chunks, seed=args.seed * chunks + j)
        dr.eval(img)
        arr = np.array(img, dtype=np.float64)
        render_s += time.perf_counter() - t
        acc = arr if acc is None else acc + arr
    acc /= chunks
    bitmap = film.bitmap()
    names = [bitmap.struct_()[i].name for i in range(bitmap.channel_count())]
    names = [n for n in names if n != "W"]
    if len(names) != acc.shape[-1]:
        raise RuntimeError(f"specfilm channels {names[:4]}... do not match the image's {acc.shape[-1]} channels")
    order = [names.index(band_name(k)) for k in range(len(band_list))]
    widths = np.array([hi - lo for lo, hi in band_list])
    centres = np.array([(lo + hi) / 2 for lo, hi in band_list])
    spectral_exr.write(args.out, centres, acc[..., order] / widths)  # band integrals -> band averages
    Path(args.result).write_text(json.dumps({
        "variant": args.variant, "spp": args.spp, "seed": args.seed, "chunks": chunks, "time_s": render_s,
        "wall_s": time.perf_counter() - t0, "resolution": [int(width), int(height)],
        "bands": [[lo, hi] for lo, hi in band_list], "film": "specfilm, box bands",
        "versions": {"mitsuba": mi.__version__, "drjit": dr.__version__}}, indent=1))


if __name__ == "__main__":
    main()
