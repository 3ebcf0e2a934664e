"""Smooth thin film on a conductor sphere in a uniform environment: every camera ray that meets
the sphere reflects once, specularly, into the environment (a sphere cannot see itself), so the
radiance it brings back is exactly R(theta, l) L(l), with R = (R_s + R_p) / 2 the film's Airy
reflectance for unpolarised light (batch/verdict/airy.py) at the ray's angle of incidence theta.
Integrated against the CIE 1931 CMFs as a spectral film does (exporters/colorimetry.py) and
averaged over each pixel's footprint (the box filter): theta changes quickly across a pixel near
the silhouette, so each pixel is supersampled on an S x S grid of its own rays, and pixels that
touch the silhouette (a corner or a sub-ray misses the sphere) or whose reflected rays meet any
other object are left out.

The verdict is the render's own noise: the sphere's pixels are grouped in image tiles, and each
tile's mean residual (rendered minus expected, per channel) is tested against its standard error
(stats.region_mean_test: pixels are independent), Sidak-corrected over tiles and channels.

Two records: "environment seen directly" judges the renderer's colour scale (the environment's
pixels against the CIE colour of L), and "airy film <object>" the film. Both are absolute, and both
also report their verdict under the observers of recorded deviations (Measurement.observers): a
renderer whose film is right but whose spectral-to-RGB conversion deviates, as Mitsuba 3.9.1's
does (known_deviations.toml: 0.1 % bright, 5 nm colour-matching tables), is then "known" on the
first record and passes the second under its observer, while a wrong film fails under every
observer.
"""
import numpy as np

from ....exporters import colorimetry, spectra
from .. import airy, raycast, stats
from .common import MIN_PIXELS, lerp, probe as _probe, remembered

THETA_TABLE = 4097      # colour as a function of the angle of incidence, linearly interpolated
# Tiles of 4 x 4 image pixels (tiles with fewer than 8 usable pixels are left out): the film's
# colour changes within a few pixels near the silhouette. Measured (benchmarks/CALIBRATION.md): a
# film 1 nm off fails at t > 30 at the scene's default 256x256, 64 spp.
TILE_PIXELS = 4
MIN_TILE_PIXELS = 8


def supersampling(width, height):
    """Sub-rays per pixel side: 16 up to 128 x 128 pixels, 8 above. The midpoint rule's error falls
    like 1/S^2; measured on iridescent_sphere_smooth, the worst tile mean moves by 7e-5 (64x64,
    16 -> 32) and 2e-4 (256x256, 8 -> 16) of its value, against a tile standard error of ~4e-3 at
    the scene's 64 spp (benchmarks/CALIBRATION.md)."""
    return 16 if width * height <= 128 * 128 else 8


def applies(obj):
    """A smooth filmed conductor sphere whose base is given by spectra (not a renderer's table)."""
    b = obj.get("bsdf") or {}
    return (b.get("type") == "conductor" and b.get("thin_film") is not None and obj["shape"]["type"] == "sphere"
            and not ((b.get("roughness") or {}).get("alpha", 0) > 0))


@remembered()
def reflectance_table(bsdf):
    """(theta grid, wavelengths, Airy reflectance R(theta, l)) of a filmed conductor: the costly
    part of its colour table, the same for every light and observer."""
    wl = spectra.cie_1931_cmfs()[0]
    film = bsdf["thin_film"]
    n3 = spectra.evaluate(bsdf["eta"], wl) + 1j * spectra.evaluate(bsdf["k"], wl)
    theta = np.linspace(0.0, np.pi / 2, THETA_TABLE)
    refl = airy.unpolarized_reflectance(np.cos(theta)[:, None], wl[None, :], film.get("ext_ior", 1.0),
                                        film["ior"], film["thickness"], n3[None, :])
    return theta, wl, refl


def _rgb_table(theta, wl, refl, radiance, obs):
    light = spectra.evaluate(radiance, wl)
    xyz = colorimetry.xyz_rows(refl * light[None, :], obs)
    return theta, colorimetry.xyz_to_srgb(xyz)


