"""The spectral OpenEXR layout of Fichet, Pacanowski and Wilkie (JCGT 2021): batch/spectral_exr.py
reads files written by colour-science's writer (with OpenImageIO) and by hand from the
specification, refuses what it cannot read faithfully, integrates colour as the project defines it
(exporters/colorimetry.py), and reads Mitsuba's spectral render (specfilm) to the colour of its RGB
render within both renders' noise."""
import importlib.util
import math

import numpy as np
import OpenEXR
import pytest

from conftest import GOLDEN, ROOT
from spectral_bench.batch import exr, spectral_exr
from spectral_bench.batch.spectral_exr import SpectralEXRError
from spectral_bench.exporters import colorimetry, ir_json, spectra

colour = pytest.importorskip("colour")
has_oiio = importlib.util.find_spec("OpenImageIO") is not None
needs_oiio = pytest.mark.skipif(not has_oiio, reason="OpenImageIO (colour-science's EXR backend) not installed")


def raw_exr(path, channels, header=None):
    """An EXR written with the OpenEXR package alone: channel names and attributes exactly as given."""
    head = {"type": OpenEXR.scanlineimage, "compression": OpenEXR.ZIP_COMPRESSION}
    head.update(header or {})
    with OpenEXR.File(head, {n: np.ascontiguousarray(a, dtype=np.float32) for n, a in channels.items()}) as f:
        f.write(str(path))
    return path


def bands(names, shape=(2, 3), seed=0):
    rng = np.random.default_rng(seed)
    return {n: rng.uniform(0.1, 2.0, shape) for n in names}


# ---- files written by colour-science (colour.io.write_spectral_image_Fichet2021) -----------------

@needs_oiio
def test_reads_colour_sciences_d65(tmp_path):
    from colour.io import Specification_Fichet2021, write_spectral_image_Fichet2021
    sd = colour.SDS_ILLUMINANTS["D65"]
    path = tmp_path / "d65.exr"
    write_spectral_image_Fichet2021(sd, str(path), "float32", Specification_Fichet2021(is_emissive=True))
    img = spectral_exr.read(path)
    np.testing.assert_allclose(img.wavelengths_nm, sd.wavelengths, rtol=1e-12)  # colour writes repr(float)
    assert sorted(img.stokes) == [0] and img.stokes[0].shape == (1, 1, sd.wavelengths.size)
    np.testing.assert_array_equal(img.stokes[0][0, 0], sd.values.astype(np.float32))
    assert (img.units, img.version) == ("W.m^-2.sr^-1", "1.0")


@needs_oiio
def test_reads_colour_sciences_polarised_image_and_colour_reads_ours(tmp_path):
    from colour.io import Specification_Fichet2021, read_spectral_image_Fichet2021, write_spectral_image_Fichet2021
    wl = np.arange(400.0, 701.0, 20.0)
    rng = np.random.default_rng(1)
    planes = {k: rng.uniform(-1, 1, (3, 4, wl.size)) + (2 if k == 0 else 0) for k in range(4)}
    theirs = tmp_path / "theirs.exr"
    write_spectral_image_Fichet2021({f"S{k}": (wl, p) for k, p in planes.items()}, str(theirs), "float32",
                                    Specification_Fichet2021(is_emissive=True, is_polarised=True))
    img = spectral_exr.read(theirs)
    assert img.polarised and img.handedness == "right"
    for k in range(4):
        np.testing.assert_array_equal(img.stokes[k], planes[k].astype(np.float32))
    ours = spectral_exr.write(tmp_path / "ours.exr", wl, planes)
    back = read_spectral_image_Fichet2021(str(ours))
    assert sorted(back) == ["S0", "S1", "S2", "S3"]
    for k in range(4):
        w, values = back[f"S{k}"]
        order = np.argsort(w)
        np.testing.assert_array_equal(np.asarray(w)[order], wl)
        np.testing.assert_array_equal(np.asarray(values)[..., order], planes[k].astype(np.float32))


