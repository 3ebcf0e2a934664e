"""What a .blend may make the exporter open or hold: only regular files are opened, and sizes are
checked before data is read. Without bpy (extract_blender.py and batch/blend_input.py call it).

A small .blend can name a FIFO or a device as a linked library or an image (opening it waits
forever), or describe data far larger than itself (a generated 4096 x 4096 image, a cube with a
level-9 subdivision). So:

- ``file_problem``: a path is opened only when it is a regular file (``os.stat`` and
  ``stat.S_ISREG`` before any open; a symbolic link is followed to what it names, and that must be a
  regular file), and not inside the kernel's pseudo file systems (/proc, /sys, /dev).
- ``library_paths``: the linked libraries of a .blend, read from its file blocks without Blender
  (Blender opens every linked library when it opens the file, before any check could run).
- The caps below: an image is refused when its pixel count, read from its file's header (or from a
  generated image's settings) without reading pixels, is above ``MAX_IMAGE_PIXELS``; a mesh when
  its predicted size (subdivision: 4^levels faces per base quad) or its evaluated size is above
  ``MAX_MESH_TRIANGLES`` / ``MAX_MESH_VERTICES``, or would take the scene's meshes above
  ``MAX_SCENE_TRIANGLES`` / ``MAX_SCENE_VERTICES``, checked before any list of it is built.
"""
import gzip
import os
import stat
import struct
from pathlib import Path

# one environment map: its mean is computed from a float32 copy of its pixels (16 bytes a pixel,
# besides Blender's own buffer): 4096 x 2048, a 4K equirectangular map, is ~130 MB a copy
MAX_IMAGE_PIXELS = 1 << 23
# one evaluated mesh object of a Blender scene (its IR lists cost ~150 bytes a vertex or triangle)
MAX_MESH_TRIANGLES = 1 << 20
MAX_MESH_VERTICES = 1 << 20
# all the mesh objects of one Blender scene (the IR's own cap on one list is exporters/validate.py's)
MAX_SCENE_TRIANGLES = 1 << 21
MAX_SCENE_VERTICES = 1 << 21
# linked libraries followed from one .blend (libraries of libraries included)
MAX_LIBRARIES = 256
# Blender evaluates the modifiers of a file's active scene while it opens the file, before any check
# can run (an 84 kB file: a cube in an array of 4 million, 1.9 GB): a .blend with a modifier that
# multiplies geometry beyond these settings is first opened in a trial process (batch/blend_input.py),
# killed at TRIAL_MEMORY bytes resident (bpy alone is ~0.3 GB) or after TRIAL_SECONDS
GROWING_MODIFIERS = {  # DNA struct: (its fields, the largest value opened without a trial)
    "SubsurfModifierData": (("levels", "renderLevels"), 6), "MultiresModifierData": (("lvl", "renderlvl"), 6),
    "ArrayModifierData": (("count",), 1000), "ScrewModifierData": (("steps", "render_steps", "iter"), 1000),
    "RemeshModifierData": (("depth",), 8), "OceanModifierData": (("resolution",), 16),
    "NodesModifierData": ((), -1)}  # geometry nodes: anything
TRIAL_MEMORY = 3 << 30
TRIAL_SECONDS = 120
PSEUDO_FILE_SYSTEMS = ("/proc", "/sys", "/dev")


def file_kind(mode):
    """A file type in words, for a message."""
    for test, word in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder")):
        if test(mode):
            return word
    return "not a regular file"


def file_problem(path):
    """Why ``path`` must not be opened (text), or None: it is a regular file outside /proc, /sys and
    /dev. A path that does not exist is "no such file"."""
    try:
        real = os.path.realpath(path)
        st = os.stat(real)
    except OSError as exc:
        return f"{str(path)!r}: {exc.strerror or exc}"
    if not stat.S_ISREG(st.st_mode):
        return f"{str(path)!r} is {file_kind(st.st_mode)}, not a regular file: not opened"
    for top in PSEUDO_FILE_SYSTEMS:
        if real == top or real.startswith(top + "/"):
            return f"{str(path)!r} is {real!r}, inside {top} (a kernel pseudo file system): not opened"
    return None


