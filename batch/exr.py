"""EXR files through the OpenEXR package: float32 RGB(A) images and named extra channels."""
from pathlib import Path

import numpy as np
import OpenEXR


def write(path, rgb, extra=None, header=None):
    """Write an HxWx3 image as R,G,B (float32) plus ``extra`` {channel name: HxW array}
    (kept in its dtype: float16 arrays are stored as HALF). ZIP compression."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    channels = {"RGB": np.ascontiguousarray(rgb[..., :3], dtype=np.float32)}
    for name, arr in (extra or {}).items():
        channels[name] = np.ascontiguousarray(arr)
    head = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    head.update(header or {})
    with OpenEXR.File(head, channels) as f:
        f.write(str(path))
    return path


NO_COMPRESSION = OpenEXR.NO_COMPRESSION


def write_channels(path, channels, compression=OpenEXR.ZIP_COMPRESSION):
    """Write {channel name: HxW array} as they are (float32 unless float16), e.g. a renderer's raw
    film channels or a pass that is read back at once (``NO_COMPRESSION``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {n: np.ascontiguousarray(a if a.dtype == np.float16 else a.astype(np.float32)) for n, a in channels.items()}
    with OpenEXR.File({"compression": compression, "type": OpenEXR.scanlineimage}, data) as f:
        f.write(str(path))
    return path


def read(path):
    """{channel name: HxW float32 array}; an RGB(A) group is split into R, G, B(, A)."""
    out = {}
    with OpenEXR.File(str(path), separate_channels=True) as f:
        for name, ch in f.channels().items():
            out[name] = np.asarray(ch.pixels, dtype=np.float32)
    return out


def read_rgb(path, prefix=""):
    """HxWx3 float32 from channels <prefix>R, G, B (also Mitsuba's 'RGB' group names)."""
    ch = read(path)
    try:
        return np.stack([ch[prefix + c] for c in "RGB"], axis=-1)
    except KeyError as exc:
        raise ValueError(f"{path}: no channels {prefix}R,G,B (has {sorted(ch)})") from exc


def _order(names):
    """R, G, B first, then the rest by prefix and colour (S0.R, S0.G, S0.B, S1.R, ...)."""
    head = [c for c in ("R", "G", "B", "Y") if c in names]
    rank = {"R": 0, "G": 1, "B": 2}

    def key(n):
        prefix, _, colour = n.rpartition(".")
        return (prefix, rank.get(colour, 3), colour) if prefix else (n, 0, "")
    return head + sorted((n for n in names if n not in head), key=key)


def read_image(path, skip_prefix="stderr."):
    """(channel names, HxWxC float32) of every channel except those starting ``skip_prefix``."""
    names, img, _ = read_image_and_stderr(path)
    return names, img


def read_image_and_stderr(path):
    """(names, HxWxC image, HxWxC standard error or None) from one read: the stderr.<name>
    channels that independent passes write beside the mean."""
    ch = read(path)
    names = _order([n for n in ch if not n.startswith("stderr.")])
    img = np.stack([ch[n] for n in names], axis=-1)
    if not all(f"stderr.{n}" in ch for n in names):
        return names, img, None
    return names, img, np.stack([ch[f"stderr.{n}"] for n in names], axis=-1)


def write_image(path, names, img, extra=None):
    """Write channels ``names`` of an HxWxC image (R, G, B as the RGB group) plus ``extra``."""
    rgb = np.stack([img[..., names.index(c)] for c in "RGB"], axis=-1)
    rest = {n: np.ascontiguousarray(img[..., i], dtype=np.float32) for i, n in enumerate(names) if n not in "RGB"}
    rest.update(extra or {})
    return write(path, rgb, rest)