@needs_oiio
def test_colour_sciences_reflective_image_is_refused(tmp_path):
    from colour.io import Specification_Fichet2021, write_spectral_image_Fichet2021
    msds = colour.MultiSpectralDistributions({w: [0.2, 0.5] for w in range(400, 701, 10)})
    path = tmp_path / "reflective.exr"
    write_spectral_image_Fichet2021(msds, str(path), "float32", Specification_Fichet2021(is_emissive=False))
    with pytest.raises(SpectralEXRError, match=r"reflective.exr: channel 'T\.[0-9,]+nm': reflective/bispectral"):
        spectral_exr.read(path)


# ---- files written by hand from the specification --------------------------------------------------

def test_units_and_prefixes_convert_to_nm(tmp_path):
    """µm, um, Hz with SI prefixes and an exponent all read as the same three wavelengths."""
    c = spectral_exr.SPEED_OF_LIGHT
    spellings = {
        "nm": ["S0.450nm", "S0.550,5nm", "S0.650nm"],
        "um": ["S0.0,45um", "S0.0,5505um", "S0.0,65um"],
        "µm": ["S0.0,45\u00b5m", "S0.0,5505\u00b5m", "S0.0,65\u00b5m"],
        "exponent": ["S0.4,5e2nm", "S0.5,505E-7m", "S0.6,5e-6dm"],
        "Hz": [f"S0.{str(round(c / (w * 1e-9) / 1e12, 9)).replace('.', ',')}THz" for w in (450.0, 550.5, 650.0)],
    }
    for label, names in spellings.items():
        data = dict(zip(names, bands(names).values()))
        img = spectral_exr.read(raw_exr(tmp_path / f"{label}.exr", data))
        np.testing.assert_allclose(img.wavelengths_nm, [450.0, 550.5, 650.0], rtol=1e-9, err_msg=label)
        # ascending wavelengths whatever the channel order (Hz reverses it)
        assert [np.float32(data[n][0, 0]) for n in img.channels[0]] == list(img.stokes[0][0, 0]), label


def test_polarised_hand_written_file_and_handedness(tmp_path):
    wl = ["S{}.500nm", "S{}.600nm", "S{}.700nm"]
    data = {n.format(k): np.full((1, 2), (k + 1) * 0.1 + i) for k in range(4) for i, n in enumerate(wl)}
    data.update({"R": np.zeros((1, 2)), "G": np.zeros((1, 2)), "B": np.zeros((1, 2))})  # a preview: ignored
    right = spectral_exr.read(raw_exr(tmp_path / "r.exr", data, {"polarisationHandedness": "right"}))
    left = spectral_exr.read(raw_exr(tmp_path / "l.exr", data, {"polarisationHandedness": "left"}))
    assert right.polarised and sorted(right.stokes) == [0, 1, 2, 3]
    np.testing.assert_allclose(right.stokes[2][0, 0], [0.3, 1.3, 2.3], rtol=1e-6)
    np.testing.assert_array_equal(left.stokes[3], -right.stokes[3])  # brought to right-handed
    np.testing.assert_array_equal(left.stokes[1], right.stokes[1])
    names, img = spectral_exr.to_rgb(right)
    assert names == ["R", "G", "B"] + [f"S{k}.{c}" for k in range(4) for c in "RGB"]
    np.testing.assert_array_equal(img[..., :3], img[..., 3:6])  # R, G, B are S0's