def image_header_size(path):
    """(width, height) of an image file from its header (OpenImageIO reads no pixels for it; where
    its Python module is missing, as in some Blender builds, ``header_size`` reads PNG, JPEG,
    Radiance HDR and OpenEXR headers), or None when no reader knows the file. Call only after
    ``file_problem(path)`` is None."""
    try:
        import OpenImageIO as oiio
    except ImportError:
        with open(path, "rb") as f:
            return header_size(f.read(1 << 16))
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()  # clears OpenImageIO's error
        return None
    try:
        spec = inp.spec()
        return int(spec.full_width or spec.width), int(spec.full_height or spec.height)
    finally:
        inp.close()


def header_size(head):
    """(width, height) from the first bytes of a PNG, JPEG, Radiance HDR or OpenEXR file (its
    data window), or None."""
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        return struct.unpack(">II", head[16:24])
    if head[:4] == b"\x76\x2f\x31\x01":  # OpenEXR: attributes (name, type, size, value) up to an empty name
        pos = 8
        while pos < len(head) and head[pos] != 0:
            name_end = head.index(b"\0", pos)
            type_end = head.index(b"\0", name_end + 1)
            size, = struct.unpack_from("<i", head, type_end + 1)
            if head[pos:name_end] == b"dataWindow" and size == 16:
                x0, y0, x1, y1 = struct.unpack_from("<4i", head, type_end + 5)
                return x1 - x0 + 1, y1 - y0 + 1
            pos = type_end + 5 + size
        return None
    if head[:2] == b"#?":  # Radiance: text lines up to an empty one, then "-Y h +X w"
        lines = head.split(b"\n")
        for i, line in enumerate(lines[:-1]):
            if not line.strip():
                parts = lines[i + 1].split()
                if len(parts) == 4 and parts[0][1:2] in (b"Y", b"X") and parts[2][1:2] in (b"Y", b"X"):
                    a, b = int(parts[1]), int(parts[3])
                    return (b, a) if parts[0][1:2] == b"Y" else (a, b)
                return None
        return None
    if head[:2] == b"\xff\xd8":  # JPEG: the first start-of-frame segment
        pos = 2
        while pos + 9 <= len(head) and head[pos] == 0xFF:
            marker, length = head[pos + 1], struct.unpack(">H", head[pos + 2:pos + 4])[0]
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                h, w = struct.unpack(">HH", head[pos + 5:pos + 9])
                return w, h
            pos += 2 + length
        return None
    return None


def image_bytes_size(data):
    """(width, height) of an image held in memory (a packed image's bytes), from its header."""
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "packed"
        path.write_bytes(data)
        return image_header_size(path)


def subdivided(counts, modifiers, render):
    """Predicted (vertices, triangles, fields) of a mesh of ``counts`` (vertices, polygons, loops)
    after the subdivision modifiers (Subdivision Surface, Multiresolution) of its stack that
    evaluation applies (``render``: their render levels, else the viewport's), without evaluating
    it: a level-1 subdivision makes one quad per face corner, each further level 4 of each quad; 2
    triangles a quad. ``fields`` names the levels that were counted ("modifiers[Subdivision].levels").
    Other modifiers are not predicted (the evaluated size is checked before it is read)."""
    verts, polys, loops = counts
    tris, fields = loops - 2 * polys, []
    quads = None
    for mod in modifiers:
        if mod.type not in ("SUBSURF", "MULTIRES") or not (mod.show_render if render else mod.show_viewport):
            continue
        field = "render_levels" if render else "levels"
        levels = int(getattr(mod, field))
        if levels <= 0:
            continue
        quads = (loops if quads is None else quads * 4) * 4 ** (levels - 1)
        tris, verts = 2 * quads, quads + 2  # a closed quad mesh has about as many vertices as quads
        fields.append(f"modifiers[{mod.name}].{field}")
    return verts, tris, fields


# --- linked libraries, read from the .blend's file blocks


class BlendScanError(Exception):
    pass


def _reader(path):
    """A binary stream of the .blend's uncompressed bytes (zstd, gzip or none)."""
    f = open(path, "rb")  # noqa: SIM115 - the caller closes it
    magic = f.read(4)
    f.seek(0)
    if magic == b"\x28\xb5\x2f\xfd":
        import zstandard
        return zstandard.ZstdDecompressor().stream_reader(f, closefd=True)
    if magic[:2] == b"\x1f\x8b":
        return gzip.GzipFile(fileobj=f)
    return f


