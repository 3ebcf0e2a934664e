"""Reference images: references/<scene>.exr (the mean of every channel the scene outputs, R, G,
B and, for Stokes scenes, S0.R ... S3.B; the standard error of that mean per pixel as
stderr.<channel>) and references/<scene>.json (provenance).

A reference records the fingerprint of the scene it was rendered from: everything that
determines the expected image, i.e. the IR without the sample count and names, with every named
spectrum and named conductor replaced by its table and every mesh file by a hash of its contents
(a changed data file or mesh changes the scene). A changed scene makes the reference stale, and
stale references are never used for a verdict. The renderer and its version are provenance, not
fingerprint: a reference exists to judge other versions (and renderers) against; every job shows
the versions of both. References change only through ``batch/make_references.py`` (an explicit
request; it replaces an existing reference only with ``--replace``).

Every candidate is checked before it is used (``search``): a readable record, a readable EXR
with its noise channels, channels and a resolution the render can be judged with, the scene's
fingerprint and, for records written by ``save`` since it records one, the image's sha256. A
broken, wrong-sized or stale candidate is passed over for the next folder and reported with its
file. ``save`` writes unique temporary files, syncs them and renames them into place under the
scene's lock, the record (with the image's hash) first: a reader between the two renames, or
after a crash between them, sees a record that does not match its image and passes it over.
Records written before the hash was recorded (no exr_sha256) are accepted as they are.

A replaced reference is kept, not overwritten (``replace``, for ``make_references.py --replace``):
its record and image move to <references>/history/<scene>/<UTC time>-<backend>/ beside a
``replaced.json`` record (who replaced it, why: the verdict of the new against the old on both
noises, the command). A search never reads history: it looks only at <folder>/<scene>.exr and
.json, and a folder holding a ``replaced.json`` is refused as a candidate even when named directly.

A write never replaces another scene's file (``refuse_collision``, issue 40): where
``<scene>.exr|.json`` is an observer layer of scene S kept in the old layout (``S.<observer>.exr``,
S's record naming it) or a record of another scene (a file system that ignores case), ``save`` and
``replace`` raise ``Collision`` naming both. Observer layers themselves live in
``<folder>/layers/<scene>/`` (batch/verdict/observer_layers.py), where no scene's reference is.
"""
import copy
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ...exporters import ir_json, mesh_io, spectra
from .. import exr

REFERENCE_DIR = Path(__file__).resolve().parents[2] / "references"


def _resolved(node, base_dir):
    """The IR with named spectra and conductors replaced by their tables and mesh files by hashes
    of their contents (in place)."""
    if isinstance(node, dict):
        if node.get("type") == "named" and "name" in node and node["name"] in spectra.named_spectra():
            wl, values = spectra.tabulate(node)
            node["table"] = [[round(float(w), 6), round(float(v), 9)] for w, v in zip(wl, values)]
        if node.get("type") == "conductor" and "material" in node:
            node["tables"] = [spectra.tabulate(s)[1].round(9).tolist() for s in spectra.named_conductor(node["material"])]
        if node.get("type") == "mesh" and "file" in node:
            verts, faces = mesh_io.load_mesh(node, base_dir)
            node["file"] = hashlib.sha256(np.asarray(verts, dtype=np.float64).tobytes()
                                          + np.asarray(faces, dtype=np.int64).tobytes()).hexdigest()
        for v in node.values():
            _resolved(v, base_dir)
    elif isinstance(node, list):
        for v in node:
            _resolved(v, base_dir)
    return node


def fingerprint(scene):
    """sha256 of what determines the expected image: the IR without the sample count, the
    description and the names of the scene's objects (objects sorted by content), with the data
    behind named spectra, conductors and mesh files resolved."""
    data = _resolved(copy.deepcopy({k: v for k, v in scene.items() if not k.startswith("_")}), scene.get("_base_dir"))
    data["render"].pop("spp", None)
    for key in ("description", "name", "case", "warnings"):
        data.pop(key, None)
    data["camera"].pop("name", None)
    for obj in data["objects"]:
        obj.pop("name", None)
    data["objects"].sort(key=lambda o: json.dumps(o, sort_keys=True))
    for light in data.get("lights", []):
        light.pop("name", None)
    data.get("lights", []).sort(key=lambda o: json.dumps(o, sort_keys=True))
    return hashlib.sha256(ir_json.dumps(data).encode()).hexdigest()


