"""Spectral images in the OpenEXR layout of A. Fichet, R. Pacanowski and A. Wilkie, "An OpenEXR
Layout for Spectral Images", Journal of Computer Graphics Techniques 10(3), 2021
(https://jcgt.org/published/0010/03/01/), which ART and pbrt-v4 write and colour-science reads;
and their colour, integrated as the project defines colour (exporters/colorimetry.py).

The layout (facts from the article and its reference implementation, github.com/afichet/spectral-exr,
lib/EXRSpectralImage.cpp; colour-science's colour/io/fichet2021.py reads the same):
- an emissive spectrum is one channel per wavelength, named ``S<k>.<value><prefix><unit>``: k the
  Stokes component (S0 alone, or S0..S3 for a polarised image), the value with a comma as decimal
  separator (the dot separates OpenEXR layers), an optional exponent (``5,5e2``), an optional SI
  prefix (Y Z E P T G M k h da d c m u n p) and the unit ``m`` (a wavelength) or ``Hz`` (a
  frequency, lambda = c / f): ``S0.555,5nm``, ``S0.0,5555um``, ``S0.539,7THz``;
- a reflective spectrum is ``T.<value><unit>`` and a bi-spectral (re-radiation) one
  ``T.<in>.<out>``; they describe materials, not light;
- header attributes: ``spectralLayoutVersion`` ("1.0"), ``emissiveUnits`` (default, and the only
  unit defined, "W.m^-2.sr^-1"), ``polarisationHandedness`` ("right", the default, or "left"); a
  viewer may add an R, G, B preview, which this reader ignores.

This reader accepts emissive images (S0, or all of S0..S3 on one wavelength set): the benchmark
compares emitted radiance. It refuses what it cannot read faithfully, naming the file and the
channel or attribute (SpectralEXRError). Tolerated beyond the reference implementation: the micro
sign (``um`` written ``µm`` or ``μm``). A left-handed file's S3 is negated, so that S0..S3 are
always in the layout's default, right-handed, convention.

Colour (to_rgb): the spectrum at a pixel is the piecewise-linear interpolation of its samples,
zero outside the sampled range, integrated against an observer's colour-matching functions on
their 1 nm grid (exporters/colorimetry.py hat_weights: one weight per sample and CMF, computed once
per wavelength set), normalised so that a flat spectrum of 1 has Y = 1, then converted to linear
sRGB (IEC 61966-2-1, D65, no adaptation), as exporters/colorimetry.py does for the ground truth.
"""
import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import OpenEXR

from ..exporters import colorimetry
from . import exr

LAYOUT_MAJOR = 1  # spectralLayoutVersion 1.x (Fichet et al. 2021)
LAYOUT_VERSION = "1.0"
EMISSIVE_UNITS = "W.m^-2.sr^-1"
SPEED_OF_LIGHT = 299792458.0  # m/s, exact (SI)
# SI prefixes the layout allows (reference implementation, Util::strToNanometers), as powers of
# ten; µ and μ: the micro sign and the Greek mu, which some writers use for u
PREFIXES = {"Y": 24, "Z": 21, "E": 18, "P": 15, "T": 12, "G": 9, "M": 6, "k": 3, "h": 2, "da": 1, "": 0,
            "d": -1, "c": -2, "m": -3, "u": -6, "\u00b5": -6, "\u03bc": -6, "n": -9, "p": -12}


def _times_ten_to(value, power):
    """value * 10**power with an exact power of ten (10.0**k is exact for 0 <= k <= 22), so that
    '555,5nm' and '0,5555um' read as the same float."""
    return value * 10.0 ** power if power >= 0 else value / 10.0 ** -power


# a quantity (value, power of ten of its prefix) in metres or hertz, in nm
UNITS = {"m": lambda v, p: _times_ten_to(v, p + 9),
         "Hz": lambda v, p: _times_ten_to(SPEED_OF_LIGHT / v, 9 - p)}
