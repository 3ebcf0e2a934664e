"""Camera rays and ray/shape intersections in numpy, for locating probe regions in an image.

Only the IR's analytic shapes (rectangles, spheres) are intersected; meshes are ignored, so a
probe is only derived for scenes made of them. Conventions are the IR's (exporters/ir.py).
"""
import numpy as np


CAMERA_FIELDS = ("to_world", "fov", "fov_axis")  # all that camera_rays and camera_rays_at read of a camera


def camera_fields(camera):
    """The fields of ``camera`` that the ray casts here read (not its name, not a polariser): the
    key under which a probe remembers what it computed from the camera's rays, so that scenes
    which differ only in those (iridescent_spheres_film, _height, _materials; polarizing_plane_0
    and _90) share it (issue 45 item 1)."""
    return {k: camera[k] for k in CAMERA_FIELDS if k in camera}


def camera_rays(camera, width, height, points="centers", rows=None):
    """Origins (3,) and unit directions of rays through pixel centers (H, W, 3), pixel corners
    (H+1, W+1, 3), or a point (ox, oy) in [0, 1)^2 inside every pixel (H, W, 3). Pixel (0, 0)
    is the top-left one. ``rows`` (a range of pixel rows) limits the result to those rows."""
    m = np.asarray(camera["to_world"], dtype=np.float64)
    t = np.tan(np.radians(camera["fov"]) / 2)
    tx, ty = (t, t * height / width) if camera.get("fov_axis", "x") == "x" else (t * width / height, t)
    if points == "corners":
        xs, ys = np.arange(width + 1) / width, np.arange(height + 1) / height
    else:
        ox, oy = (0.5, 0.5) if points == "centers" else points
        xs, ys = (np.arange(width) + ox) / width, (np.arange(height) + oy) / height
    if rows is not None:
        ys = ys[rows.start:rows.stop]
    gx, gy = np.meshgrid((2 * xs - 1) * tx, (1 - 2 * ys) * ty)
    local = np.stack([gx, gy, -np.ones_like(gx)], axis=-1)
    d = local @ m[:3, :3].T
    return m[:3, 3], d / np.linalg.norm(d, axis=-1, keepdims=True)


def camera_rays_at(camera, width, height, px, py):
    """Origin and unit directions of rays through continuous image positions (px, py) in pixel
    units (0 at the left/top edge, width/height at the right/bottom edge), any array shape."""
    m = np.asarray(camera["to_world"], dtype=np.float64)
    t = np.tan(np.radians(camera["fov"]) / 2)
    tx, ty = (t, t * height / width) if camera.get("fov_axis", "x") == "x" else (t * width / height, t)
    px, py = np.broadcast_arrays(np.asarray(px, dtype=np.float64), np.asarray(py, dtype=np.float64))
    local = np.stack([(2 * px / width - 1) * tx, (1 - 2 * py / height) * ty, -np.ones_like(px)], axis=-1)
    d = local @ m[:3, :3].T
    return m[:3, 3], d / np.linalg.norm(d, axis=-1, keepdims=True)