@remembered()
def colour_table(bsdf, radiance, obs=colorimetry.GROUND_TRUTH):
    """(theta grid, linear sRGB of R(theta, l) L(l) per angle) for a filmed conductor."""
    return _rgb_table(*reflectance_table(bsdf), radiance, obs)


def _trial_colour_table(bsdf, radiance, obs, cache):
    """``colour_table`` for a fit over the film's thickness: the film's interfaces (q2, r12 and
    r23 per angle and wavelength: reference_code's ``_film_interfaces``, all of the Airy sum but
    the thickness) kept in ``cache`` for the material without its thickness, so that a trial
    thickness computes the Airy sum alone (``airy_sum``: the same operations as
    ``airy.unpolarized_reflectance``, the same values)."""
    import json
    film = bsdf["thin_film"]
    base = dict(bsdf, thin_film={k: v for k, v in film.items() if k != "thickness"})
    key = json.dumps(["film interfaces", base], sort_keys=True, default=repr)
    if key not in cache:
        wl = spectra.cie_1931_cmfs()[0]
        n3 = spectra.evaluate(bsdf["eta"], wl) + 1j * spectra.evaluate(bsdf["k"], wl)
        theta = np.linspace(0.0, np.pi / 2, THETA_TABLE)
        cache[key] = theta, wl, airy.film_interfaces(np.cos(theta)[:, None], film.get("ext_ior", 1.0), film["ior"],
                                                     n3[None, :])
    theta, wl, interfaces = cache[key]
    rs, rp = airy.airy_sum(interfaces, wl[None, :], film["thickness"])
    return _rgb_table(theta, wl, 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2), radiance, obs)


def expected_image(scene, index, width, height, sub=None, obs=colorimetry.GROUND_TRUTH, cache=None):
    """(expected linear sRGB per pixel (H, W, 3), mask of pixels fully on the sphere with every
    reflected ray reaching the environment) for object ``index``; ``cache``: as for
    ``expected_images``."""
    images, mask = expected_images(scene, index, width, height, (obs,), sub, cache)
    return images[obs], mask


def _sub_rays(scene, index, width, height, sub, r0, r1, origin):
    """Pixel rows r0..r1's sub-rays: (their angle of incidence on the sphere as an index and
    weight into the colour tables' uniform theta grid, the rows' mask: every sub-ray meets the
    sphere and its reflection reaches the environment)."""
    objs, cam = scene["objects"], scene["camera"]
    obj = objs[index]
    centre = np.asarray(obj["shape"]["center"], dtype=np.float64)
    others = [o for j, o in enumerate(objs) if j != index]
    # sub-rays: the centres of an S x S grid in every pixel are the pixel centres at S times
    # the resolution
    _, dirs = raycast.camera_rays(cam, width * sub, height * sub, "centers", rows=range(r0 * sub, r1 * sub))
    who, t = raycast.nearest(objs, origin, dirs)
    p = origin + np.where(np.isfinite(t), t, 0.0)[..., None] * dirs
    n = (p - centre) / obj["shape"]["radius"]
    cos_i = np.clip(-np.sum(dirs * n, axis=-1), 0.0, 1.0)
    ok = who == index
    if others:
        refl = dirs + 2.0 * cos_i[..., None] * n
        who_r, _ = raycast.nearest(others, p + 1e-6 * n, refl)
        ok &= who_r == -1
    # the tables' theta grid is uniform on [0, pi/2] (THETA_TABLE points): np.interp's lerp with
    # the search done by arithmetic (the same values to rounding)
    x = np.arccos(cos_i) * ((THETA_TABLE - 1) / (np.pi / 2))
    i = np.minimum(x.astype(np.intp), THETA_TABLE - 2)
    return i, x - i, ok.reshape(r1 - r0, sub, width, sub).all(axis=(1, 3))


