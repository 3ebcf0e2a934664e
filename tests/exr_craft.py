"""Crafted EXR files for the tests of hostile inputs: real OpenEXR files (the OpenEXR library reads
them), built from a strip the library itself writes, so a huge image costs a few MB of disk and no
memory to make.

``bomb(path, width, height)``: a ZIP-compressed scanline image of ``height`` rows of zeros, made
from one 16-row block that OpenEXR writes (ZIP keeps 16 rows per block) repeated with its row
number changed: 20000 x 20000 x 3 HALF channels is about 2.5 MB on disk and 2.4 GB of pixels."""
import struct
from pathlib import Path

import numpy as np
import OpenEXR

ROWS = 16  # ZIP_COMPRESSION's rows per block


def _attributes(buf):
    """{name: (offset of its value, size)} of a single-part header, and the header's end."""
    pos, out = 8, {}
    while buf[pos] != 0:
        end = buf.index(b"\0", pos)
        name = buf[pos:end].decode()
        pos = buf.index(b"\0", end + 1) + 1
        size = struct.unpack_from("<i", buf, pos)[0]
        out[name] = (pos + 4, size)
        pos += 4 + size
    return out, pos + 1


def bomb(path, width, height, channels=("B", "G", "R")):
    """Write the crafted image to ``path`` (height a multiple of 16)."""
    assert height % ROWS == 0
    path = Path(path)
    strip = path.with_name(path.name + ".strip")
    zeros = np.zeros((ROWS, width), np.float16)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {c: zeros for c in channels}) as f:
        f.write(str(strip))
    buf = bytearray(strip.read_bytes())
    strip.unlink()
    attrs, end = _attributes(buf)
    (offset,) = struct.unpack_from("<Q", buf, end)
    y, size = struct.unpack_from("<ii", buf, offset)
    payload = bytes(buf[offset + 8:offset + 8 + size])
    header = bytearray(buf[:end])
    for name in ("dataWindow", "displayWindow"):
        at, _ = attrs[name]
        struct.pack_into("<iiii", header, at, 0, 0, width - 1, height - 1)
    blocks = height // ROWS
    first = len(header) + 8 * blocks
    chunk = 8 + len(payload)
    with open(path, "wb") as f:
        f.write(header)
        f.write(struct.pack(f"<{blocks}Q", *(first + k * chunk for k in range(blocks))))
        for k in range(blocks):
            f.write(struct.pack("<ii", k * ROWS, len(payload)))
            f.write(payload)
    return path