_PREFIX = "da|[YZEPTGMkhdcmun\u00b5\u03bcp]"
_QUANTITY = rf"([0-9]*(?:,[0-9]*)?(?:[eE][+-]?[0-9]+)?)({_PREFIX})?(m|Hz)"
EMISSIVE = re.compile(rf"S([0-3])\.{_QUANTITY}")
REFLECTIVE = re.compile(rf"T\.{_QUANTITY}")
BISPECTRAL = re.compile(rf"T\.{_QUANTITY}\.{_QUANTITY}")
# a wavelength written with a dot as decimal separator: an OpenEXR layer separator, not a number
DOTTED = re.compile(rf"(S[0-3]|T)\.[0-9]+\.[0-9]+(?:[eE][+-]?[0-9]+)?(?:{_PREFIX})?(m|Hz)")
HANDEDNESS = {"right": 1.0, "left": -1.0}  # the factor that brings S3 to right-handed


class SpectralEXRError(ValueError):
    """A spectral EXR this reader refuses; the message names the file and channel or attribute."""


@dataclass
class SpectralImage:
    """An emissive spectral image: ``stokes`` {k: H x W x N float64} for k = 0 or 0..3, on the
    ascending ``wavelengths_nm``; the file's attributes as written (None where absent)."""
    path: str
    wavelengths_nm: np.ndarray
    stokes: dict
    units: str = None
    version: str = None
    handedness: str = None
    channels: dict = field(default_factory=dict)  # {k: [channel name per wavelength]}

    @property
    def polarised(self):
        return len(self.stokes) == 4


def _fail(path, what, message):
    raise SpectralEXRError(f"{path}: {what}: {message}")


def quantity_nm(number, prefix, unit):
    """nm of a channel name's quantity: number (comma decimal separator), SI prefix, m or Hz."""
    if not re.search("[0-9]", number):
        raise ValueError("no number")
    value = float(number.replace(",", "."))
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{number}{prefix or ''}{unit} is not a positive quantity")
    nm = UNITS[unit](value, PREFIXES[prefix or ""])
    if not (math.isfinite(nm) and nm > 0):
        raise ValueError(f"{number}{prefix or ''}{unit} is not a finite wavelength")
    return nm


def classify(name):
    """("emissive", k, nm) | ("reflective", None, nm) | ("bispectral", None, (nm_in, nm_out)) |
    ("dotted", None, None) | (None, None, None) for a channel that is not spectral. Raises
    ValueError for a spectral name whose quantity is not a wavelength."""
    m = EMISSIVE.fullmatch(name)
    if m:
        return "emissive", int(m.group(1)), quantity_nm(*m.group(2, 3, 4))
    m = BISPECTRAL.fullmatch(name)
    if m:
        return "bispectral", None, (quantity_nm(*m.group(1, 2, 3)), quantity_nm(*m.group(4, 5, 6)))
    m = REFLECTIVE.fullmatch(name)
    if m:
        return "reflective", None, quantity_nm(*m.group(1, 2, 3))
    if DOTTED.fullmatch(name):
        return "dotted", None, None
    return None, None, None


def _attribute(path, header, name, allowed):
    """A string attribute's value, None when absent; refused when of another type."""
    if name not in header:
        return None
    value = header[name]
    if not isinstance(value, str):
        _fail(path, f"attribute {name}", f"is {type(value).__name__} {value!r}, the layout defines a string")
    if allowed is not None and value not in allowed:
        _fail(path, f"attribute {name}", f"{value!r} is not supported (accepted: {', '.join(map(repr, allowed))})")
    return value


def _check_version(path, header):
    version = _attribute(path, header, "spectralLayoutVersion", None)
    if version is None:
        return None
    m = re.fullmatch(r"([0-9]+)(?:\.[0-9]+)*", version.strip())
    if not m:
        _fail(path, "attribute spectralLayoutVersion", f"{version!r} is not a version number (expected '1.0')")
    if int(m.group(1)) != LAYOUT_MAJOR:
        _fail(path, "attribute spectralLayoutVersion",
              f"{version!r}: this reader knows layout version {LAYOUT_MAJOR}.x (Fichet, Pacanowski and Wilkie "
              f"2021); a different major version may name or scale channels differently")
    return version


