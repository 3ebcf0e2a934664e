"""Image textures of the IR (docs/scene-format.md 6.7): a diffuse BSDF's ``reflectance_texture``.

    "reflectance_texture": {"file": "textures/floor.png", "colour_space": "srgb", "filter": "bilinear"}

The reflectance at a surface point is the image's colour at the point's texture coordinates,
decoded to linear sRGB by ``colour_space`` ("srgb": the IEC 61966-2-1 transfer function, as
Blender's "sRGB" colour space; "linear": the values as stored, Blender's "Non-Color" and "Linear
Rec.709"), and uplifted to a reflectance spectrum by the renderer's own RGB-to-spectrum method
(WRITERS below says which). Texture coordinates come from the mesh's ``uvs`` (one (u, v) per
vertex; (0, 0) is the image's bottom-left corner and (1, 1) its top-right, as in Blender), and the
image repeats outside [0, 1]. ``filter``: "bilinear" (Blender's Linear) or "nearest" (Closest).
The BSDF's ``reflectance`` is the texture's mean colour uplifted: what a check that reads one
reflectance per object sees (a renderer that cannot take a texture is ``unsupported``, never given
the mean silently).

The file is data from outside: a relative path inside the scene's folder (no absolute path, no
'..', no link leading out), a regular file (never a FIFO or a device: ``blend_safety.file_problem``
before any open), at most MAX_FILE_BYTES, of a format in FORMATS, whose header says at most
``blend_safety.MAX_IMAGE_PIXELS`` pixels, all checked before a pixel is read. The renderers'
writers write it decoded, as linear float OpenEXR, into their export folder as
``textures/<object>_reflectance.exr`` (the object's checked name); the scene file export copies
the file as it is (with its colour space). An export never points outside itself.
"""
import shutil
from pathlib import Path

import numpy as np

from . import blend_safety, names

FORMATS = (".png", ".jpg", ".jpeg", ".exr", ".hdr", ".tif", ".tiff")
MAX_FILE_BYTES = 256 << 20
COLOUR_SPACES = ("srgb", "linear")
FILTERS = ("bilinear", "nearest")
FIELD = "bsdf.reflectance_texture"
# the uplift each backend's renderer applies to an RGB texture (docs/backends.md says the same)
UPLIFTS = {
    "mitsuba": "Mitsuba 3's spectral variants: Jakob and Hanika 2019 coefficients (its srgb2spec table) per texel",
    "pbrt": "pbrt-v4: RGBAlbedoSpectrum, Jakob and Hanika 2019's sigmoid fitted per texel in sRGB",
}


def relative_problem(raw):
    """Why ``raw`` cannot name a file inside a scene's folder (text), or None."""
    rel = Path(raw)
    if not raw or rel.is_absolute() or raw.startswith(("/", "\\")) or ".." in rel.parts or "\\" in raw \
            or any(ord(c) < 32 for c in raw):
        return (f"{raw!r}: an image file must be a relative path inside the scene's folder (no absolute path, "
                "no '..', no backslash or control character)")
    return None


def resolve(tex, base_dir):
    """(absolute path, None) of a texture's file, or (None, why not): every check of the module
    docstring, the header's size included, without reading a pixel. A path the system refuses
    (a name too long, ...) is a why, not an error."""
    try:
        return _resolve(tex, base_dir)
    except (OSError, ValueError) as exc:
        return None, f"{tex['file']!r}: {getattr(exc, 'strerror', None) or exc}"


def _resolve(tex, base_dir):
    raw = tex["file"]
    why = relative_problem(raw)
    if why:
        return None, why
    base = Path(base_dir or ".").resolve()
    path = (base / raw).resolve()
    if base not in path.parents:
        return None, f"{raw!r} resolves to {path}, outside the scene's folder {base} (a link?)"
    if not path.exists():
        return None, f"{raw!r}: no such file ({path})"
    refused = blend_safety.file_problem(path)
    if refused:
        return None, refused
    if path.suffix.lower() not in FORMATS:
        return None, f"{raw!r}: a texture is one of {', '.join(FORMATS)}"
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        return None, f"{raw!r} is {size} bytes, above the cap of {MAX_FILE_BYTES} (MAX_FILE_BYTES, exporters/textures.py)"
    dims = blend_safety.image_header_size(str(path))
    if dims is None:
        return None, f"{raw!r} is no image whose size can be read from its header"
    if dims[0] <= 0 or dims[1] <= 0 or dims[0] * dims[1] > blend_safety.MAX_IMAGE_PIXELS:
        return None, (f"{raw!r} is {dims[0]} x {dims[1]} pixels, outside 1 to {blend_safety.MAX_IMAGE_PIXELS} "
                      "(MAX_IMAGE_PIXELS, exporters/blend_safety.py)")
    return path, None