REFUSED = [  # (what, channels, header, message pattern)
    ("reflective", ["S0.500nm", "S0.600nm", "T.500nm", "T.600nm"], {},
     r"channel 'T\.500nm': reflective/bispectral layers are not supported: the benchmark compares emitted radiance"),
    ("bispectral", ["S0.500nm", "S0.600nm", "T.500nm.600nm"], {}, r"channel 'T\.500nm\.600nm': reflective/bispectral"),
    ("version", ["S0.500nm", "S0.600nm"], {"spectralLayoutVersion": "2.0"},
     r"attribute spectralLayoutVersion: '2\.0': this reader knows layout version 1\.x"),
    ("version_garbage", ["S0.500nm", "S0.600nm"], {"spectralLayoutVersion": "one"}, r"spectralLayoutVersion: 'one' is not a version"),
    ("units", ["S0.500nm", "S0.600nm"], {"emissiveUnits": "W.m^-2.sr^-1.nm^-1"},
     r"attribute emissiveUnits: 'W\.m\^-2\.sr\^-1\.nm\^-1' is not supported"),
    ("units_type", ["S0.500nm", "S0.600nm"], {"emissiveUnits": 1.0}, r"attribute emissiveUnits: is float"),
    ("handedness", ["S0.500nm", "S0.600nm"], {"polarisationHandedness": "up"}, r"polarisationHandedness: 'up'"),
    ("partial_stokes", ["S0.500nm", "S0.600nm", "S1.500nm", "S1.600nm"], {}, r"S0, S1 without S2, S3"),
    ("no_s0", ["S1.500nm", "S1.600nm"], {}, r"S1 without S0, S2, S3"),
    ("mismatch", [f"S{k}.{w}nm" for k in range(4) for w in (500, 600)][:-1] + ["S3.610nm"], {},
     r"channels S3: wavelengths differ from S0's .*600 nm, 610 nm"),
    ("nothing", ["R", "G", "B", "A"], {}, r"no spectral channels .* it has A, B, G, R"),
    ("one_band", ["S0.500nm", "R"], {}, r"one wavelength \('S0\.500nm'\): a spectrum needs at least 2"),
    ("duplicate", ["S0.500nm", "S0.0,5um", "S0.600nm"], {}, r"duplicate wavelength 500 nm"),
    ("dotted", ["S0.500.5nm", "S0.600nm"], {}, r"channel 'S0\.500\.5nm': a '\.' as decimal separator"),
    ("empty_number", ["S0.nm", "S0.600nm"], {}, r"channel 'S0\.nm': not a wavelength"),
    ("zero_hz", ["S0.0Hz", "S0.600nm"], {}, r"channel 'S0\.0Hz': not a wavelength"),
]


@pytest.mark.parametrize("what, names, header, pattern", REFUSED, ids=[r[0] for r in REFUSED])
def test_refused_files_say_file_and_channel(tmp_path, what, names, header, pattern):
    path = raw_exr(tmp_path / f"{what}.exr", bands(names), header)
    with pytest.raises(SpectralEXRError, match=rf"{what}\.exr: .*{pattern}"):
        spectral_exr.read(path)


def test_accepted_attributes(tmp_path):
    names = ["S0.500nm", "S0.600nm"]
    for header in ({}, {"spectralLayoutVersion": "1.0", "emissiveUnits": "W.m^-2.sr^-1"}, {"spectralLayoutVersion": "1.1"}):
        img = spectral_exr.read(raw_exr(tmp_path / "a.exr", bands(names), header))
        assert img.units == header.get("emissiveUnits") and img.version == header.get("spectralLayoutVersion")
    (tmp_path / "a.txt").write_text("not an image")
    with pytest.raises(SpectralEXRError, match=r"a\.txt: not a readable OpenEXR file"):
        spectral_exr.read(tmp_path / "a.txt")


def test_writer_follows_the_layout_and_reads_back(tmp_path):
    wl = np.array([380.0, 455.5, 530.25, 780.0])
    s0 = np.random.default_rng(3).uniform(0, 1, (2, 5, wl.size))
    path = spectral_exr.write(tmp_path / "w.exr", wl, s0, extra={"stderr.S0.380nm": np.zeros((2, 5), np.float32)})
    with OpenEXR.File(str(path), separate_channels=True) as f:
        header, names = dict(f.header()), sorted(f.channels())
    assert header["spectralLayoutVersion"] == "1.0" and header["emissiveUnits"] == "W.m^-2.sr^-1"
    assert "polarisationHandedness" not in header  # written for polarised images only
    assert names == sorted(["B", "G", "R", "S0.380nm", "S0.455,5nm", "S0.530,25nm", "S0.780nm", "stderr.S0.380nm"])
    img = spectral_exr.read(path)
    np.testing.assert_array_equal(img.wavelengths_nm, wl)
    np.testing.assert_array_equal(img.stokes[0], s0.astype(np.float32))
    preview = exr.read(path)
    np.testing.assert_allclose(preview["R"], spectral_exr.to_rgb(img)[1][..., 0], rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="strictly ascending"):
        spectral_exr.write(tmp_path / "x.exr", wl[::-1], s0)
    with pytest.raises(ValueError, match=r"S0 alone or S0\.\.S3"):
        spectral_exr.write(tmp_path / "x.exr", wl, {0: s0, 1: s0})