def _spectral_channels(path, names):
    """{k: {nm: channel name}} of the emissive channels; refuses the rest of the layout."""
    found = {}
    for name in names:
        try:
            kind, k, nm = classify(name)
        except ValueError as exc:
            _fail(path, f"channel {name!r}", f"not a wavelength: {exc}")
        if kind in ("reflective", "bispectral"):
            _fail(path, f"channel {name!r}", (
                "reflective/bispectral layers are not supported: the benchmark compares emitted radiance "
                "(S0..S3 channels); a T layer is a reflectance or re-radiation texture, not a render"))
        if kind == "dotted":
            _fail(path, f"channel {name!r}", ("a '.' as decimal separator: the layout writes the wavelength "
                                              "with a comma (the dot separates OpenEXR layers), e.g. S0.555,5nm"))
        if kind == "emissive":
            per = found.setdefault(k, {})
            twin = next((other for w, other in per.items() if math.isclose(w, nm, rel_tol=1e-9)), None)
            if twin is not None:
                _fail(path, f"channel {name!r}", f"duplicate wavelength {nm:g} nm (also channel {twin!r})")
            per[nm] = name
    if not found:
        shown = ", ".join(sorted(names)[:12]) + (f", ... ({len(names)} channels)" if len(names) > 12 else "")
        _fail(path, "channels", f"no spectral channels (S0.<wavelength><unit>, e.g. S0.555,5nm); it has {shown or 'none'}")
    present = sorted(found)
    if present != [0] and present != [0, 1, 2, 3]:
        missing = [f"S{k}" for k in range(4) if k not in found]
        _fail(path, "channels", (f"Stokes components {', '.join(f'S{k}' for k in present)} without "
                                 f"{', '.join(missing)}: an image holds S0 alone or all of S0..S3"))
    base = sorted(found[0])
    for k in present[1:]:
        other = sorted(found[k])
        if len(other) != len(base) or not np.allclose(other, base, rtol=1e-9, atol=0):
            only = sorted(set(np.round(other, 6)) ^ set(np.round(base, 6)))
            _fail(path, f"channels S{k}", (f"wavelengths differ from S0's ({len(other)} against {len(base)}; "
                                          f"not in both: {', '.join(f'{w:g} nm' for w in only[:6])})"))
    if len(base) < 2:
        _fail(path, "channels", f"one wavelength ({found[0][base[0]]!r}): a spectrum needs at least 2")
    return found


def read(path, expect=None):
    """The emissive spectral image of a Fichet 2021 EXR (SpectralImage). Raises SpectralEXRError.
    The header is checked before any pixel is read (batch/exr.py ``check_header``: the expected
    (width, height) where known, else the caps there)."""
    path = str(path)
    try:
        exr.check_header(path, expect)
    except OSError as exc:
        raise SpectralEXRError(f"{path}: cannot be read ({exc.strerror or exc})") from exc
    except exr.EXRLimitError as exc:
        raise SpectralEXRError(str(exc)) from exc
    try:
        f = OpenEXR.File(path, separate_channels=True)
    except Exception as exc:  # the OpenEXR package raises a bare RuntimeError for unreadable files
        raise SpectralEXRError(f"{path}: not a readable OpenEXR file ({exc})") from exc
    with f:
        header = f.header()
        channels = f.channels()
        version = _check_version(path, header)
        units = _attribute(path, header, "emissiveUnits", (EMISSIVE_UNITS,))
        handedness = _attribute(path, header, "polarisationHandedness", tuple(HANDEDNESS))
        found = _spectral_channels(path, list(channels))
        wls = np.array(sorted(found[0]), dtype=np.float64)
        stokes, names = {}, {}
        for k, per in sorted(found.items()):
            order = [per[w] for w in sorted(per)]
            for name in order:
                ch = channels[name]
                if (ch.xSampling, ch.ySampling) != (1, 1):
                    _fail(path, f"channel {name!r}", f"subsampled ({ch.xSampling}x{ch.ySampling}): spectral channels are full resolution")
            stokes[k] = np.stack([np.asarray(channels[n].pixels, dtype=np.float64) for n in order], axis=-1)
            names[k] = order
    if 3 in stokes and handedness == "left":
        stokes[3] = stokes[3] * HANDEDNESS["left"]
    return SpectralImage(path, wls, stokes, units, version, handedness, names)