def problems(tex, base_dir):
    """[(field, message)] of a ``reflectance_texture`` (the schema checked its keys and enums)."""
    _path, why = resolve(tex, base_dir)
    return [(f"{FIELD}.file", why)] if why else []


def decode(values, colour_space):
    """Stored values -> linear sRGB (IEC 61966-2-1's decoding for "srgb")."""
    v = np.asarray(values, dtype=np.float64)
    if colour_space == "linear":
        return v
    return np.where(v <= 0.04045, v / 12.92, ((np.clip(v, 0.04045, None) + 0.055) / 1.055) ** 2.4)


def read_linear(tex, base_dir):
    """H x W x 3 linear sRGB of a texture, row 0 the image's top (raises ValueError naming why)."""
    path, why = resolve(tex, base_dir)
    if why:
        raise ValueError(why)
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"{tex['file']!r}: {oiio.geterror() or 'not readable'}")
    try:
        px = inp.read_image("float")
    finally:
        inp.close()
    if px is None:
        raise ValueError(f"{tex['file']!r}: {oiio.geterror() or 'no pixels'}")
    px = np.asarray(px, dtype=np.float64)
    px = px.reshape(px.shape[0], px.shape[1], -1)
    rgb = px[..., :3] if px.shape[-1] >= 3 else np.repeat(px[..., :1], 3, axis=-1)
    return decode(rgb, tex.get("colour_space", "linear" if tex.get("type") == "map" else "srgb"))


def mean_rgb(tex, base_dir):
    """The texture's mean linear sRGB over its texels."""
    return read_linear(tex, base_dir).reshape(-1, 3).mean(axis=0)


def copy_into(tex, obj_name, base_dir, out_dir, stem=None):
    """Copy the texture's file into ``out_dir``/textures/ under the object's checked name; returns
    the path relative to ``out_dir`` (forward slashes)."""
    path, why = resolve(tex, base_dir)
    if why:
        raise ValueError(f"object {obj_name!r}, {FIELD}.file: {why}")
    rel = f"textures/{stem or names.file_stem(obj_name) + '_reflectance'}{path.suffix.lower()}"
    dest = Path(out_dir) / rel
    dest.parent.mkdir(parents=True, exist_ok=True)
    if not (dest.exists() and dest.resolve() == path):  # a scene file rewritten where it was read
        shutil.copyfile(path, dest)
    return rel


def write_linear(tex, obj_name, base_dir, out_dir, stem=None):
    """The texture decoded to linear sRGB (``read_linear``) and written as a float OpenEXR file in
    ``out_dir``/textures/ under the object's checked name; returns its path relative to
    ``out_dir``. What the renderers' writers give them: one linear file, whatever the source's
    format and colour space, so no renderer applies a transfer function of its own (Mitsuba's
    bitmap decodes an 8-bit file as sRGB unless told ``raw``, which would also turn off its
    spectral uplift)."""
    rel = f"textures/{stem or names.file_stem(obj_name) + '_reflectance'}.exr"
    write_exr(read_linear(tex, base_dir), Path(out_dir) / rel)
    return rel


def write_exr(rgb, dest):
    """An H x W x 3 image as a float OpenEXR file at ``dest`` (its folder made)."""
    import OpenImageIO as oiio
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(dest))
    if out is None or not out.open(str(dest), oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, "float")):
        raise ValueError(f"cannot write {dest}: {oiio.geterror()}")
    try:
        if not out.write_image(rgb):
            raise ValueError(f"cannot write {dest}: {out.geterror()}")
    finally:
        out.close()
    return dest