class Reference:
    def __init__(self, names, mean, stderr, provenance, path):
        self.names, self.mean, self.stderr, self.provenance, self.path = names, mean, stderr, provenance, path

    @property
    def spp(self):
        return self.provenance["spp"]


def directories(directory=None):
    """The reference folders to search, in order: None -> references/; one path; or a list of
    paths (the Blender extension passes the user's folder and its own)."""
    if not directory:
        return [REFERENCE_DIR]
    if isinstance(directory, (str, Path)):
        return [Path(directory)]
    return [Path(d) for d in directory] or [REFERENCE_DIR]


def problem(path, text):
    """One reference problem as every report shows it: the file and what is wrong with it."""
    return {"file": str(path), "problem": text}


def sha256_of(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _shown(value, limit=60):
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _positive_int(value):
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


def read_record(meta_path):
    """(record, None) or (None, what is wrong) for a reference's JSON record."""
    try:
        meta = json.loads(Path(meta_path).read_bytes().decode("utf-8"))
    except (OSError, ValueError) as exc:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        return None, f"unreadable record: {exc}"
    except RecursionError:
        return None, "unreadable record: nested too deeply"
    if not isinstance(meta, dict):
        return None, f"not a reference record: a JSON {type(meta).__name__}, not an object"
    if not isinstance(meta.get("fingerprint"), str):
        return None, "not a reference record: no fingerprint"
    if not _positive_int(meta.get("spp")):
        return None, f"record field spp is {_shown(meta.get('spp'))}, not a positive integer"
    if "passes" in meta and not _positive_int(meta["passes"]):
        return None, f"record field passes is {_shown(meta['passes'])}, not a positive integer"
    if "exr_sha256" in meta and not isinstance(meta["exr_sha256"], str):
        return None, f"record field exr_sha256 is {_shown(meta['exr_sha256'])}, not a string"
    return meta, None


def usable_for(ref, shape=None, names=None):
    """None if the reference's image can judge a render of ``shape`` (H, W, ...) with channels
    ``names`` (either may be None: not checked), else why not. What batch/verdict/compare.py
    ``reference_at`` and the noise test can use: colour channels R, G, B shared with the render,
    and a resolution that is the render's times an integer in each axis (the factors may differ)."""
    shared = [n for n in ref.names if names is None or n in names]
    if shared[:3] != ["R", "G", "B"]:
        return (f"its channels {ref.names} lack the colour channels R, G, B"
                + ("" if names is None else f" of the render ({names})"))
    H, W = ref.mean.shape[:2]
    if shape is not None:
        h, w = shape[:2]
        if h <= 0 or w <= 0 or H % h or W % w:
            return (f"its resolution {W}x{H} cannot judge a {w}x{h} render (the reference must be the "
                    "render's resolution times an integer in each axis)")
    return None


def examine(folder, scene_name, fp=None, shape=None, names=None):
    """The candidate in one folder: (Reference or None, problem or None). (None, None): no
    candidate there. A problem names the file; a candidate whose only problem is that it is stale
    comes back with its problem (so that the caller can still show what is stale)."""
    folder = Path(folder)
    exr_path, meta_path = folder / f"{scene_name}.exr", folder / f"{scene_name}.json"
    has_exr, has_meta = exr_path.exists(), meta_path.exists()
    if not has_exr and not has_meta:
        return None, None
    if is_history(folder):
        return None, problem(folder / HISTORY_RECORD, (
            "this folder keeps a replaced reference (history of batch/make_references.py --replace), "
            "never a current one"))
    if not has_meta:
        owner = owner_elsewhere(folder, scene_name)
        return None, problem(exr_path, f"no record {meta_path.name} beside it: not a complete reference"
                             + (f" ({owner})" if owner else ""))
    if not has_exr:
        return None, problem(meta_path, f"no image {exr_path.name} beside it: not a complete reference")
    meta, bad = read_record(meta_path)
    if bad:
        return None, problem(meta_path, bad)
    try:
        if meta.get("exr_sha256") is not None and sha256_of(exr_path) != meta["exr_sha256"]:
            return None, problem(exr_path, (
                f"the image is not the one its record {meta_path.name} describes (sha256 differs): the "
                f"pair was not replaced together (an interrupted save?); {_remake(scene_name, exr_path)}"))
        names_, mean, stderr = exr.read_image_and_stderr(exr_path, expect=meta.get("resolution"))
    except Exception as exc:  # noqa: BLE001 - any unreadable file is a problem of that file
        return None, problem(exr_path, f"unreadable EXR: {exc}")
    if stderr is None:
        return None, problem(exr_path, "no stderr.<channel> noise channels: not a reference")
    if not (np.isfinite(mean).all() and np.isfinite(stderr).all() and (stderr >= 0).all()):
        return None, problem(exr_path, "non-finite values (NaN or Inf) in its mean or noise channels")
    res = meta.get("resolution")
    if res is not None and res != [mean.shape[1], mean.shape[0]]:
        return None, problem(exr_path, (f"its resolution {mean.shape[1]}x{mean.shape[0]} is not the "
                                        f"{res} its record {meta_path.name} gives"))
    ref = Reference(names_, mean, stderr, meta, exr_path)
    why = usable_for(ref, shape, names)
    if why:
        return None, problem(exr_path, why)
    if fp is not None and meta["fingerprint"] != fp:
        return ref, problem(exr_path, _stale(ref, scene_name))
    return ref, None


def _remake(scene_name, path):
    """The command that renders this reference again, into the folder it is in."""
    folder = Path(path).parent
    out = "" if folder.resolve() == REFERENCE_DIR else f" --out {folder}"
    return f"re-render it with batch/make_references.py -s {scene_name}{out} --replace"


def _stale(ref, scene_name):
    return (f"stale: the scene changed since it was rendered ({ref.provenance.get('date')}); "
            f"{_remake(scene_name, ref.path)}")


@dataclass
class Search:
    """The outcome of a search: the first usable reference (or None), the problems of every
    candidate passed over (file and problem, in search order), and the first candidate whose
    only fault is being stale (for callers that want to show it)."""
    ref: Optional[Reference] = None
    problems: list = field(default_factory=list)
    stale: Optional[Reference] = None


def search(scene_name, directory=None, scene=None, shape=None, names=None):
    """Every folder's candidate in order, checked: a readable record, a readable EXR with its
    noise channels (and, where the record gives one, the sha256 it records), channels and a
    resolution usable for a render of ``shape`` with ``names``, and the fingerprint of ``scene``.
    The first sound one wins; a broken, wrong-sized or stale one is passed over and recorded."""
    fp = fingerprint(scene) if scene is not None else None
    out = Search()
    for folder in directories(directory):
        ref, bad = examine(folder, scene_name, fp, shape, names)
        if bad:
            out.problems.append(bad)
            if ref is not None and out.stale is None:
                out.stale = ref
            continue
        if ref is not None:
            out.ref = ref
            break
    return out


def load(scene_name, directory=None, scene=None, shape=None, names=None):
    """Reference or None. With several folders, the first usable candidate wins (see search);
    when none is usable, the first that is only stale (so that check_usable can say it is
    stale), else None. search() also gives the problems of the candidates passed over."""
    found = search(scene_name, directory, scene, shape, names)
    return found.ref or found.stale


def check_usable(ref, scene, shape=None, names=None):
    """None if ``ref`` can judge renders of ``scene`` (of ``shape`` with ``names``, when given),
    else the reason it cannot."""
    if ref is None:
        return "no reference for this scene"
    if ref.provenance.get("fingerprint") != fingerprint(scene):
        return f"reference {ref.path.name} is {_stale(ref, ref.path.stem)}"
    why = usable_for(ref, shape, names)
    return f"reference {ref.path.name}: {why}" if why else None


class Collision(ValueError):
    """A write that would replace a file of another scene (issue 40): refused, naming both."""


def owner_elsewhere(directory, scene_name):
    """None, or what makes ``<directory>/<scene>.exr|.json`` another scene's file: a record there
    whose ``scene`` differs from it in case only (a file system that ignores case; a record of any
    other name is a reference renamed by hand, replaced as it is), or an observer layer of
    scene S kept in the old layout (``S.<observer>.exr``, S's record naming that file) under the
    name of the reference of a scene called ``S.<observer>``."""
    from . import observer_layers
    directory = Path(directory)
    meta_path, exr_path = directory / f"{scene_name}.json", directory / f"{scene_name}.exr"
    if meta_path.is_file():  # a record of a name that differs in case only: the same file where case is ignored
        meta, _bad = read_record(meta_path)
        other = (meta or {}).get("scene")
        if isinstance(other, str) and other != scene_name and other.lower() == scene_name.lower():
            return f"{meta_path} is the record of scene {other!r} (a file system that ignores case)"
    stem, _, obs = scene_name.rpartition(".")
    if stem and exr_path.is_file() and observer_layers.NAME.fullmatch(obs) and (directory / f"{stem}.json").is_file():
        meta, _bad = read_record(directory / f"{stem}.json")
        item = ((meta or {}).get(observer_layers.RECORD_KEY) or {}) if isinstance(meta, dict) else {}
        item = item.get(obs) if isinstance(item, dict) else None
        if isinstance(item, dict) and item.get("file") == exr_path.name:
            return (f"{exr_path} is scene {stem!r}'s observer layer {obs} in the old layout "
                    f"({observer_layers._migrate_hint(directory)})")
    return None


def refuse_collision(directory, scene_name):
    """Raise Collision, naming both scenes, where writing ``scene_name``'s reference into
    ``directory`` would replace another scene's file (owner_elsewhere)."""
    owner = owner_elsewhere(directory, scene_name)
    if owner:
        raise Collision(f"scene {scene_name!r}: refusing to write its reference into {directory}: {owner}; "
                        "nothing written, nothing replaced")


HALF_MAX = 65504.0


def _noise_channel(stderr):
    """The standard error as half floats (the mean stays float32): a third smaller references
    with no verdict changed (benchmarks/reference_storage.py, benchmarks/REFERENCES.md); float32
    where a value would not fit in half."""
    finite = np.isfinite(stderr)
    if finite.all() and float(np.max(np.abs(stderr), initial=0.0)) < HALF_MAX:
        return stderr.astype(np.float16)
    return stderr.astype(np.float32)


def scene_lock(directory, scene_name):
    """The lock every writer of ``scene_name``'s reference in ``directory`` holds (a file in
    ``directory``/.work/.locks/, which git and the extension build leave out: a folder no scene's
    passes, ``.work/<scene>/``, can be, since a scene name never starts with a dot). One lock object per file
    in this process (filelock's singletons), re-entrant and not bound to a thread, so that
    make_references can hold it for a whole scene and save() take it again from an engine's
    callback. (filelock is imported here: only writers need it, not the extension.)"""
    import filelock
    work = Path(directory) / ".work" / ".locks"
    work.mkdir(parents=True, exist_ok=True)
    return filelock.FileLock(str(work / f"{scene_name}.lock"), is_singleton=True, thread_local=False)


def _fsync_dir(directory):
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _umask():
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _temp(directory, scene_name, suffix):
    """A new, uniquely named temporary file in ``directory`` (hidden; never *.exr or *.json), with
    the permissions a new file gets (0666 less the umask: mkstemp's 0600 would make the reference
    private once it is renamed into place)."""
    fd, path = tempfile.mkstemp(dir=directory, prefix=f".{scene_name}.", suffix=suffix)
    try:
        os.fchmod(fd, 0o666 & ~_umask())
    finally:
        os.close(fd)
    return Path(path)


def _write_synced(path, data):
    with open(path, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def _read_back(path, names, shape):
    """The written image read back whole before it is put in place: a write that failed without
    saying so (a full disk under some writers) never becomes the reference. OSError naming it."""
    try:
        got, img, se = exr.read_image_and_stderr(path, expect=(shape[1], shape[0]))
    except (OSError, ValueError) as exc:
        raise OSError(f"{path}: the reference written cannot be read back ({exc})") from exc
    if set(got) != set(names) or img.shape != tuple(shape) or se is None:
        raise OSError(f"{path}: the reference read back is not the one written (channels {got}, shape {img.shape})")


def _replace_pair(meta_tmp, meta_path, exr_tmp, exr_path):
    """Put a written record and image in place: the record first, then the image, the folder
    synced after each. The record carries the image's sha256, so until the second rename the pair
    on disk (new record, old image) does not match and search() passes it over and reports it;
    a crash between the two can never pair an image with a record that was not written for it."""
    os.replace(meta_tmp, meta_path)
    _fsync_dir(meta_path.parent)
    os.replace(exr_tmp, exr_path)
    _fsync_dir(exr_path.parent)


def save(scene, names, mean, stderr, provenance, directory=None):
    """Write ``scene``'s reference into ``directory`` (default references/), replacing what is
    there as one step a reader sees whole or sees as broken: unique temporary files in the same
    folder, each synced to disk, the record carrying the image's sha256 (exr_sha256), renamed
    into place record first (_replace_pair), under the scene's lock (two writers of the same
    scene take turns)."""
    directory = Path(directory or REFERENCE_DIR)
    directory.mkdir(parents=True, exist_ok=True)
    name = scene["name"]
    extra = {f"stderr.{n}": _noise_channel(stderr[..., i]) for i, n in enumerate(names)}
    exr_path, meta_path = directory / f"{name}.exr", directory / f"{name}.json"
    fp = fingerprint(scene)
    with scene_lock(directory, name):
        refuse_collision(directory, name)
        exr_tmp, meta_tmp = _temp(directory, name, ".exr.tmp"), _temp(directory, name, ".json.tmp")
        try:
            exr.write_image(exr_tmp, names, mean, extra)
            with open(exr_tmp, "rb+") as f:
                os.fsync(f.fileno())
            _read_back(exr_tmp, names, mean.shape)
            meta = dict(provenance, scene=name, fingerprint=fp, exr_sha256=sha256_of(exr_tmp))
            _write_synced(meta_tmp, (json.dumps(meta, indent=1, sort_keys=True) + "\n").encode())
            _replace_pair(meta_tmp, meta_path, exr_tmp, exr_path)
        finally:
            for tmp in (exr_tmp, meta_tmp):
                tmp.unlink(missing_ok=True)
    return exr_path


# -- replacing a reference (batch/make_references.py --replace): judged, the old one kept ----------
HISTORY = "history"                # <references>/history/<scene>/<UTC time>-<backend>/
HISTORY_RECORD = "replaced.json"   # in each history folder: who replaced it, why, with what command


def is_history(folder):
    """Whether ``folder`` keeps a replaced reference (it holds a replacement record): never a
    current reference, whoever points a search at it."""
    return (Path(folder) / HISTORY_RECORD).exists()


def judge_replacement(old, new, alpha=None, min_samples=None, block=None, keep=False):
    """The new reference judged against the old on both their noises, by the block test that
    judges a render against a reference (batch/verdict/compare.py ``z_test``, Sidak-corrected):
    the image of finer resolution is the "render" (its own per-pixel standard error from its own
    passes), the other one the reference brought to that resolution (``reference_at``; the
    resolutions must differ by an integer factor, the channels must be the same). ``alpha``,
    ``min_samples`` and ``block`` are the runner's --alpha, --min-samples and --block (default: its
    defaults, so that "the same within noise" means what it means for a render).

    Returns plain data: ``comparable`` (False with ``reason`` when the two cannot be judged),
    ``same`` (within noise), ``test`` (the block test's record: p_min, threshold, ...), ``ratio``
    ({channel: [mean new / mean old over the image, its standard error]} for R, G, B: the standard
    error by first-order propagation of the two image means' independent standard errors, JCGM
    100:2008 (GUM) section 5.1.2, the means' variances being the sums of the per-pixel variances
    over N^2 since pixels are independent) and ``detectable`` (the smallest uniform relative change
    of the whole image the test would have refused: the expected difference alone reaching the
    Sidak threshold in the most sensitive block, found with the test's own ``rejudge`` on a zero
    difference; detected about half the time at that size, more often above it; None beyond
    100 %). ``keep``: also return the in-memory test (``_ztest``), the image brought to the test
    resolution (``_at``) and whether the new image is the test one (``_new_is_test``), for callers
    that write its z-map or compute its power (batch/verdict/baseline.py)."""
    import dataclasses
    from . import compare, stats
    alpha = stats.ALPHA if alpha is None else alpha
    min_samples = compare.MIN_SAMPLES if min_samples is None else min_samples
    if list(old.names) != list(new.names):
        return {"comparable": False, "same": False, "reason": f"their channels differ: old {old.names}, new {new.names}"}
    (H, W), (h, w) = old.mean.shape[:2], new.mean.shape[:2]
    if H >= h and W >= w and not (H % h or W % w) and H // h == W // w:
        test, ref, new_is_test = new, old, True
    elif h >= H and w >= W and not (h % H or w % W) and h // H == w // W:
        test, ref, new_is_test = old, new, False
    else:
        return {"comparable": False, "same": False,
                "reason": f"their resolutions {W}x{H} (old) and {w}x{h} (new) differ by no integer factor"}
    at = compare.reference_at(ref.mean, ref.stderr, ref.spp, test.mean.shape, ref.provenance.get("passes", 8))
    own = test.stderr.astype(np.float64) ** 2
    zt = compare.z_test(test.mean.astype(np.float64), at, test.spp, own_var_of_mean=own,
                        own_passes=test.provenance.get("passes", 8), alpha=alpha, block=block, min_samples=min_samples)
    n = test.mean.shape[0] * test.mean.shape[1]
    means = {"test": test.mean.astype(np.float64).reshape(n, -1).mean(axis=0), "ref": at.mean.reshape(n, -1).mean(axis=0)}
    var = {"test": own.reshape(n, -1).sum(axis=0) / n**2, "ref": at.var_of_mean.reshape(n, -1).sum(axis=0) / n**2}
    num, den = ("test", "ref") if new_is_test else ("ref", "test")
    ratio = {}
    for c in ("R", "G", "B"):
        i = new.names.index(c)
        a, b = means[num][i], means[den][i]
        if not abs(b) > 0 or not abs(a) > 0:
            ratio[c] = None
            continue
        r = a / b
        ratio[c] = [float(r), float(abs(r) * np.sqrt(var[num][i] / a**2 + var[den][i] / b**2))]
    zero = dataclasses.replace(zt, diff=np.zeros_like(zt.diff))
    detectable = None
    if not zero.rejudge(2.0):
        lo, hi = 0.0, 1.0
        for _ in range(40):  # bisection on the test's own re-judgement: the smallest change it refuses
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if zero.rejudge(1.0 + mid) else (lo, mid)
        detectable = hi
    out = {"comparable": True, "same": bool(zt.passed), "test": zt.as_dict(), "ratio": ratio,
           "detectable": detectable, "judged_at": [int(test.mean.shape[1]), int(test.mean.shape[0])]}
    if keep:
        out.update(_ztest=zt, _at=at, _new_is_test=new_is_test)
    return out


def history_folder(directory, scene_name, backend, when):
    """A new folder <directory>/history/<scene>/<when>-<backend>[-k] for a replaced reference;
    ``backend`` comes from the old record (any text): one that is not a plain name becomes
    "unknown"."""
    from ...exporters import names as scene_names
    tag = backend if isinstance(backend, str) and scene_names.problem(backend) is None else "unknown"
    base = Path(directory) / HISTORY / scene_names.file_stem(scene_name)
    base.mkdir(parents=True, exist_ok=True)
    for k in range(1, 1000):
        folder = base / (f"{when}-{tag}" if k == 1 else f"{when}-{tag}-{k}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue
    raise FileExistsError(f"{base}: too many replacements at {when}")


def replace(scene, names, mean, stderr, provenance, directory, record, when):
    """Save a new reference (``save``: the pair replaced as one step) and keep what it replaces:
    under the scene's lock, the old record and image (whatever of the two is there) are linked
    (copied where a link cannot be made) into a new history folder with ``record`` (who, why,
    command: written first, so the folder is marked as history before it holds any reference
    file), synced, and only then is the new pair saved. The old files stay current until that
    save; if it fails the history folder is removed. Returns (new image path, history folder or
    None when there was nothing to keep)."""
    import shutil
    directory = Path(directory)
    name = scene["name"]
    old = [p for p in (directory / f"{name}.json", directory / f"{name}.exr") if p.exists()]
    with scene_lock(directory, name):
        refuse_collision(directory, name)
        if not old:
            return save(scene, names, mean, stderr, provenance, directory), None
        backend = None
        if (directory / f"{name}.json").exists():
            meta, _bad = read_record(directory / f"{name}.json")
            backend = (meta or {}).get("backend")
        folder = history_folder(directory, name, backend, when)
        try:
            _write_synced(folder / HISTORY_RECORD, (json.dumps(record, indent=1, sort_keys=True, default=str) + "\n").encode())
            for path in old:
                try:
                    os.link(path, folder / path.name)
                except OSError:
                    shutil.copy2(path, folder / path.name)
                    with open(folder / path.name, "rb+") as f:
                        os.fsync(f.fileno())
            _fsync_dir(folder)
            path = save(scene, names, mean, stderr, provenance, directory)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
    return path, folder