def hit_plane(shape, origin, dirs):
    """Distance to the infinite plane of a rectangle (inf where parallel or behind)."""
    m = np.asarray(shape["to_world"], dtype=np.float64)
    inv = np.linalg.inv(m)
    o_local = (inv @ np.append(origin, 1.0))[:3]
    d_local = dirs @ inv[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o_local[2] / d_local[..., 2]
    return np.where(np.isfinite(t) & (t > 1e-9), t, np.inf)


def hit_rectangle(shape, origin, dirs, margin=1.0):
    """Distance t to the rectangle (inf where missed) for rays origin + t * dirs; ``margin``
    < 1 shrinks the rectangle (0.7: its inner 70 %)."""
    m = np.asarray(shape["to_world"], dtype=np.float64)
    inv = np.linalg.inv(m)
    o_local = (inv @ np.append(origin, 1.0))[:3] if np.ndim(origin) == 1 else (
        origin @ inv[:3, :3].T + inv[:3, 3])
    d_local = dirs @ inv[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o_local[..., 2] / d_local[..., 2]
    # the hit point's local x and y alone (its z is 0), in place: the same numbers as
    # o_local + t * d_local per component, 2.5x faster (issue 45 item 1; the probes cast up to
    # 513 x 513 rays at every object; tests/probes/test_probe_speedups.py pins it)
    tt = np.where(np.isfinite(t), t, 0.0)
    x = tt * d_local[..., 0]
    x += o_local[..., 0]
    inside = np.abs(x, out=x) <= margin
    y = np.multiply(tt, d_local[..., 1], out=tt)
    y += o_local[..., 1]
    inside &= np.abs(y, out=y) <= margin
    inside &= t > 1e-9
    return np.where(inside, t, np.inf)


def hit_sphere(shape, origin, dirs):
    c = np.asarray(shape["center"], dtype=np.float64)
    oc = origin - c
    b = np.sum(dirs * oc, axis=-1)
    disc = b * b - (np.sum(oc * oc, axis=-1) - shape["radius"] ** 2)
    with np.errstate(invalid="ignore"):
        s = np.sqrt(disc)
    t0, t1 = -b - s, -b + s
    t = np.where(t0 > 1e-9, t0, np.where(t1 > 1e-9, t1, np.inf))
    return np.where(disc >= 0, t, np.inf)


def hit(shape, origin, dirs, margin=1.0):
    if shape["type"] == "rectangle":
        return hit_rectangle(shape, origin, dirs, margin)
    if shape["type"] == "sphere":
        return hit_sphere(shape, origin, dirs)
    return np.full(dirs.shape[:-1], np.inf)


def nearest(objects, origin, dirs):
    """(index of the nearest object or -1, distance) per ray."""
    ts = np.stack([hit(o["shape"], origin, dirs) for o in objects], axis=0) if objects else np.full(
        (1,) + dirs.shape[:-1], np.inf)
    idx = np.argmin(ts, axis=0)
    t = np.min(ts, axis=0)
    return np.where(np.isfinite(t), idx, -1), t


def rectangle_frame(shape):
    """(center, unit normal, half extents along local x and y) of a rectangle."""
    m = np.asarray(shape["to_world"], dtype=np.float64)
    # the normal of a transformed plane is the inverse transpose applied to +Z
    n = np.linalg.inv(m[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
    return m[:3, 3], n / np.linalg.norm(n), np.linalg.norm(m[:3, 0]), np.linalg.norm(m[:3, 1])


def corner_hits(camera, width, height, objects):
    """(origin, corner ray directions, index of the object each corner ray meets first or -1):
    cast once, shared by every region of an image (pixels_inside)."""
    origin, dirs = camera_rays(camera, width, height, "corners")
    return origin, dirs, nearest(objects, origin, dirs)[0]


def pixels_inside(camera, width, height, objects, index, margin=0.7, hits=None):
    """Mask (H, W) of pixels whose four corners see object ``index`` first, inside its inner
    ``margin`` (for rectangles), so that the whole pixel shows that object. ``hits``: the
    image's corner_hits, when several regions of one image are wanted."""
    origin, dirs, who = hits or corner_hits(camera, width, height, objects)
    ok = who == index
    shape = objects[index]["shape"]
    if shape["type"] == "rectangle":
        ok &= np.isfinite(hit_rectangle(shape, origin, dirs, margin))
    return ok[:-1, :-1] & ok[1:, :-1] & ok[:-1, 1:] & ok[1:, 1:]


def footprint_offsets(k):
    """k x k stratified points inside a pixel (Gauss-Legendre nodes on [0, 1]^2) and their
    weights: the mean over a box-filtered pixel of a smooth function, to O(h^(2k))."""
    x, wts = np.polynomial.legendre.leggauss(k)
    x, wts = (x + 1) / 2, wts / 2
    return [((float(a), float(b)), float(wa * wb)) for a, wa in zip(x, wts) for b, wb in zip(x, wts)]