def test_arts_channel_names(tmp_path):
    """ART 2.1.2 (-s46e, -p) names its 46 band centres 'S<k>.<nm>,000000nm' from 325 nm."""
    centres = 325.0 + 10.0 * np.arange(46)
    data = {f"S{k}.{c:.0f},000000nm": np.full((2, 2), (k + 1) * c) for k in range(4) for c in centres}
    img = spectral_exr.read(raw_exr(tmp_path / "art.exr", data))
    np.testing.assert_array_equal(img.wavelengths_nm, centres)
    np.testing.assert_allclose(img.stokes[3][0, 0], 4 * centres, rtol=1e-7)
    assert img.channels[0][0] == "S0.325,000000nm"


# ---- colorimetry against published values -----------------------------------------------------------

def _xyz_of(wl, values, observer="cie1931"):
    img = spectral_exr.SpectralImage("x", np.asarray(wl, float), {0: np.asarray(values, float)[None, None, :]})
    rgb = spectral_exr.to_rgb(img, observer)[1][0, 0, :3]
    return np.linalg.solve(colorimetry._srgb_matrix(), rgb)  # the exact inverse of the matrix used


@pytest.mark.parametrize("observer", ["cie1931", "cie1964"])
def test_flat_spectrum_has_unit_luminance(observer):
    wl = np.arange(360.0, 831.0, 5.0)
    assert _xyz_of(wl, np.ones(wl.size), observer)[1] == pytest.approx(1.0, abs=1e-12)
    assert _xyz_of(wl, np.full(wl.size, 3.0), observer)[1] == pytest.approx(3.0, abs=1e-12)


def test_equals_the_projects_ground_truth_for_a_piecewise_linear_spectrum():
    """A spectrum sampled at 5 nm and read as its linear interpolation is exactly what
    colorimetry.spectrum_xyz computes for the IR's sampled spectrum (same 1 nm trapezoid rule)."""
    d65 = spectra._named_tables()["cie_d65"][0]
    expected = colorimetry.spectrum_xyz({"type": "sampled", "wavelengths": d65["wavelengths"], "values": d65["values"]})
    got = _xyz_of(d65["wavelengths"], d65["values"])
    # the IR pads a sampled spectrum with its edge value beyond 780 nm; the image is zero there
    wl, xb, yb, zb, norm = colorimetry.observer()
    tail = np.array([np.trapz(np.where(wl > 780, d65["values"][-1], 0.0) * c, wl) for c in (xb, yb, zb)]) / norm
    np.testing.assert_allclose(got, expected - tail, rtol=1e-12)


