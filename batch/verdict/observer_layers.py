"""Observer layers of a reference (issue 33): the reference as other films would have seen it.

A reference's R, G, B are the scene format's colour (docs/scene-format.md: CIE 1931 2 degree at
1 nm, the IEC 61966-2-1 matrix) where its provenance's ``colour`` says so. A renderer whose film
integrates spectra another way (Mitsuba's 5 nm tables, ART's 10 nm bands: the ``observer`` of a
recorded deviation, exporters/colorimetry.py) differs from it by an amount that depends on each
pixel's spectrum: a uniform scale cannot model it (the ColorChecker's saturated patches move by
4-8 standard errors against its greys). So a reference may keep, beside its image, the difference
each such observer makes: one file per observer, ``layers/<scene>/<observer>.exr`` in the
reference's folder (issue 40: not ``<scene>.<observer>.exr`` beside it, the name of another scene's
reference: a scene name may hold dots, and no scene name reaches into ``layers/``), channels R, G, B
(that observer's linear sRGB minus the IR's, per pixel) and stderr.R/G/B (the standard error of
that difference), rendered through one film whose channels are the CMFs of every observer at once
(batch/backends/mitsuba/spectral.py layer_channels), so each difference comes from the same paths
and its noise is a small fraction of the image's (measured per layer and recorded as
``noise_ratio``: the median over pixels of the layer's standard error over the reference's). One
file per observer, so that a copy of the references (the Blender extension's) can carry only the
observers its renderers need.

The record (``<scene>.json``) describes each file under ``observer_layers.<observer>``: file
(``layers/<scene>/<observer>.exr``, relative to the folder), sha256, spp, passes, seed, film,
noise_ratio, date, versions, command. A layer that is missing, whose hash differs from its record,
that cannot be read or is not the reference's size, or whose record entry is not one, is not used:
the reference stays usable, the layer's problem is one of the verdict's ``reference_problems``
(``check``), and a deviation naming that observer cannot re-judge the noise test and says so by
not applying. A layer stored in the old layout (``<scene>.<observer>.exr`` beside the reference,
the hash of its record) is named as such, with the command that moves it (``migrate``,
``batch/make_references.py --migrate-layers``); it is not read where it is, since that name is
another scene's reference.

``offsets(ref)``: {observer: (difference, variance of the difference)} for the reference's own
observer (zero) and every layer; batch/verdict/compare.py carries them to the test resolution and
the noise test re-judges a render under a deviation's observer against reference + difference.
"""
import re
from pathlib import Path

import numpy as np

from .. import exr

RECORD_KEY = "observer_layers"
CHANNELS = ("R", "G", "B")
NAME = re.compile(r"[a-z][a-z0-9]{0,31}")  # an observer's name (exporters/colorimetry.py OBSERVERS)
FOLDER = "layers"  # <references>/layers/<scene>/<observer>.exr: a folder, where no scene's file is


def _scene_of(ref_path):
    """The scene of a reference's image or record ``<folder>/<scene>.exr|.json`` (a scene name
    may hold dots: only the suffix goes), checked as a name before it names a folder."""
    from ...exporters import names
    return names.file_stem(Path(ref_path).stem)


def relative(scene_name, observer):
    """``observer``'s layer of ``scene_name`` relative to the references folder, as the record's
    ``file`` gives it (POSIX separators)."""
    from ...exporters import names
    if not NAME.fullmatch(str(observer)):
        raise ValueError(f"observer {observer!r}: not an observer's name")
    return f"{FOLDER}/{names.file_stem(scene_name)}/{observer}.exr"


def path_for(ref_path, observer):
    """The file of ``observer``'s layer of the reference ``<folder>/<scene>.exr`` (or its record):
    ``<folder>/layers/<scene>/<observer>.exr``."""
    return Path(ref_path).parent.joinpath(*relative(_scene_of(ref_path), observer).split("/"))


def old_path_for(ref_path, observer):
    """Where the layer was kept before issue 40: ``<folder>/<scene>.<observer>.exr``, beside the
    reference, which is also the reference image of a scene named ``<scene>.<observer>``."""
    p = Path(ref_path)
    return p.with_name(f"{_scene_of(p)}.{observer}.exr")


def own_observer(provenance):
    """The observer a reference's R, G, B were made with (its provenance's ``colour.observer``,
    first word), or None where the record does not say."""
    colour = provenance.get("colour") if isinstance(provenance, dict) else None
    text = colour.get("observer") if isinstance(colour, dict) else None
    m = re.match(r"[A-Za-z0-9]+", text) if isinstance(text, str) else None
    return m.group(0) if m else None


