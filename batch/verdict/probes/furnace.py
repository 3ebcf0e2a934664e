"""Spectral furnaces (issue 41): the camera inside a closed diffuse enclosure whose every face reflects
rho(l) (Lambertian, one-sided, facing the camera) and emits the same uniform radiance Le(l), nothing
else in the scene (furnace_colorchecker_yellow, furnace_spiky).

Derivation. In a closed enclosure every direction from a surface point meets the enclosure again,
so if the radiance leaving every point is the same L, the irradiance is pi L everywhere and
L = Le + rho L: L = Le / (1 - rho), whatever the enclosure's shape (the "furnace test": Pharr,
Jakob and Humphreys, Physically Based Rendering, 4th ed., 2023, pbrt-v4's analytic scene
test rho = Le = 0.5, L = 1; the flat faces of the scenes' icosphere change nothing). A path tracer
limited to ``max_depth`` segments (docs/scene-format.md section 4: 1 sees the emitters directly, 2
adds one reflection, ...) sums the Neumann series' first d terms, wavelength by wavelength:

    L_d(l) = Le(l) sum_{k < d} rho(l)^k = Le(l) (1 - rho(l)^d) / (1 - rho(l)),

the whole series where d <= 0 (no limit). To linear sRGB by the project's colour pipeline
(exporters/colorimetry.py: the CIE 1931 CMFs at 1 nm, the IEC matrix), as the other probes do.

What an RGB renderer gets (``rgb``): rho and Le reduced to channels first by the RGB backends' rule
(exporters/rgb_reduction.py), then the same series per channel. The series is convex in rho, so
reducing first reads dark where rho varies inside a channel (Jensen's inequality; the reduction's
negative matrix lobes can also push a channel up): the record carries that prediction, its gap to
the truth and the render judged against it, which the diagnosis names (diagnosis/materials.py
"RGB transport").

Judged on the render's own noise: every pixel has the same expected value and the pixels are
independent draws (box filter, independent sampling), so

- ``image mean``: the mean of all pixels per channel against the truth, its standard error from the
  pixels' spread (Student's t, n - 1; Sidak over the 3 channels at stats.ALPHA), with the
  observers' alternatives as the lone-sphere probe has (a renderer's film, known_deviations.toml);
- ``every 4 x 4 block``: each block of BLOCK x BLOCK pixels (its mean) against the truth in units of
  the blocks' spread (the same standard deviation for every block, n - 1 dof), Sidak over every
  block and channel: a local error (a seam, a face, a hot pixel) that the mean dilutes. Blocks, not
  single pixels: a spiky reflectance makes a pixel's value skewed (the rare wavelengths inside a
  peak are worth 10 times the others), and at single pixels the Sidak tail (|t| > 4.9 over 12288
  tests) false-alarmed on a correct Mitsuba render of furnace_spiky (|t| = 5.7, 64x64 at 256 spp);
  the mean of 16 pixels is 4 times less skewed. Its ``detectable`` is how large a change of a
  single block's value (relative, best channel) it sees with 90 % power."""
import numpy as np

from ....exporters import colorimetry, mesh_io, rgb_reduction, spectra
from .. import stats
from .common import MIN_PIXELS, probe as _probe, remembered

POWER = 0.9
BLOCK = 4  # pixels per side of the blocks the local test judges (every_block)
FINE_NM = 0.05  # the wavelength step of the colour integral (expected_rgb)
PREFIX = "furnace "


def _mesh(shape, base_dir=None):
    """(V x 3 world vertices, F x 3 faces) of an IR mesh."""
    verts, faces = mesh_io.load_mesh(shape, base_dir)
    v = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if shape.get("to_world") is not None:
        m = np.asarray(shape["to_world"], dtype=np.float64)
        v = v @ m[:3, :3].T + m[:3, 3]
    return v, f


def closed(faces):
    """Whether a triangle mesh is closed and consistently wound: every directed edge appears once
    and its reverse once."""
    f = np.asarray(faces, dtype=np.int64)
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    if len(edges) == 0 or np.any(edges[:, 0] == edges[:, 1]):
        return False
    directed = {tuple(e) for e in edges.tolist()}
    return len(directed) == len(edges) and all((b, a) in directed for a, b in directed)