def test_d65_chromaticity_and_srgb_white_balance():
    """CIE D65 (colour.SDS_ILLUMINANTS: the CIE table at 5 nm, 300-780 nm) read as a spectral
    image. Published: CIE 015:2018 gives D65 (2 degrees) as x, y = 0.31272, 0.32903, computed by
    summation at 5 nm over 380-780 nm; IEC 61966-2-1 rounds it to 0.3127, 0.3290 for sRGB's white.
    The reader integrates the linear interpolation of the 5 nm samples at 1 nm instead; that
    sampling moves x, y by the difference between the two sums (computed here, about 1e-5). So:
    x, y within the published rounding (0.5e-5) plus that difference of CIE's values, and within
    the IEC half unit (5e-5) of sRGB's white. sRGB's RGB of D65 then equals the RGB of CIE's
    chromaticity through the project's (IEC, four-decimal) matrix within that chromaticity
    tolerance propagated through the matrix; and R = G = B within it plus the matrix's own
    rounding (its white is not exactly R = G = B)."""
    sd = colour.SDS_ILLUMINANTS["D65"]
    xyz = _xyz_of(sd.wavelengths, sd.values)
    x, y = xyz[:2] / xyz.sum()
    wl5 = np.arange(380.0, 781.0, 5.0)
    cie_sum = (sd[wl5][:, None] * colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"][wl5]).sum(axis=0)
    x5, y5 = cie_sum[:2] / cie_sum.sum()
    assert abs(x5 - 0.31272) <= 0.5e-5 and abs(y5 - 0.32903) <= 0.5e-5  # CIE's method reproduces CIE's value
    sampling = max(abs(x - x5), abs(y - y5))
    assert sampling < 1e-5, sampling  # 1 nm linear interpolation against 5 nm summation
    tol = 0.5e-5 + sampling
    assert abs(x - 0.31272) <= tol and abs(y - 0.32903) <= tol, (x, y, tol)
    assert abs(x - 0.3127) <= 5e-5 and abs(y - 0.3290) <= 5e-5, (x, y)
    m = colorimetry._srgb_matrix()

    def rgb_of(xc, yc):
        v = m @ np.array([xc / yc, 1.0, (1 - xc - yc) / yc])
        return v / v[1]
    expected = rgb_of(0.31272, 0.32903)
    bound = max(np.abs(rgb_of(0.31272 + dx, 0.32903 + dy) - expected).max() for dx in (-tol, tol) for dy in (-tol, tol))
    rgb = m @ xyz
    assert np.abs(rgb / rgb[1] - expected).max() <= bound, (rgb / rgb[1], expected, bound)
    white_balance = np.abs(expected - 1).max() + bound
    assert np.abs(rgb / rgb[1] - 1).max() <= white_balance < 1e-3, (rgb / rgb[1], white_balance)


def test_cie1964_observer_is_colour_sciences():
    """The 10-degree observer's XYZ of a smooth spectrum matches colour-science's own integration
    (colour.sd_to_XYZ, 1 nm, E illuminant) to its interpolation's precision."""
    wl = np.arange(360.0, 831.0, 1.0)
    values = np.exp(-0.5 * ((wl - 560.0) / 60.0) ** 2)
    sd = colour.SpectralDistribution(dict(zip(wl, values)))
    cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]
    theirs = colour.sd_to_XYZ(sd, cmfs=cmfs, illuminant=colour.SDS_ILLUMINANTS["E"], method="Integration") / 100
    ours = _xyz_of(wl, values, "cie1964")
    np.testing.assert_allclose(ours / ours[1], theirs / theirs[1], rtol=2e-3)
    assert not np.allclose(ours, _xyz_of(wl, values, "cie1931"), rtol=1e-2)
    with pytest.raises(ValueError, match="unknown observer 'art46'"):
        _xyz_of(wl, values, "art46")


def test_read_render_dispatches_on_what_the_renderer_writes(tmp_path):
    wl = np.arange(400.0, 701.0, 10.0)
    s0 = np.ones((2, 2, wl.size))
    spectral_exr.write(tmp_path / "s.exr", wl, s0)
    names, img = spectral_exr.read_render(tmp_path / "s.exr", "spectral")
    assert names == ["R", "G", "B"] and img.shape == (2, 2, 3)
    exr.write_image(tmp_path / "rgb.exr", ["R", "G", "B"], np.full((2, 2, 3), 0.5))
    names, img = spectral_exr.read_render(tmp_path / "rgb.exr", "rgb")
    assert names == ["R", "G", "B"] and np.all(img == 0.5)
    with pytest.raises(ValueError, match="writes = 'xyz'"):
        spectral_exr.read_render(tmp_path / "rgb.exr", "xyz")
    with pytest.raises(SpectralEXRError, match="rgb.exr: channels: no spectral channels"):
        spectral_exr.read_render(tmp_path / "rgb.exr", "spectral")


# ---- Mitsuba's spectral film -----------------------------------------------------------------------

