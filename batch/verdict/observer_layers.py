"""Observer layers of a reference (issue 33): the reference as other films would have seen it.

A reference's R, G, B are the scene format's colour (docs/scene-format.md: CIE 1931 2 degree at
1 nm, the IEC 61966-2-1 matrix) where its provenance's ``colour`` says so. A renderer whose film
integrates spectra another way (Mitsuba's 5 nm tables, ART's 10 nm bands: the ``observer`` of a
recorded deviation, exporters/colorimetry.py) differs from it by an amount that depends on each
pixel's spectrum: a uniform scale cannot model it (the ColorChecker's saturated patches move by
4-8 standard errors against its greys). So a reference may keep, beside its image, the difference
each such observer makes: one file per observer, ``<scene>.<observer>.exr``, channels R, G, B
(that observer's linear sRGB minus the IR's, per pixel) and stderr.R/G/B (the standard error of
that difference), rendered through one film whose channels are the CMFs of every observer at once
(batch/backends/mitsuba/spectral.py layer_channels), so each difference comes from the same paths
and its noise is a small fraction of the image's (measured per layer and recorded as
``noise_ratio``: the median over pixels of the layer's standard error over the reference's). One
file per observer, so that a copy of the references (the Blender extension's) can carry only the
observers its renderers need.

The record (``<scene>.json``) describes each file under ``observer_layers.<observer>``: file,
sha256, spp, passes, seed, film, noise_ratio, date, versions, command. A file that is missing or
whose hash differs from its record is not used (the reference stays usable; a deviation naming
that observer then cannot re-judge the noise test and says so by not applying).

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


def path_for(ref_path, observer):
    """The file of ``observer``'s layer beside a reference image ``<scene>.exr``."""
    p = Path(ref_path)
    return p.with_name(f"{p.stem}.{observer}.exr")


def own_observer(provenance):
    """The observer a reference's R, G, B were made with (its provenance's ``colour.observer``,
    first word), or None where the record does not say."""
    colour = provenance.get("colour") if isinstance(provenance, dict) else None
    text = colour.get("observer") if isinstance(colour, dict) else None
    m = re.match(r"[A-Za-z0-9]+", text) if isinstance(text, str) else None
    return m.group(0) if m else None


def problems(ref):
    """{observer: why its layer cannot be used} for the layers the reference's record lists."""
    rec = ref.provenance.get(RECORD_KEY)
    if rec is None:
        return {}
    if not isinstance(rec, dict):
        return {"*": f"record field {RECORD_KEY} is not an object"}
    from .references import sha256_of  # references imports this module lazily; no cycle at import time
    out = {}
    for obs, item in rec.items():
        if not (isinstance(obs, str) and NAME.fullmatch(obs)) or not isinstance(item, dict) \
                or not isinstance(item.get("sha256"), str):
            out[str(obs)[:40]] = f"record field {RECORD_KEY} names no layer file with its sha256 here"
            continue
        path = path_for(ref.path, obs)
        if not path.is_file():
            out[obs] = f"{path.name} is missing"
        elif sha256_of(path) != item["sha256"]:
            out[obs] = f"{path.name} is not the file its record describes (sha256 differs)"
    return out


def problem_of(ref):
    """None, or why some of the observer layers the reference's record lists cannot be used."""
    bad = problems(ref)
    return "; ".join(bad.values()) if bad else None


def load(ref):
    """{observer: (difference H x W x 3, its standard error H x W x 3)} of the reference's usable
    layers ({} where it has none; problems() says why a listed one is not usable)."""
    rec = ref.provenance.get(RECORD_KEY)
    if not isinstance(rec, dict):
        return {}
    bad = problems(ref)
    h, w = ref.mean.shape[:2]
    out = {}
    for obs in rec:
        if obs in bad or "*" in bad:
            continue
        names, mean, stderr = exr.read_image_and_stderr(path_for(ref.path, obs), expect=[w, h])
        if stderr is not None and names[:3] == list(CHANNELS):
            out[obs] = (mean[..., :3].astype(np.float64), stderr[..., :3].astype(np.float64))
    return out


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


def save(directory, scene_name, layers, info, ref_stderr=None, stored=False):
    """Write ``layers`` ({observer: (difference, standard error)}) as ``<scene>.<observer>.exr`` in
    ``directory`` and describe each in the scene's record under ``observer_layers.<observer>``
    (``info`` plus its file, sha256 and its noise_ratio as stored):
    the files first (temporary files renamed into place), then the record the same way, all under
    the scene's lock. The reference's image is not touched. Each layer is stored as a render is
    (batch/exr.py stored_render: half floats, rounded stochastically, the rounding variance in its
    standard error) with a step below ``ref_stderr``, the reference's standard error (its own is
    far smaller and its bits below the reference's noise would only take room); ``stored``: write
    the layers as they are."""
    import json
    import os

    from . import references
    directory = Path(directory)
    meta_path = directory / f"{scene_name}.json"
    with references.scene_lock(directory, scene_name):
        meta, bad = references.read_record(meta_path)
        if bad:
            raise ValueError(f"{meta_path}: {bad}")
        record = dict(meta.get(RECORD_KEY) or {}) if isinstance(meta.get(RECORD_KEY), dict) else {}
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
                record[obs] = dict(item, file=path_for(meta_path, obs).name, sha256=references.sha256_of(tmp))
            meta[RECORD_KEY] = record
            meta_tmp = references._temp(directory, scene_name, ".json.tmp")
            temps.append(meta_tmp)
            references._write_synced(meta_tmp, (json.dumps(meta, indent=1, sort_keys=True) + "\n").encode())
            for tmp, obs in zip(temps, layers):
                os.replace(tmp, path_for(meta_path, obs))
            os.replace(meta_tmp, meta_path)
        finally:
            for t in temps:
                t.unlink(missing_ok=True)
    return [path_for(meta_path, obs) for obs in layers]