def _key(obs):
    """A record key as problems() names it: itself when it is a name, else its first 40 characters
    (any text: shown, never used as a name)."""
    return obs if isinstance(obs, str) and NAME.fullmatch(obs) else str(obs)[:40]


def _migrate_hint(folder):
    from . import references
    out = "" if Path(folder).resolve() == references.REFERENCE_DIR else f" --out {folder}"
    return f"move it with batch/make_references.py --migrate-layers{out}"


def check(ref):
    """({observer: (difference H x W x 3, its standard error H x W x 3)} of the reference's usable
    layers, {record key: (file, why its layer cannot be used)} of the others). Never raises for
    what a layer file or record holds: an unusable layer leaves the reference usable. A key that
    is not an observer's name never names a file."""
    rec = ref.provenance.get(RECORD_KEY)
    if rec is None or ref.path is None:  # no layers, or a reference not in a folder (being made)
        return {}, {}
    meta_path = Path(ref.path).with_suffix(".json")
    if not isinstance(rec, dict):
        return {}, {"*": (meta_path, f"record field {RECORD_KEY} is not an object")}
    from .references import sha256_of  # references imports this module lazily; no cycle at import time
    h, w = ref.mean.shape[:2]
    layers, bad = {}, {}
    for obs, item in rec.items():
        if not (isinstance(obs, str) and NAME.fullmatch(obs)) or not isinstance(item, dict) \
                or not isinstance(item.get("sha256"), str):
            bad[_key(obs)] = (meta_path, f"record field {RECORD_KEY} names no layer file with its sha256 here")
            continue
        try:
            path, old = path_for(ref.path, obs), old_path_for(ref.path, obs)
            shown = relative(_scene_of(ref.path), obs)
        except (TypeError, ValueError) as exc:  # a reference whose file is not named by a scene name
            bad[obs] = (meta_path, f"no layer file can be named for this reference: {exc}")
            continue
        try:
            if not path.is_file():
                if old.is_file() and sha256_of(old) == item["sha256"]:
                    bad[obs] = (old, f"{old.name} is the layer in the old layout, beside the reference (where a "
                                     f"scene named {old.stem} would keep its reference): not read there; "
                                     f"{_migrate_hint(old.parent)}")
                else:
                    bad[obs] = (path, f"{shown} is missing")
                continue
            if sha256_of(path) != item["sha256"]:
                bad[obs] = (path, f"{shown} is not the file its record describes (sha256 differs)")
                continue
            names, mean, stderr = exr.read_image_and_stderr(path, expect=[w, h])
        except Exception as exc:  # noqa: BLE001 - any unreadable or wrong-sized layer is a problem of that layer
            bad[obs] = (path, f"{shown} cannot be used: {type(exc).__name__}: {exc}")
            continue
        if stderr is None or names[:3] != list(CHANNELS):
            bad[obs] = (path, f"{shown} is not a layer (channels {names[:6]}, no stderr.R/G/B)"
                        if stderr is None else f"{shown} is not a layer (channels {names[:6]}, not R, G, B first)")
            continue
        mean, stderr = mean[..., :3].astype(np.float64), stderr[..., :3].astype(np.float64)
        if mean.shape[:2] != (h, w) or not (np.isfinite(mean).all() and np.isfinite(stderr).all() and (stderr >= 0).all()):
            bad[obs] = (path, f"{shown} is not usable: {mean.shape[1]}x{mean.shape[0]} for a {w}x{h} reference"
                        if mean.shape[:2] != (h, w) else f"{shown} holds non-finite or negative values")
            continue
        layers[obs] = (mean, stderr)
    return layers, bad


def problems(ref):
    """{observer: why its layer cannot be used} for the layers the reference's record lists."""
    return {k: why for k, (_f, why) in check(ref)[1].items()}


def problem_of(ref):
    """None, or why some of the observer layers the reference's record lists cannot be used."""
    bad = problems(ref)
    return "; ".join(bad.values()) if bad else None


def reference_problems(ref, bad=None):
    """The unusable layers as reference problems (batch/verdict/references.py ``problem``: file and
    problem, as every report shows them): the reference itself is used. ``bad``: check(ref)[1]."""
    from . import references
    bad = check(ref)[1] if bad is None else bad
    return [references.problem(f, f"observer layer {k} of this reference not used: {why} (the reference itself is used)")
            for k, (f, why) in bad.items()]