# ---- colour -------------------------------------------------------------------------------------

# observers to_rgb integrates with: (wavelengths, x_bar, y_bar, z_bar, normalisation). "mitsuba3"
# is Mitsuba 3's RGB film (exporters/colorimetry.py), to compare a Mitsuba spectral render with
# its RGB render; "art46" is not here: it is ART's band film as read with the "box" band model below
OBSERVERS = {
    "cie1931": lambda: colorimetry.observer("cie1931"),
    "cie1964": lambda: colorimetry.observer("cie1964"),
    "mitsuba3": lambda: colorimetry.observer("mitsuba3"),
}


def box_edges(wavelengths_nm, width_nm=None):
    """[(lo, hi)] of box bands centred on ``wavelengths_nm``: ``width_nm`` wide, or (None) meeting
    midway between neighbouring centres, the outer ones half a spacing out."""
    c = np.asarray(wavelengths_nm, dtype=np.float64)
    if width_nm is not None:
        return np.stack([c - width_nm / 2, c + width_nm / 2], axis=-1)
    mid = (c[1:] + c[:-1]) / 2
    return np.stack([np.r_[c[0] - (mid[0] - c[0]), mid], np.r_[mid, c[-1] + (c[-1] - mid[-1])]], axis=-1)


# how a renderer's channels hold its spectrum (issue 33): "hat" (default) and "point", samples at
# the channel wavelengths, read as their piecewise-linear interpolation; "box", each channel the
# mean radiance over its band (ART's film, ArSpectrum46.c; a specfilm of box responses), read as a
# spectrum constant over each band (colorimetry.box_weights)
BAND_MODELS = ("hat", "point", "box")


@lru_cache(maxsize=64)
def rgb_weights(wavelengths_nm, observer="cie1931", bands="hat", band_width_nm=None):
    """N x 3 matrix from N channels (at the tuple ``wavelengths_nm``, holding the spectrum as the
    band model ``bands`` says) to linear sRGB."""
    if observer not in OBSERVERS:
        raise ValueError(f"unknown observer {observer!r} (known: {', '.join(OBSERVERS)})")
    if bands not in BAND_MODELS:
        raise ValueError(f"unknown band model {bands!r} (known: {', '.join(BAND_MODELS)})")
    wl, xb, yb, zb, norm = OBSERVERS[observer]()
    cmfs = np.stack([xb, yb, zb])
    if bands == "box":
        xyz = colorimetry.box_weights(box_edges(wavelengths_nm, band_width_nm), wl, cmfs, norm)  # N x 3
    else:
        xyz = colorimetry.hat_weights(np.array(wavelengths_nm), wl, cmfs, norm)  # N x 3
    weights = colorimetry.xyz_to_srgb(xyz)
    weights.setflags(write=False)  # shared by every caller through the cache
    return weights


def to_rgb(image, observer="cie1931", bands="hat", band_width_nm=None):
    """(names, H x W x C float64): linear sRGB R, G, B of S0 and, for a polarised image,
    S0.R ... S3.B after them (the project's channel order), its channels read under the band model
    ``bands`` (BAND_MODELS)."""
    weights = rgb_weights(tuple(float(w) for w in image.wavelengths_nm), observer, bands, band_width_nm)
    planes = {k: image.stokes[k] @ weights for k in sorted(image.stokes)}
    names, parts = ["R", "G", "B"], [planes[0]]
    if image.polarised:
        names += [f"S{k}.{c}" for k in range(4) for c in "RGB"]
        parts += [planes[k] for k in range(4)]
    return names, np.concatenate(parts, axis=-1)