def expected_images(scene, index, width, height, observers=(colorimetry.GROUND_TRUTH,), sub=None, cache=None,
                    tables=None):
    """({observer: expected linear sRGB per pixel (H, W, 3)}, mask) as ``expected_image``, the
    rays traced once for every observer. ``cache``: a dict the caller keeps across calls where
    only the film's thickness (or the sphere's material) changes (the diagnosis's thickness fit):
    the sub-rays are then traced once per geometry (keyed by the camera, the objects' shapes, the
    sphere and the size), and a trial thickness pays for its Airy table and the sums alone."""
    import json
    objs, cam = scene["objects"], scene["camera"]
    obj = objs[index]
    sub = sub or supersampling(width, height)
    radiance = scene["environment"]["radiance"]
    if tables is None:  # ``tables``: {observer: (theta grid, RGB per angle)} of another material (probes/coated.py)
        tables = {o: colour_table(obj["bsdf"], radiance, o) if cache is None
                  else _trial_colour_table(obj["bsdf"], radiance, o, cache) for o in observers}
    geo = None
    if cache is not None:
        key = json.dumps(["thin film", cam, [o["shape"] for o in objs], index, width, height, sub], sort_keys=True,
                         default=repr)
        geo = cache.setdefault(key, {})
    if geo and "corners" in geo:
        origin, corner_mask = geo["corners"]
    else:
        origin, corners = raycast.camera_rays(cam, width, height, "corners")
        who_c, _ = raycast.nearest(objs, origin, corners)
        on = who_c == index
        corner_mask = on[:-1, :-1] & on[1:, :-1] & on[:-1, 1:] & on[1:, 1:]
        if geo is not None:
            geo["corners"] = (origin, corner_mask)
    mask = corner_mask.copy()
    images = {o: np.zeros((height, width, 3)) for o in observers}
    rows = max(1, 262144 // (width * sub * sub))  # pixel rows per chunk (bounded memory)
    for r0 in range(0, height, rows):
        r1 = min(height, r0 + rows)
        rays = None if geo is None else geo.get(r0)
        if rays is None:
            rays = _sub_rays(scene, index, width, height, sub, r0, r1, origin)
            if geo is not None:
                geo[r0] = rays
        i, f, ok = rays
        shape = (r1 - r0, sub, width, sub)
        for o, (_theta_grid, rgb_grid) in tables.items():
            rgb = lerp(rgb_grid, i, f)
            images[o][r0:r1] = rgb.reshape(shape + (3,)).mean(axis=(1, 3))
        mask[r0:r1] &= ok
    return images, mask


def tiles(mask, size=None, min_pixels=None):
    """Lists of (row, column) index arrays, one per image tile with enough usable pixels."""
    size, min_pixels = size or TILE_PIXELS, min_pixels or MIN_TILE_PIXELS
    h, w = mask.shape
    out = []
    for y in range(0, h, size):
        for x in range(0, w, size):
            ys, xs = np.nonzero(mask[y:y + size, x:x + size])
            if len(ys) >= min_pixels:
                out.append((ys + y, xs + x))
    return out


def environment_pixels(scene, width, height):
    """Mask (H, W) of pixels whose corners and centre meet no object: the environment itself."""
    objs, cam = scene["objects"], scene["camera"]
    origin, corners = raycast.camera_rays(cam, width, height, "corners")
    free = raycast.nearest(objs, origin, corners)[0] == -1
    centre = raycast.nearest(objs, origin, raycast.camera_rays(cam, width, height)[1])[0] == -1
    return free[:-1, :-1] & free[1:, :-1] & free[:-1, 1:] & free[1:, 1:] & centre


def tile_moments(rgb, expected, blocks):
    """Per tile (in ``blocks``' order) and channel: the mean measured, the mean expected and the
    standard error of the mean residual (T x 3 each), and the tiles' pixel counts. The tiles of
    one pixel count are reduced together (T x n x 3 arrays, axis 1): the same numbers, bit for
    bit, as each tile's own (n x 3, axis 0) mean and std, 8x faster on a 256 x 256 sphere's 4,000
    tiles (issue 45 item 1; tests/probes/test_probe_speedups.py pins it to the tile loop)."""
    n = np.array([len(ys) for ys, _xs in blocks])
    meas, exp, se = (np.empty((len(blocks), 3)) for _ in range(3))
    for k in np.unique(n):
        idx = np.nonzero(n == k)[0]
        ys, xs = np.stack([blocks[j][0] for j in idx]), np.stack([blocks[j][1] for j in idx])
        m_px, e_px = rgb[ys, xs], expected[ys, xs]
        meas[idx], exp[idx] = m_px.mean(axis=1), e_px.mean(axis=1)
        se[idx] = (m_px - e_px).std(axis=1, ddof=1) / np.sqrt(k)
    return meas, exp, se, n


def _tile_stat(rgb, expected, blocks, alpha):
    """compare_means over every tile and channel: tile means against their standard error from the
    spread of the tile's residuals (independent pixels)."""
    meas, exp, se, n = tile_moments(rgb, expected, blocks)
    return stats.compare_means(np.ravel(meas), np.ravel(exp), np.ravel(se), dof=np.repeat(n - 1.0, 3), alpha=alpha)


def smooth_film(m, alpha=None):
    alpha = stats.ALPHA if alpha is None else alpha
    scene, image = m.scene, m.image
    env = scene.get("environment")
    films = [i for i, obj in enumerate(scene["objects"]) if applies(obj)]
    if not env or not films or "R" not in m.names[:3]:
        return []
    h, w = image.shape[:2]
    rgb = image[..., :3].astype(np.float64)
    observers = [o for o in m.observers if o != colorimetry.GROUND_TRUTH]
    out = []
    # the environment as this render shows it, against its CIE colour: the renderer's colour scale
    bg = environment_pixels(scene, w, h)
    if bg.sum() >= MIN_PIXELS:
        def env_stat(obs):
            expected = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz(env["radiance"], obs=obs))
            n = int(bg.sum())
            return stats.compare_means(rgb[bg].mean(axis=0), expected, rgb[bg].std(axis=0, ddof=1) / np.sqrt(n),
                                       dof=n - 1, alpha=alpha)
        stat = env_stat(colorimetry.GROUND_TRUTH)
        expected = np.array(stat["expected"])
        out.append(_probe("environment seen directly", expected, rgb[bg].mean(axis=0), stat["z"], "sigma",
                          stat["pass"], pixels=int(bg.sum()), ratio=rgb[bg].mean(axis=0) / expected, z=stat["z"],
                          stat=stat, alternatives={o: env_stat(o) for o in observers}))
    for i in films:
        obj = scene["objects"][i]
        name = f"airy film {obj['name']}"
        if "material" in obj["bsdf"]:
            out.append(_probe(name, None, None, None, "sigma", None,
                              note="a named conductor's eta/k are the renderer's own table: no independent truth"))
            continue
        images, mask = expected_images(scene, i, w, h, (colorimetry.GROUND_TRUTH, *observers))
        expected = images[colorimetry.GROUND_TRUTH]
        blocks = tiles(mask)
        if mask.sum() < MIN_PIXELS or not blocks:
            out.append(_probe(name, None, None, None, "sigma", None, pixels=int(mask.sum()),
                              note="needs whole pixels of the sphere"))
            continue
        stat = _tile_stat(rgb, expected, blocks, alpha)
        alternatives = {o: _tile_stat(rgb, images[o], blocks, alpha) for o in observers}
        used = np.zeros_like(mask)
        for ys, xs in blocks:
            used[ys, xs] = True
        out.append(_probe(name, expected[used].mean(axis=0), rgb[used].mean(axis=0), stat["z"], "sigma",
                          stat["pass"], pixels=int(used.sum()), tiles=len(blocks), z=stat["z"], stat=stat,
                          alternatives=alternatives, film_nm=float(obj["bsdf"]["thin_film"]["thickness"])))
    return out