def winding_number(vertices, faces, point):
    """The winding number of a closed triangle mesh about ``point``: the sum of its triangles'
    signed solid angles over 4 pi (Van Oosterom and Strackee, "The solid angle of a plane
    triangle", IEEE Trans. Biomed. Eng. 30(2), 1983: tan(Omega / 2) = a . (b x c) / (|a||b||c| +
    (a . b)|c| + (a . c)|b| + (b . c)|a|)). +1 inside a mesh wound outwards (counter-clockwise seen
    from outside), -1 inside one wound inwards, 0 outside."""
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)] - np.asarray(point, dtype=np.float64)
    a, b, c = v[:, 0], v[:, 1], v[:, 2]
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb \
        + np.einsum("ij,ij->i", b, c) * la
    return float(np.sum(2.0 * np.arctan2(num, den)) / (4.0 * np.pi))


def applies(scene):
    """The enclosure's object when ``scene`` is a spectral furnace: no delta lights, one closed
    triangle mesh, diffuse (not fluorescent) and an area emitter, wound inwards about the camera
    (winding number -1: every face shows its front to the inside); else None."""
    objs = scene["objects"]
    if scene.get("lights") or len(objs) != 1:
        return None
    obj = objs[0]
    b, e = obj.get("bsdf") or {}, obj.get("emitter") or {}
    if obj["shape"]["type"] != "mesh" or b.get("type") != "diffuse" or b.get("fluorescence") is not None \
            or e.get("type") != "area":
        return None
    try:
        v, f = _mesh(obj["shape"], scene.get("_base_dir"))
    except (OSError, ValueError):
        return None
    if not closed(f):
        return None
    cam = np.asarray(scene["camera"]["to_world"], dtype=np.float64)[:3, 3]
    return obj if round(winding_number(v, f, cam)) == -1 else None


def depth(scene):
    """The render's max_depth (segments, docs/scene-format.md section 4); <= 0: no limit."""
    return int((scene.get("render") or {}).get("max_depth", 64))


def series(rho, d):
    """sum_{k < d} rho^k (1 - rho^d) / (1 - rho); 1 / (1 - rho) for d <= 0 (rho < 1 there)."""
    rho = np.asarray(rho, dtype=np.float64)
    if d <= 0:
        return 1.0 / (1.0 - rho)
    near = np.abs(1.0 - rho) < 1e-12
    return np.where(near, float(d), (1.0 - rho ** d) / np.where(near, 1.0, 1.0 - rho))


def spectrum(reflectance, radiance, d, wavelengths):
    """L_d(l) = Le(l) (1 - rho(l)^d) / (1 - rho(l)) at ``wavelengths`` (IR spectra)."""
    rho = np.clip(np.asarray(spectra.evaluate(reflectance, wavelengths), dtype=np.float64), 0.0, None)
    return np.asarray(spectra.evaluate(radiance, wavelengths), dtype=np.float64) * series(rho, d)


@remembered()
def expected_rgb(reflectance, radiance, d, obs=colorimetry.GROUND_TRUTH):
    """Linear sRGB of the truncated series, integrated spectrally with observer ``obs``: its CMF
    table interpolated linearly (as the 1 nm table is read everywhere) onto a FINE_NM grid, the
    trapezoid rule there, normalised as colorimetry.xyz normalises (for a spectrum linear between
    whole nanometres the same value as colorimetry.xyz). The series is a convex function of rho,
    sharp where rho peaks: on the 1 nm grid the trapezoid rule reads furnace_spiky's peaks (rho
    0.9, 1 / (1 - rho) = 10 at the tip) 1.0-1.5 % too bright; on FINE_NM the rule's error falls as
    the grid step squared, 400 times less."""
    wl, xb, yb, zb, norm = colorimetry.observer(obs)
    fine = np.linspace(wl[0], wl[-1], int(round((wl[-1] - wl[0]) / FINE_NM)) + 1)
    values = spectrum(reflectance, radiance, d, fine)
    xyz = np.array([np.trapz(values * np.interp(fine, wl, c), fine) for c in (xb, yb, zb)]) / norm
    return colorimetry.xyz_to_srgb(xyz)


@remembered()
def rgb_prediction(reflectance, radiance, d):
    """What an RGB renderer gets: rho and Le reduced to linear sRGB channels first
    (exporters/rgb_reduction.py, clipped as the RGB backends clip them), then the series per
    channel."""
    rho_c, _ = rgb_reduction.reflectance_rgb(reflectance)
    le_c, _ = rgb_reduction.emission_rgb(radiance)
    return np.asarray(le_c, dtype=np.float64) * series(rho_c, d)