def _check_script():
    spec = importlib.util.spec_from_file_location("spectral_exr_check", ROOT / "scripts" / "spectral_exr_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_mitsuba_spectral_render_matches_its_rgb_render(tmp_path):
    """ggx_copper_50 at 64 x 64, 4 passes of 256 spp each way: Mitsuba's specfilm (10 nm boxes)
    read with spectral_exr and Mitsuba's film observer ("mitsuba3") against Mitsuba's RGB film, on
    both renders' noise: the block noise test passes, and the image means agree within 4 standard
    errors plus the band discretisation error expected for the scene's spectra (|e| < 1.5e-3,
    scripts/spectral_exr_check.py). A 1 % brighter reading fails."""
    check = _check_script()
    scene = ir_json.load(GOLDEN / "ggx_copper_50.json")
    zt, mean, se, rgb, rgb_se = check.agreement(scene, tmp_path, size=64, spp=256, passes=4)
    assert zt.passed, zt.as_dict()
    img = spectral_exr.read(tmp_path / "spectral_0.exr")
    assert img.stokes[0].shape == (64, 64, 47) and img.wavelengths_nm[0] == 365.0 and img.wavelengths_nm[-1] == 825.0

    def mean_z(m, s):
        n = m[..., 0].size
        diff = m.mean(axis=(0, 1)) - rgb.mean(axis=(0, 1))
        allowance = 1.5e-3 * rgb.mean(axis=(0, 1))
        sd = np.sqrt((s**2).sum(axis=(0, 1)) + (rgb_se**2).sum(axis=(0, 1))) / n
        return (np.abs(diff) - allowance) / sd
    assert np.all(mean_z(mean, se) < 4), mean_z(mean, se)
    assert np.any(mean_z(mean * 1.01, se) > 4), mean_z(mean * 1.01, se)


def test_spectral_scene_xml_and_refusals(tmp_path):
    from spectral_bench.batch.backends.mitsuba import spectral as ms
    text = (ROOT / "golden" / "mitsuba" / "ggx_copper_50" / "scene.xml").read_text()
    out = ms.spectral_xml(text, ms.bands())
    assert 'type="specfilm"' in out and "pixel_format" not in out and out.count('type="irregular"') == 47
    assert '<rfilter type="box"' in out and 'name="band_046"' in out and 'value="820.0, 830.0"' in out
    assert ms.bands(10, (360, 365 + 10)) == [(360.0, 370.0), (370.0, 375.0)]
    with pytest.raises(ms.SpectralRenderError, match="stokes integrator"):
        ms.spectral_xml(text.replace('<integrator type="path">', '<integrator type="stokes">'), ms.bands())
    with pytest.raises(ms.SpectralRenderError, match="unpolarised radiance only"):
        ms.spectral_variant("llvm_ad_spectral_polarized")
    assert ms.spectral_variant("llvm_ad_mono") == "llvm_ad_spectral" and ms.spectral_variant("scalar_rgb") == "scalar_spectral"


@pytest.mark.slow
def test_spectral_film_band_is_the_band_average(tmp_path):
    """A constant environment of a known spectrum seen through the spectral film: each 10 nm band
    holds the spectrum's average over the band (specfilm stores the band integral; the module
    divides by the width), judged on the pixels' own spread."""
    from spectral_bench.batch.backends.mitsuba import spectral as ms
    xml = tmp_path / "env.xml"
    xml.write_text("""<scene version="3.0.0"><integrator type="path"/>
      <sensor type="perspective"><float name="fov" value="10"/>
        <sampler type="independent"><integer name="sample_count" value="8"/></sampler>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
          <rfilter type="box"/></film></sensor>
      <emitter type="constant"><spectrum name="radiance" value="360:1, 600:1, 830:3"/></emitter></scene>""")
    ms.render(xml, tmp_path / "env.exr", 256, seed=0, variant="scalar_spectral")
    img = spectral_exr.read(tmp_path / "env.exr")
    pixels = img.stokes[0].reshape(-1, img.wavelengths_nm.size)
    expected = np.array([np.mean(np.interp(np.linspace(c - 5, c + 5, 1001), [360, 600, 830], [1, 1, 3]))
                         for c in img.wavelengths_nm])
    z = (pixels.mean(axis=0) - expected) / (pixels.std(axis=0, ddof=1) / math.sqrt(len(pixels)))
    assert np.abs(z).max() < 4.0, z  # 47 bands: a Sidak 1 % threshold is |z| < 3.5; 4 keeps margin
    assert abs(np.mean(z)) < 4.0 / math.sqrt(len(z))