def _read(stream, n):
    out = bytearray()
    while len(out) < n:
        chunk = stream.read(min(n - len(out), 1 << 20))
        if not chunk:
            raise BlendScanError("the file ends inside a block")
        out += chunk
    return bytes(out)


def _skip(stream, n):
    while n > 0:
        chunk = stream.read(min(n, 1 << 20))
        if not chunk:
            raise BlendScanError("the file ends inside a block")
        n -= len(chunk)


def _header(stream):
    """(pointer size, endian prefix, block header size) from the file header."""
    head = stream.read(12)
    if len(head) < 12 or not head.startswith(b"BLENDER"):
        return None
    if head[7:9].isdigit():  # BLENDER17-01v0500: header size 17, file format 1 (Blender 5.0)
        size = int(head[7:9])
        head += _read(stream, size - 12)
        return 8, "<" if head[12:13] == b"v" else ">", "v1"
    return (8 if head[7:8] == b"-" else 4), ("<" if head[8:9] == b"v" else ">"), "v0"


def _bhead(stream, psize, end, kind):
    """(code, sdna index, data length, count) of the next block."""
    if kind == "v1":  # int code, int SDNAnr, uint64 old, int64 len, int64 nr
        raw = _read(stream, 32)
        code, sdna, _old, length, nr = struct.unpack(end + "4si Q q q", raw)
    elif psize == 8:  # int code, int len, uint64 old, int SDNAnr, int nr
        code, length, _old, sdna, nr = struct.unpack(end + "4si Q i i", _read(stream, 24))
    else:
        code, length, _old, sdna, nr = struct.unpack(end + "4si I i i", _read(stream, 20))
    return code, sdna, length, nr


def _sdna(data, psize, end):
    """{struct name: {field name: (offset, size)}} from a DNA1 block."""
    pos = 8  # "SDNA" "NAME"
    def ints(n):
        nonlocal pos
        out = struct.unpack_from(end + f"{n}i", data, pos)
        pos += 4 * n
        return out

    def strings(n):
        nonlocal pos
        out = []
        for _ in range(n):
            stop = data.index(b"\0", pos)
            out.append(data[pos:stop].decode("latin-1"))
            pos = stop + 1
        pos = (pos + 3) & ~3
        return out
    names = strings(ints(1)[0])
    pos += 4  # "TYPE"
    types = strings(ints(1)[0])
    pos += 4  # "TLEN"
    lengths = struct.unpack_from(end + f"{len(types)}h", data, pos)
    pos = (pos + 2 * len(types) + 3) & ~3
    pos += 4  # "STRC"
    structs = {}
    for _ in range(ints(1)[0]):
        stype, nfields = struct.unpack_from(end + "2h", data, pos)
        pos += 4
        fields, offset = {}, 0
        for _ in range(nfields):
            ftype, fname = struct.unpack_from(end + "2h", data, pos)
            pos += 4
            name = names[fname]
            count = 1
            for dim in name.split("[")[1:]:
                count *= int(dim.rstrip("]"))
            size = (psize if name.startswith("*") or name.startswith("(*") else lengths[ftype]) * count
            fields[name.split("[")[0].lstrip("*")] = (offset, size)
            offset += size
        structs[types[stype]] = fields
    return structs


def _blocks(path, keep):
    """(pointer size, endian, DNA1 data or None, [(code, sdna index, data)] of the blocks for which
    ``keep(code, sdna index)`` is true), or None when the file is no .blend."""
    with _reader(path) as stream:
        head = _header(stream)
        if head is None:
            return None
        psize, end, kind = head
        kept, sdna = [], None
        while True:
            code, index, length, _nr = _bhead(stream, psize, end, kind)
            if code == b"ENDB":
                break
            if length < 0:
                raise BlendScanError("a block of negative length")
            if code == b"DNA1":
                sdna = _read(stream, length)
            elif keep(code, index):
                if len(kept) >= 100000:
                    raise BlendScanError("more than 100000 blocks of one kind")
                part = min(length, 1 << 16)
                kept.append((code, index, _read(stream, part)))
                _skip(stream, length - part)
            else:
                _skip(stream, length)
    return psize, end, sdna, kept