def load(ref):
    """{observer: (difference H x W x 3, its standard error H x W x 3)} of the reference's usable
    layers ({} where it has none; check() says why a listed one is not usable)."""
    return check(ref)[0]


def offsets(ref, channels=3, layers=None):
    """{observer: (difference, variance)} as ``channels``-channel images (the layers cover R, G, B;
    further channels, Stokes ones, get none): the reference's own observer at zero, then its
    layers (``layers``: what load(ref) gave, if the caller has it)."""
    out = {}
    own = own_observer(ref.provenance)
    if own:
        out[own] = (0.0, 0.0)
    for obs, (delta, se) in (load(ref) if layers is None else layers).items():
        if obs == own:
            continue
        pad = [(0, 0), (0, 0), (0, max(channels - 3, 0))]
        out[obs] = (np.pad(delta, pad)[..., :channels], np.pad(se ** 2, pad)[..., :channels])
    return out


def split(names, mean, stderr):
    """A render of the CMF film with layers (channels R, G, B, ..., then "<observer>.R/G/B", as
    batch/backends/mitsuba/backend.py film_to_ir gives them) as (names, mean, stderr) of the image
    and {observer: (difference, standard error)} of the layers."""
    is_layer = [n.rpartition(".")[0] not in ("", "stderr", "S0", "S1", "S2", "S3") and n.rpartition(".")[2] in CHANNELS
                for n in names]
    keep = [i for i, x in enumerate(is_layer) if not x]
    layers = {}
    for i, n in enumerate(names):
        obs, _, c = n.rpartition(".")
        if is_layer[i] and c == "R":
            idx = [names.index(f"{obs}.{k}") for k in CHANNELS]
            layers[obs] = (mean[..., idx], stderr[..., idx])
    return [names[i] for i in keep], mean[..., keep], stderr[..., keep], layers


def noise_ratio(layer_stderr, ref_stderr):
    """Median over pixels (where the reference has noise) of a layer's standard error over the
    reference's, per channel: how much the layer adds to the noise a render is judged on."""
    rs = np.asarray(ref_stderr, dtype=np.float64)[..., :3]
    ok = rs > 0
    return [float(np.median(np.asarray(layer_stderr)[..., c][ok[..., c]] / rs[..., c][ok[..., c]])) if ok[..., c].any()
            else None for c in range(3)]


def _write_record(directory, scene_name, meta_path, meta):
    """The record written whole (a unique temporary file, synced, renamed over it)."""
    import json
    import os

    from . import references
    tmp = references._temp(directory, scene_name, ".json.tmp")
    try:
        references._write_synced(tmp, (json.dumps(meta, indent=1, sort_keys=True) + "\n").encode())
        os.replace(tmp, meta_path)
    finally:
        tmp.unlink(missing_ok=True)


def _own_old_file(directory, scene_name, obs, item):
    """The old-layout file ``<scene>.<obs>.exr`` if it is this scene's layer (its record's file
    and sha256), else None: a file of that name that is not is another scene's reference."""
    old = Path(directory) / f"{scene_name}.{obs}.exr"
    if isinstance(item, dict) and item.get("file") == old.name and old.is_file() \
            and sha256_of_or_none(old) == item.get("sha256"):
        return old
    return None


def sha256_of_or_none(path):
    from . import references
    try:
        return references.sha256_of(path)
    except OSError:
        return None