def blocks(image, size=None):
    """The means of ``size`` x ``size`` pixel blocks (BLOCK; the image's right and bottom remainder
    dropped) of an H x W x c image, as (blocks x c); the pixels themselves where the image is
    smaller than one block."""
    size = BLOCK if size is None else size
    h, w, c = image.shape
    bh, bw = h // size, w // size
    if bh == 0 or bw == 0:
        return image.reshape(-1, c)
    return image[:bh * size, :bw * size].reshape(bh, size, bw, size, c).mean(axis=(1, 3)).reshape(-1, c)


def every_block(values, expected, alpha=None):
    """Each block mean (n x c) against ``expected`` in units of the blocks' own spread per channel
    (n - 1 dof), Sidak over n x c tests. Returns {z (worst |z|), p, threshold, tests, pass,
    detectable}: detectable, the smallest relative change of one block's value (best channel)
    detected with 90 % power."""
    alpha = stats.ALPHA if alpha is None else alpha
    n, c = values.shape
    sd = values.std(axis=0, ddof=1)
    z = (values - expected[None, :]) / np.maximum(sd, 1e-300)[None, :]
    worst = float(np.max(np.abs(z)))
    p = float(stats.two_sided_p(worst, n - 1))
    threshold = stats.sidak_threshold(alpha, n * c)
    sens = np.abs(expected) / np.maximum(sd, 1e-300)
    curve = stats.power_curve(threshold, n - 1, sens.shape)
    det = stats.smallest_detectable(lambda eps: float(np.max(curve(eps * sens))), POWER, hi=100.0)
    return {"z": worst, "p": p, "threshold": threshold, "tests": n * c,
            "pass": bool(p >= threshold and np.isfinite(values).all()), "detectable": det}


def furnace(m):
    obj = applies(m.scene)
    if obj is None:
        return []
    scene = m.scene
    d = depth(scene)
    reflectance, radiance = obj["bsdf"]["reflectance"], obj["emitter"]["radiance"]
    expected = np.asarray(expected_rgb(reflectance, radiance, d), dtype=np.float64)
    rgb = np.asarray(rgb_prediction(reflectance, radiance, d), dtype=np.float64)
    series_text = "Le (1 - rho^d) / (1 - rho)" if d > 0 else "Le / (1 - rho)"
    name_mean = f"{PREFIX}{obj['name']}: image mean, {series_text}, d = {d}"
    name_px = f"{PREFIX}{obj['name']}: every {BLOCK} x {BLOCK} block, {series_text}, d = {d}"
    if "R" not in m.names:
        return []
    px = m.image[..., [m.names.index(ch) for ch in "RGB"]].reshape(-1, 3).astype(np.float64)
    n = len(px)
    if n < MIN_PIXELS:
        return [_probe(name_mean, expected, None, None, "sigma", None, pixels=n)]
    mean = px.mean(axis=0)
    se = px.std(axis=0, ddof=1) / np.sqrt(n)

    def judged(e):
        return stats.compare_means(mean, e, se, dof=n - 1)
    stat = judged(expected)
    alternatives = {o: judged(np.asarray(expected_rgb(reflectance, radiance, d, o), dtype=np.float64))
                    for o in m.observers if o != colorimetry.GROUND_TRUTH}
    rgb_stat = judged(rgb)
    rgb_record = {"expected": rgb.round(8).tolist(), "gap": (rgb / expected - 1.0).round(6).tolist(),
                  "measured_gap": (mean / expected - 1.0).round(6).tolist(),
                  "measured_gap_se": (se / np.abs(expected)).round(6).tolist(), "stat": rgb_stat,
                  "method": "rho and Le reduced to linear sRGB first (exporters/rgb_reduction.py), then the series per channel"}
    out = [_probe(name_mean, expected, mean, stat["z"], "sigma", stat["pass"], pixels=n, z=stat["z"], stat=stat,
                  alternatives=alternatives, depth=d, rgb=rgb_record)]
    rgb_image = m.image[..., [m.names.index(ch) for ch in "RGB"]].astype(np.float64)
    each = every_block(blocks(rgb_image), expected)
    out.append(_probe(name_px, expected, mean, each["z"], "sigma", each["pass"], pixels=n, z=each["z"],
                      p=each["p"], threshold=each["threshold"], tests=each["tests"], detectable=each["detectable"],
                      depth=d))
    return out