# -- environment maps (docs/scene-format.md 7.1): the same file rules, an equirectangular image --
def equirect_directions(width, height):
    """World directions (H x W x 3, z up) of an equirectangular image's texel centres in the IR's
    (Blender's) convention, rotation 0: column u = (x + 0.5) / W is the azimuth phi = pi (1 - 2u)
    about +Z from +X (u = 0.5: +X; u = 0.25: +Y), row v = (y + 0.5) / H from the top is the
    polar angle theta = pi v from +Z."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    phi = np.pi * (1.0 - 2.0 * u)[None, :]
    theta = np.pi * v[:, None]
    return np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)),
                    axis=-1)


def map_mean_rgb(rgb):
    """The mean of an equirectangular image (H x W x 3) over the sphere: rows weighted by their
    solid angle (sin theta)."""
    h = rgb.shape[0]
    w = np.sin(np.pi * (np.arange(h) + 0.5) / h)
    return (rgb * w[:, None, None]).sum(axis=(0, 1)) / (w.sum() * rgb.shape[1])


def equal_area_square_directions(n):
    """Directions (n x n x 3) of the texel centres of an equal-area octahedral square image, row 0
    first: the mapping pbrt-v4's image infinite light reads (Clarberg, "Fast equal-area mapping of
    the (hemi)sphere using SIMD", JGT 13(3), 2008; pbrt-v4 util/math.cpp EqualAreaSquareToSphere),
    texel (row i, column j) at (u, v) = ((j + 0.5) / n, (i + 0.5) / n)."""
    c = (np.arange(n) + 0.5) / n
    u, v = np.meshgrid(2 * c - 1, 2 * c - 1)  # u across (columns), v down (rows)
    up, vp = np.abs(u), np.abs(v)
    signed = 1 - (up + vp)
    r = 1 - np.abs(signed)
    phi = np.where(r == 0, 1.0, (vp - up) / np.where(r == 0, 1.0, r) + 1) * np.pi / 4
    z = np.copysign(1 - r * r, signed)
    s = r * np.sqrt(np.clip(2 - r * r, 0, None))
    return np.stack([np.copysign(np.cos(phi), u) * s, np.copysign(np.sin(phi), v) * s, z], axis=-1)


def equirect_lookup(rgb, directions, rotation=0.0):
    """Bilinear lookup of an equirectangular map (H x W x 3, the IR's convention, turned by
    ``rotation`` degrees about +Z) at world ``directions`` (... x 3): u wraps, v clamps."""
    h, w = rgb.shape[:2]
    a = np.radians(rotation)
    x, y, z = (directions[..., k] for k in range(3))
    xr, yr = np.cos(a) * x + np.sin(a) * y, -np.sin(a) * x + np.cos(a) * y  # Rz(-rotation) d
    phi = np.arctan2(yr, xr)
    theta = np.arccos(np.clip(z, -1, 1))
    fx = ((0.5 - phi / (2 * np.pi)) % 1.0) * w - 0.5
    fy = np.clip(theta / np.pi * h - 0.5, 0, h - 1)
    x0, y0 = np.floor(fx).astype(int), np.floor(fy).astype(int)
    tx, ty = (fx - x0)[..., None], (fy - y0)[..., None]
    x0, x1 = x0 % w, (x0 + 1) % w
    y1 = np.minimum(y0 + 1, h - 1)
    return ((1 - ty) * ((1 - tx) * rgb[y0, x0] + tx * rgb[y0, x1]) + ty * ((1 - tx) * rgb[y1, x0] + tx * rgb[y1, x1]))


def write_equal_area(env, base_dir, out_dir, stem="environment"):
    """The map resampled to pbrt-v4's equal-area octahedral square (side sqrt(W H), at least 16,
    bilinear), the rotation applied, written as linear float OpenEXR; returns its path relative to
    ``out_dir``."""
    rgb = read_linear(env, base_dir)
    n = max(16, int(round(np.sqrt(rgb.shape[0] * rgb.shape[1]))))
    rel = f"textures/{stem}.exr"
    write_exr(equirect_lookup(rgb, equal_area_square_directions(n), float(env.get("rotation", 0.0))), Path(out_dir) / rel)
    return rel


def env_map(env):
    """Whether an IR environment is a map."""
    return bool(env) and env.get("type") == "map"


def textured(obj):
    """The object's ``reflectance_texture`` or None."""
    return (obj.get("bsdf") or {}).get("reflectance_texture")