def save(directory, scene_name, layers, info, ref_stderr=None, stored=False):
    """Write ``layers`` ({observer: (difference, standard error)}) as ``layers/<scene>/<observer>.exr``
    in ``directory`` and describe each in the scene's record under ``observer_layers.<observer>``
    (``info`` plus its file, sha256 and its noise_ratio as stored):
    the files first (temporary files renamed into place), then the record the same way, all under
    the scene's lock. The reference's image is not touched; this scene's own layer of the same
    observer in the old layout (``<scene>.<observer>.exr``, its record's hash) is removed once the
    new one is in place. Each layer is stored as a render is
    (batch/exr.py stored_render: half floats, rounded stochastically, the rounding variance in its
    standard error) with a step below ``ref_stderr``, the reference's standard error (its own is
    far smaller and its bits below the reference's noise would only take room); ``stored``: write
    the layers as they are. A layer of another size than ``ref_stderr`` is refused (ValueError
    naming the scene and both sizes) before anything is written."""
    import os

    from . import references
    directory = Path(directory)
    meta_path = directory / f"{scene_name}.json"
    if ref_stderr is not None:
        H, W = np.asarray(ref_stderr).shape[:2]
        for obs, (mean, _se) in layers.items():
            if tuple(np.asarray(mean).shape[:2]) != (H, W):
                h, w = np.asarray(mean).shape[:2]
                raise ValueError(f"scene {scene_name}: observer layer {obs} is {w}x{h}, its reference {W}x{H}: "
                                 "a layer is the reference's size (render it at the reference's --scale)")
    with references.scene_lock(directory, scene_name):
        meta, bad = references.read_record(meta_path)
        if bad:
            raise ValueError(f"{meta_path}: {bad}")
        record = dict(meta.get(RECORD_KEY) or {}) if isinstance(meta.get(RECORD_KEY), dict) else {}
        old = {obs: _own_old_file(directory, scene_name, obs, record.get(obs)) for obs in layers}
        temps = []
        try:
            for obs, (mean, stderr) in layers.items():
                if not NAME.fullmatch(obs):
                    raise ValueError(f"observer {obs!r}: not an observer's name")
                if not stored:
                    mean, stderr = exr.stored_render(mean, stderr, int(info.get("seed") or 0),
                                                     None if ref_stderr is None else np.asarray(ref_stderr)[..., :3])
                channels = {c: mean[..., i] for i, c in enumerate(CHANNELS)}
                channels.update({f"stderr.{c}": stderr[..., i] for i, c in enumerate(CHANNELS)})
                tmp = references._temp(directory, scene_name, ".layer.tmp")
                temps.append(tmp)
                exr.write_channels(tmp, channels)
                references._read_back(tmp, list(CHANNELS), mean.shape)
                item = {k: v for k, v in info.items() if k != "noise_ratio"}
                if ref_stderr is not None:  # as stored: what a re-judged noise test adds
                    item["noise_ratio"] = noise_ratio(np.asarray(stderr, dtype=np.float64), ref_stderr)
                record[obs] = dict(item, file=relative(scene_name, obs), sha256=references.sha256_of(tmp))
            meta[RECORD_KEY] = record
            for tmp, obs in zip(temps, layers):
                path_for(meta_path, obs).parent.mkdir(parents=True, exist_ok=True)
                os.replace(tmp, path_for(meta_path, obs))
            _write_record(directory, scene_name, meta_path, meta)
            for path in old.values():
                if path is not None:
                    path.unlink(missing_ok=True)
        finally:
            for t in temps:
                t.unlink(missing_ok=True)
    return [path_for(meta_path, obs) for obs in layers]


def migrate(directory, scene_name):
    """Move ``scene_name``'s observer layers in ``directory`` from the old layout
    (``<scene>.<observer>.exr`` beside the reference) to ``layers/<scene>/<observer>.exr``, the
    bytes unchanged (a rename), and point their records' ``file`` there, under the scene's lock.
    Only a file whose sha256 is its record's moves (any other file of that name is another
    scene's reference, or not this layer, and stays). Returns (moved: [(old, new)], left:
    [(file, why)])."""
    import os

    from . import references
    directory = Path(directory)
    meta_path = directory / f"{scene_name}.json"
    moved, left = [], []
    with references.scene_lock(directory, scene_name):
        meta, bad = references.read_record(meta_path)
        if bad:
            return moved, [(meta_path, bad)]
        rec = meta.get(RECORD_KEY)
        if not isinstance(rec, dict):
            return moved, ([] if rec is None else [(meta_path, f"record field {RECORD_KEY} is not an object")])
        changed = False
        for obs, item in rec.items():
            if not (isinstance(obs, str) and NAME.fullmatch(obs)) or not isinstance(item, dict):
                left.append((meta_path, f"record entry {_key(obs)!r} of {RECORD_KEY} is not a layer's: left as it is"))
                continue
            new, old = path_for(meta_path, obs), old_path_for(meta_path, obs)
            if not new.is_file() and old.is_file():
                if sha256_of_or_none(old) != item.get("sha256"):
                    left.append((old, f"not observer layer {obs} of {scene_name} (its sha256 is not the record's): "
                                      "not moved"))
                    continue
                new.parent.mkdir(parents=True, exist_ok=True)
                os.replace(old, new)
                moved.append((old, new))
            if new.is_file() and item.get("file") != relative(scene_name, obs):
                rec[obs] = dict(item, file=relative(scene_name, obs))
                changed = True
        if changed:
            _write_record(directory, scene_name, meta_path, meta)
    return moved, left