def pass_bands(image, bands="hat", band_width_nm=None):
    """One pass's S0 bands as the pass loop keeps them (batch/backends/passes.py): {"wavelengths_nm",
    "cube": H x W x N, "bands": the band model, "band_width_nm"}."""
    return {"wavelengths_nm": [float(w) for w in image.wavelengths_nm], "cube": image.stokes[0],
            "bands": bands, "band_width_nm": band_width_nm}


def read_render(path, writes="rgb", observer="cie1931", expect=None):
    """(names, H x W x C image) of what a renderer wrote: ``writes`` "rgb" reads R, G, B then
    S0.R ... (batch/exr.py read_image), "spectral" a Fichet 2021 spectral EXR integrated with
    ``observer`` (to_rgb); ``expect``: the (width, height) the job asked for, checked in the header
    before any pixel is read."""
    if writes not in READERS:
        raise ValueError(f"writes = {writes!r}: a renderer writes one of {', '.join(READERS)}")
    return READERS[writes](path, observer, expect)


READERS = {
    "rgb": lambda path, observer, expect: exr.read_image(path, expect=expect),
    "spectral": lambda path, observer, expect: to_rgb(read(path, expect), observer),
}


# ---- writing ------------------------------------------------------------------------------------

def channel_name(k, nm):
    """``S<k>.<nm>nm`` with a comma as decimal separator, the shortest form that reads back to nm."""
    return f"S{k}.{np.format_float_positional(float(nm), trim='-').replace('.', ',')}nm"


def write(path, wavelengths_nm, planes, rgb_preview=True, extra=None, header=None, dtype=np.float32):
    """Write an emissive spectral image in the Fichet 2021 layout: ``planes`` an H x W x N array
    (S0) or {k: H x W x N} for k = 0 or 0..3, sampled at the N ascending, distinct
    ``wavelengths_nm``. Attributes spectralLayoutVersion "1.0", emissiveUnits "W.m^-2.sr^-1" and,
    when polarised, polarisationHandedness "right"; with ``rgb_preview`` the R, G, B of S0 (CIE
    1931, to_rgb) for viewers; ``extra`` {name: H x W} channels; ``header`` more attributes."""
    planes = planes if isinstance(planes, dict) else {0: planes}
    wls = np.asarray(wavelengths_nm, dtype=np.float64)
    if sorted(planes) not in ([0], [0, 1, 2, 3]):
        raise ValueError(f"{path}: Stokes components {sorted(planes)}: write S0 alone or S0..S3")
    if wls.ndim != 1 or wls.size < 2 or not np.all(np.isfinite(wls)) or not np.all(np.diff(wls) > 0) or wls[0] <= 0:
        raise ValueError(f"{path}: wavelengths must be at least 2, positive, finite and strictly ascending")
    shape = np.shape(planes[0])
    for k, arr in planes.items():
        if np.shape(arr) != shape or len(shape) != 3 or shape[2] != wls.size:
            raise ValueError(f"{path}: S{k} has shape {np.shape(arr)}, expected H x W x {wls.size} like S0 {shape}")
    channels = {}
    for k in sorted(planes):
        for i, nm in enumerate(wls):
            channels[channel_name(k, nm)] = np.ascontiguousarray(planes[k][..., i], dtype=dtype)
    if rgb_preview:
        img = SpectralImage(str(path), wls, {0: np.asarray(planes[0], dtype=np.float64)})
        rgb = to_rgb(img)[1]
        channels.update({c: np.ascontiguousarray(rgb[..., i], dtype=np.float32) for i, c in enumerate("RGB")})
    for name, arr in (extra or {}).items():
        if classify(name)[0] is not None:
            raise ValueError(f"{path}: extra channel {name!r} would read as a spectral channel")
        channels[name] = np.ascontiguousarray(arr)
    head = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
            "spectralLayoutVersion": LAYOUT_VERSION, "emissiveUnits": EMISSIVE_UNITS}
    if len(planes) == 4:
        head["polarisationHandedness"] = "right"
    head.update(header or {})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return exr._write_file(path, head, channels)