def library_paths(path):
    """The linked libraries' file paths stored in the .blend at ``path``, as Blender stores them
    (``//`` relative to the file), without opening any of them; None when the file is no .blend
    (Blender itself then says what it is). Raises BlendScanError when a .blend's blocks cannot be
    read."""
    scan = _blocks(path, lambda code, index: code == b"LI\0\0")
    if scan is None:
        return None
    psize, end, sdna, libs = scan
    if len(libs) > MAX_LIBRARIES:
        raise BlendScanError(f"more than {MAX_LIBRARIES} linked libraries")
    if not libs:
        return []
    if sdna is None:
        raise BlendScanError("linked libraries but no DNA1 block")
    fields = _sdna(sdna, psize, end).get("Library", {})
    # the path's field: "filepath" (2.8 to 4.x; 5.0's DNA calls it "name"), "filepath_abs" or an
    # older "name": every one present is read, so no version's path is missed
    found = [fields[k] for k in ("filepath", "name", "filepath_abs") if k in fields and fields[k][1] >= 64]
    if not found:
        raise BlendScanError("no Library.filepath in the file's DNA")
    out = []
    for _code, _index, raw in libs:
        for offset, size in found:
            text = raw[offset:offset + size].split(b"\0", 1)[0].decode("utf-8", "replace")
            if text and text not in out:
                out.append(text)
    return out


def growing_modifiers(path):
    """["modifiers[Array] (count 4000000)", ...]: the modifiers stored in the .blend at ``path`` that
    can multiply its geometry beyond GROWING_MODIFIERS' settings (read from the file's blocks, two
    passes: the DNA comes last); [] when none, None when the file is no .blend."""
    first = _blocks(path, lambda code, index: False)
    if first is None:
        return None
    psize, end, sdna, _ = first
    if sdna is None:
        raise BlendScanError("no DNA1 block")
    structs = _sdna(sdna, psize, end)
    order = list(structs)
    wanted = {i for i, name in enumerate(order) if name in GROWING_MODIFIERS}
    if not wanted:
        return []
    _, _, _, blocks = _blocks(path, lambda code, index: code == b"DATA" and index in wanted)
    base = structs.get("ModifierData", {})
    out = []
    for _code, index, raw in blocks:
        name_struct = order[index]
        fields, most = GROWING_MODIFIERS[name_struct]
        own = structs[name_struct]
        values = {}
        for field in fields:
            if field in own and own[field][1] in (1, 2, 4):
                offset, size = own[field]
                if offset + size <= len(raw):
                    values[field] = struct.unpack_from(end + {1: "B", 2: "h", 4: "i"}[size], raw, offset)[0]
        if most >= 0 and all(v <= most for v in values.values()):
            continue
        label = name_struct[:-len("ModifierData")]
        if "name" in base:
            offset, size = base["name"]
            label = raw[offset:offset + size].split(b"\0", 1)[0].decode("utf-8", "replace") or label
        shown = ", ".join(f"{k} {v}" for k, v in values.items()) or "geometry nodes"
        out.append(f"modifiers[{label}] ({shown})")
    return out


def library_problem(blend):
    """Why the .blend at ``blend`` must not be opened (text naming the library and its path), or
    None: each linked library, and theirs in turn, that exists must be a regular file (a missing one
    Blender reports itself)."""
    seen, todo = set(), [Path(blend)]
    while todo:
        current = todo.pop()
        try:
            paths = library_paths(current)
        except Exception as exc:  # noqa: BLE001 - any fault of a hostile file: it is not opened
            return f"{str(current)!r}: its linked libraries cannot be read: {exc}"
        for lib in paths or ():
            full = Path(os.path.normpath(current.parent / lib[2:] if lib.startswith("//") else Path(lib)))
            if full in seen:
                continue
            seen.add(full)
            if len(seen) > MAX_LIBRARIES:
                return f"more than {MAX_LIBRARIES} linked libraries (libraries of libraries included)"
            if not os.path.lexists(full):
                continue
            problem = file_problem(full)
            if problem:
                via = "" if current == Path(blend) else f" (a library of {str(current)!r})"
                return f"linked library {lib!r}{via}: {problem}"
            todo.append(full)
    return None
