"""metrics.json as a contract: one builder of a run record, one writer, one reader.

Layout: ``schemas/metrics.schema.json`` (JSON Schema, draft 2020-12) describes every field; the
file carries ``schema_version`` (SCHEMA_VERSION; files written before it existed are version 1)
and ``tool`` (this checkout's version from blender_manifest.toml and its git commit, or null).

- ``run_record``: the metrics.json entry of one render job or one job decided without rendering
  (batch/jobs/job.py ``new_entry`` and batch/jobs/plan.py ``entry`` call it).
- ``write``: the file, atomically; every path field (PATHS) relative to the run folder.
- ``read``: a metrics.json (or its run folder) as a Run (a plain dict, upgraded to SCHEMA_VERSION,
  that knows its file and folder); errors name the file. ``Run.path`` resolves a path field
  against the run folder; ``Run.resolved`` is a copy with every path field absolute.
- ``validate``: the schema's complaints about a dict, each naming the field.
- ``noise_test_text``: the noise test of a run entry as one line (summary, report, panel).

Per-block arrays: a probe's test numbers (``stat`` and each of its ``alternatives``) hold arrays
of one value per block (thousands for a GGX plate). Any such array longer than ARRAY_INLINE_MAX is
stored beside the run's image in ``probe_arrays-<sha256 of its content>.npz`` (numpy, no pickle)
and metrics.json holds ``{"array_file": <path relative to the run folder>, "key": <name>}`` in
its place; ``read`` puts the arrays back, so every reader sees the lists the verdict made. The
file is named by its content: written once, never overwritten with other numbers.

Paths: a path the runner writes is stored relative to the run folder (``os.path.relpath``, with
``/``; a reference outside the folder gets ``..`` parts), so a run folder can be moved together
with what it points to. Only where no relative path exists (another drive on Windows) is a path
stored absolute. Options (``options``) and ``baseline.run`` are the user's and stay as given.
"""
import copy
import functools
import json
import math
import os
import pickle
import subprocess
import tomllib
from pathlib import Path, PurePosixPath, PureWindowsPath

from .stat_text import format_z

ROOT = Path(__file__).resolve().parents[1]
SCHEMA_FILE = ROOT / "schemas" / "metrics.schema.json"
FILE_NAME = "metrics.json"
SCHEMA_VERSION = 2

# Where paths live, per top-level list: dotted fields, "[]" steps into a list's items. A reader
# resolves them against the run folder; the writer makes them relative to it.
PATHS = {
    "runs": ("image", "export", "reference.path", "reference.image", "reference_problems[].file", "baseline.zmap",
             "diagnosis.image"),  # baseline.image: relative to the baseline run
    "jobs": ("image", "image_path", "row.image", "point.reference_problems[].file"),
    "sweeps": ("chart", "points[].reference_problems[].file"),
    "studies": ("images.spectral", "images.rgb", "images.de00"),
}


class RecordError(ValueError):
    """A metrics.json that cannot be read (named by its file)."""


# -- the tool's identity ---------------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def tool_info():
    """{"version": blender_manifest.toml's version, "commit": the checkout's git commit or None
    (not a git checkout, or no git)}. Read once per process."""
    try:
        version = tomllib.loads((ROOT / "blender_manifest.toml").read_text(encoding="utf-8")).get("version")
    except (OSError, ValueError):
        version = None
    return {"version": version if isinstance(version, str) else None, "commit": _git_commit()}


def _git_commit():
    """HEAD of the git repository whose top level is this checkout (not of a repository that
    merely contains it, e.g. an extension folder inside someone's dotfiles)."""
    try:
        proc = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--show-toplevel", "HEAD"],
                              capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    lines = proc.stdout.split()
    if proc.returncode != 0 or len(lines) != 2:
        return None
    try:
        same = Path(lines[0]).resolve() == ROOT
    except OSError:
        return None
    return lines[1] if same and len(lines[1]) in (40, 64) else None


# -- building a record ---------------------------------------------------------------------------
def run_record(scene_name, scene, backend, *, mode=None, spp=None, resolution=None, job=None, **fields):
    """A metrics.json run entry (runs[]) with every field a reader may rely on: the job's identity
    (scene, case, backend, mode, job id), its settings (spp, resolution), the status (``ok`` until
    a verdict or a decision sets it), the reason, time, image, metrics and probes; ``fields``
    override or add (their names and meaning: schemas/metrics.schema.json)."""
    e = {"scene": scene_name, "case": scene.get("case") if isinstance(scene, dict) else None, "backend": backend,
         "mode": mode, "status": "ok", "reason": "", "spp": spp,
         "resolution": list(resolution) if resolution is not None else None, "time_s": None, "image": None,
         "metrics": {"rmse": None, "relmse": None, "mape": None, "flip": None}, "probes": []}
    if job is not None:
        e["job"] = job
    if isinstance(scene, dict) and scene.get("warnings"):  # what the export converted or lost (the IR's warnings)
        e["scene_warnings"] = [dict(w) for w in scene["warnings"]]
    e.update(fields)
    return e


# -- paths -----------------------------------------------------------------------------------------
def relative(value, folder):
    """``value`` (a path) relative to ``folder`` with ``/`` separators; a relative path is taken
    as relative to the folder already and kept; not a path: unchanged."""
    if not isinstance(value, (str, os.PathLike)) or not str(value):
        return value
    path = Path(value)
    if not path.is_absolute():
        return value if isinstance(value, str) else path.as_posix()
    try:
        return Path(os.path.relpath(path, Path(folder).absolute())).as_posix()
    except ValueError:  # another drive (Windows): no relative path exists
        return str(path)


def absolute(value, folder):
    """A path field's value as an absolute path string (resolved lexically against ``folder``);
    not a non-empty string: unchanged."""
    if not isinstance(value, str) or not value or "\0" in value:
        return value
    return os.path.normpath(os.path.join(Path(folder).absolute(), value))


def _map_paths(data, fn):
    """Apply fn to every path field (PATHS) of data, in place; anything not shaped as expected
    (a hand-edited or foreign file) is left alone."""
    for section, fields in PATHS.items():
        items = data.get(section)
        if not isinstance(items, list):
            continue
        for item in items:
            for field in fields:
                _map_field(item, field.split("."), fn)
    return data


def _map_field(holder, steps, fn):
    if not isinstance(holder, dict) or not steps:
        return
    step, rest = steps[0], steps[1:]
    many = step.endswith("[]")
    key = step[:-2] if many else step
    if key not in holder:
        return
    if many:
        for item in holder[key] if isinstance(holder[key], list) else ():
            _map_field(item, rest, fn)
    elif rest:
        _map_field(holder[key], rest, fn)
    else:
        holder[key] = fn(holder[key])


# -- writing ---------------------------------------------------------------------------------------
def document(folder, started, options, runs, jobs=None, sweeps=None, stability=None, studies=None):
    """The metrics.json content of a run in ``folder``: versioned, paths relative to the folder."""
    data = {"schema_version": SCHEMA_VERSION, "tool": dict(tool_info()), "started": started,
            "options": dict(options), "runs": list(runs)}
    for key, value in (("jobs", jobs), ("sweeps", sweeps), ("stability", stability), ("studies", studies)):
        if value:
            data[key] = list(value)
    data = json.loads(json.dumps(data, default=str))  # a copy of plain JSON data: the caller's records stay as they are
    return _map_paths(data, lambda v: relative(v, folder))


ARRAY_INLINE_MAX = 64  # longer per-block arrays of a probe's test go beside the image (module doc)
ARRAY_REF = ("array_file", "key")


def _stat_holders(run):
    """Every dict of a run record's probe tests that may hold per-block arrays: each probe's
    ``stat`` and each of its ``alternatives``."""
    probes = run.get("probes") if isinstance(run, dict) else None
    for p in probes if isinstance(probes, list) else ():
        if not isinstance(p, dict):
            continue
        if isinstance(p.get("stat"), dict):
            yield p["stat"]
        alts = p.get("alternatives")
        for a in alts.values() if isinstance(alts, dict) else ():
            if isinstance(a, dict):
                yield a


def _long_numbers(value):
    """The numpy dtype that holds ``value`` exactly if it is a list of more than ARRAY_INLINE_MAX
    floats (or of as many ints); else None."""
    if not isinstance(value, list) or len(value) <= ARRAY_INLINE_MAX:
        return None
    if all(type(x) is float for x in value):
        return "float64"
    if all(type(x) is int and -2**63 <= x < 2**63 for x in value):
        return "int64"
    return None


def _store_arrays(data, folder):
    """Move each run's long per-block arrays into a .npz beside its image (module doc), in place."""
    for run in data.get("runs") or ():
        _store_run_arrays(run, folder)


def _store_run_arrays(run, folder):
    """``_store_arrays`` for one run record (in place): what the result depended on, as
    [(path, is a directory or file, whether it was)] (``_run_text`` checks them again)."""
    import hashlib
    import io
    import numpy as np
    image = run.get("image") if isinstance(run, dict) else None
    if not isinstance(image, str) or PurePosixPath(image).is_absolute() or ".." in PurePosixPath(image).parts:
        return []
    where = PurePosixPath(image).parent
    if not (folder / where).is_dir():
        return [(folder / where, "dir", False)]
    facts = [(folder / where, "dir", True)]
    arrays, places = {}, []
    for holder in _stat_holders(run):
        for k, v in holder.items():
            dtype = _long_numbers(v)
            if dtype:
                key = f"a{len(arrays)}"
                arrays[key] = np.asarray(v, dtype=dtype)
                places.append((holder, k, key))
    if not arrays:
        return facts
    digest = hashlib.sha256()
    for key, a in arrays.items():
        digest.update(f"{key}:{a.dtype.str}:{a.size};".encode() + a.tobytes())
    rel = (where / f"probe_arrays-{digest.hexdigest()[:20]}.npz").as_posix()
    path = folder / rel
    if not path.is_file():
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_bytes(buf.getvalue())
        tmp.replace(path)
    for holder, k, key in places:
        holder[k] = {"array_file": rel, "key": key}
    return facts + [(path, "file", True)]


def _load_arrays(data, folder, strict, problems):
    """Put back the arrays ``_store_arrays`` moved out (in place). A file that is missing, not
    inside the run folder or unreadable, or a key it lacks: RecordError naming both files when
    ``strict``; else the array reads as None and the problem is recorded."""
    import zipfile
    import numpy as np
    opened, seen = {}, set()

    def load(ref):
        rel = ref["array_file"]
        if rel not in opened:
            parts = inside_parts(folder, rel) if isinstance(rel, str) else None
            try:
                if parts is None:
                    raise OSError("missing, or not a file inside the run folder")
                with np.load(Path(folder, *parts), allow_pickle=False) as npz:
                    opened[rel] = {k: npz[k] for k in npz.files}
            except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
                opened[rel] = f"{type(exc).__name__}: {exc}"
        got = opened[rel]
        if isinstance(got, str):
            return None, f"{rel!r}: {got}"
        a = got.get(ref["key"]) if isinstance(ref["key"], str) else None
        if a is None or a.ndim != 1 or a.dtype.kind not in "fi":
            return None, f"{rel!r} holds no array {ref['key']!r}"
        return a.tolist(), None

    for run in data.get("runs") if isinstance(data.get("runs"), list) else ():
        for holder in _stat_holders(run):
            for k, v in list(holder.items()):
                if isinstance(v, dict) and sorted(v) == sorted(ARRAY_REF):
                    holder[k], problem = load(v)
                    if problem and problem not in seen:  # once per file (or missing key)
                        seen.add(problem)
                        problem = f"{folder / FILE_NAME}: the per-block array {k!r} of {run.get('scene')!r}: {problem}"
                        if strict:
                            raise RecordError(problem)
                        problems.append(problem)


# The text of each run record as metrics.json holds it, kept between writes (issue 45 item 1): the
# runner writes the whole file after every job, and made again each time, every record's paths,
# arrays and indented JSON cost O(jobs^2) (1.4 s of CPU over the default suite's 27 jobs).
# {folder: {the record's pickle: (its text, the files it depended on)}}, for the last folder written:
# a record is made again when it changed (its pickle), or a file it depended on did (_store_run_arrays).
_RUN_TEXTS = {}
_RUN_TEXTS_LOCK = __import__("threading").Lock()


def _run_text(run, folder, kept, now):
    """One run record as it stands in metrics.json's "runs" (indented at its depth), from
    ``kept`` when nothing it depended on changed; the entry goes into ``now``."""
    try:  # the record's content, types included: equal bytes, equal JSON (floats pickle far faster than JSON writes them)
        key = pickle.dumps(run, protocol=5)
    except Exception:  # noqa: BLE001 - an object pickle cannot take: its JSON (as document() writes it) is the key
        key = json.dumps(run, default=str)
    hit = kept.get(key)
    if hit is not None and all((p.is_dir() if kind == "dir" else p.is_file()) == was for p, kind, was in hit[1]):
        now[key] = hit
        return hit[0]
    data = _map_paths({"runs": [json.loads(json.dumps(run, default=str))]}, lambda v: relative(v, folder))
    facts = _store_run_arrays(data["runs"][0], folder)
    text = "  " + json.dumps(data["runs"][0], indent=1).replace("\n", "\n  ")  # strings hold no raw newline
    now[key] = (text, facts)
    return text


def write(folder, started, options, runs, jobs=None, sweeps=None, stability=None, studies=None):
    """Write ``folder``/metrics.json atomically (a reader never sees half a file); returns its path.
    Long per-block arrays go beside each run's image first (module doc). The same text as
    ``json.dumps(document(...), indent=1)`` with the arrays stored, each run record's part kept
    from the previous write while it is the same (``_run_text``)."""
    folder = Path(folder)
    runs = list(runs)
    data = document(folder, started, options, [], jobs, sweeps, stability, studies)
    _store_arrays(data, folder)
    where = str(folder.absolute())
    with _RUN_TEXTS_LOCK:
        kept, now = _RUN_TEXTS.get(where, {}), {}
        parts = [_run_text(r, folder, kept, now) for r in runs]
        _RUN_TEXTS.clear()
        _RUN_TEXTS[where] = now
    text = json.dumps(data, indent=1)
    if parts:
        empty = '\n "runs": [],\n' if list(data).index("runs") < len(data) - 1 else '\n "runs": []\n'
        assert text.count(empty) == 1, "the runs' place in metrics.json"
        text = text.replace(empty, empty.replace("[]", "[\n" + ",\n".join(parts) + "\n ]"), 1)
    tmp = folder / (FILE_NAME + ".tmp")
    tmp.write_text(text + "\n", encoding="utf-8")
    tmp.replace(folder / FILE_NAME)
    return folder / FILE_NAME


# -- reading ---------------------------------------------------------------------------------------
class Run(dict):
    """A metrics.json read and upgraded to SCHEMA_VERSION: the plain dict of the file, plus
    ``file`` (the metrics.json), ``folder`` (its run folder), ``read_version`` (the version the
    file had) and ``problems`` (what a lenient read passed over)."""

    def __init__(self, data, file, read_version, problems=()):
        super().__init__(data)
        self.file = Path(file)
        self.folder = self.file.parent
        self.read_version = read_version
        self.problems = list(problems)

    def path(self, value):
        """A path field's value resolved against the run folder (a Path), or None."""
        out = absolute(value, self.folder)
        return Path(out) if isinstance(out, str) and out else None

    def resolved(self):
        """A deep copy with every path field (PATHS) absolute (for code that opens the files)."""
        out = Run(copy.deepcopy(dict(self)), self.file, self.read_version, self.problems)
        return _map_paths(out, lambda v: absolute(v, self.folder))

    def entries(self, section="runs"):
        """The dict items of runs (or jobs, sweeps, stability, studies); anything else is passed over."""
        items = self.get(section)
        return [r for r in items if isinstance(r, dict)] if isinstance(items, list) else []


def _version_of(data, file, strict):
    """(the version of a file's content, problem or None)."""
    if "schema_version" not in data:
        return 1, None
    v = data["schema_version"]
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        problem = f"{file}: schema_version {v!r} is not a version (a positive integer)"
    elif v > SCHEMA_VERSION:
        problem = (f"{file}: schema_version {v} was written by a newer spectral_bench (this one reads up to "
                   f"{SCHEMA_VERSION})")
    else:
        return v, None
    if strict:
        raise RecordError(problem)
    return SCHEMA_VERSION, problem + f"; read as version {SCHEMA_VERSION}"


def _v1_folder(data):
    """Where a version-1 file's run folder was when it was written: from a study job's absolute
    ``image_path`` and its relative ``image``, else an absolute ``options.out``; None if unknown."""
    for job in data.get("jobs") if isinstance(data.get("jobs"), list) else ():
        if isinstance(job, dict) and isinstance(job.get("image_path"), str) and isinstance(job.get("image"), str):
            full, rel = Path(job["image_path"]), Path(job["image"])
            if full.is_absolute() and not rel.is_absolute() and rel.parts and full.parts[-len(rel.parts):] == rel.parts:
                return Path(*full.parts[:-len(rel.parts)])
    out = (data.get("options") or {}).get("out") if isinstance(data.get("options"), dict) else None
    return Path(out) if isinstance(out, str) and Path(out).is_absolute() else None


def _from_v1(data, folder):
    """Version 1 (no schema_version, before issue 24): paths of references, reference problems
    and study jobs' images were absolute; no tool; everything else is as version 2 has it. An
    absolute path inside the run folder where the file was written becomes relative to that folder
    (it moved with it, if the folder moved); any other (a reference) relative to where the file
    is now, so it still names the same file."""
    data["tool"] = {"version": None, "commit": None}
    then = _v1_folder(data)

    def upgrade(value):
        if then is not None and isinstance(value, str) and Path(value).is_absolute():
            try:
                return Path(value).relative_to(then).as_posix()
            except ValueError:
                pass
        return relative(value, folder)
    return _map_paths(data, upgrade)


# version -> the function that lifts a file's content from it to the next version
UPGRADES = {1: _from_v1}


def read(path, *, strict=True):
    """The metrics.json at ``path`` (the file or its run folder) as a Run upgraded to
    SCHEMA_VERSION. RecordError, naming the file, when it cannot be read, is not JSON, is not an
    object; with ``strict`` (resume, compare) also when its schema_version is not a version this
    code reads. Not strict (report, panel: show what can be shown of any file): such a version is
    read as the current one, with the problem in ``Run.problems``. The per-block arrays stored
    beside the images are put back (module doc); one that cannot be read raises RecordError when
    ``strict``, else reads as None with the problem. Content is not validated here: ``validate``
    does that."""
    path = Path(path)
    if path.is_dir() or path.name != FILE_NAME and not path.suffix:
        path = path / FILE_NAME
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise RecordError(f"cannot read {path}: {exc.strerror or exc}") from None
    except (ValueError, RecursionError) as exc:  # not UTF-8, not JSON, nested too deep
        raise RecordError(f"{path} is not a readable metrics.json: {type(exc).__name__}: {exc}") from None
    if not isinstance(data, dict):
        raise RecordError(f"{path} is not the metrics.json of a run: an object expected, got {type(data).__name__}")
    version, problem = _version_of(data, path, strict)
    read_version = version
    while version < SCHEMA_VERSION:
        data = UPGRADES[version](data, path.parent)
        version += 1
    data["schema_version"] = SCHEMA_VERSION
    problems = [problem] if problem else []
    _load_arrays(data, path.parent, strict, problems)
    return Run(data, path, read_version, problems)


# -- validating ------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def schema():
    return json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))


def validate(data):
    """["<field path>: <problem>"] for every place ``data`` breaks the schema ([] when it holds)."""
    import jsonschema
    validator = jsonschema.Draft202012Validator(schema(), format_checker=jsonschema.Draft202012Validator.FORMAT_CHECKER)
    out = []
    for err in sorted(validator.iter_errors(data), key=lambda e: [str(p) for p in e.absolute_path]):
        where = "/".join(str(p) for p in err.absolute_path) or "(top level)"
        out.append(f"{where}: {err.message[:300]}")
    return out


# -- formatting ------------------------------------------------------------------------------------
def _number(x):
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _scale_figures(sc):
    """The scale test's worst channel (largest |z|) as "B 0.11 % bright (+- 0.03)", or ""."""
    s, se, z = (sc.get(k) if isinstance(sc.get(k), list) else [] for k in ("s", "se", "z"))
    worst = [(abs(z[i]), i) for i in range(min(len(s), len(se), len(z)))
             if _number(z[i]) and _number(s[i]) and _number(se[i])]
    if not worst:
        return ""
    i = max(worst)[1]
    name = "RGB"[i] if i < 3 else f"channel {i + 1}"
    word = "bright" if s[i] > 1 else "dark"
    return f"{name} {abs(s[i] - 1) * 100:.2g} % {word} (+- {se[i] * 100:.2g}), "


def noise_test_parts(test):
    """The parts of a noise test record (a run entry's ``test``, or a comparison's) as [(passed,
    name, figures)], the failing ones first, each with its own figures: the block test ("p_min P
    (threshold T), z_max Z"), the scale test ("B 0.11 % bright (+- 0.03), p P (threshold T)": its
    channel of largest |z|, batch/verdict/compare.py ``scale_stats``) and, for a test that failed
    while both passed, the render's non-finite pixels (the third way z_test fails). Empty for a
    record without the block test's figures."""
    if not isinstance(test, dict) or not (_number(test.get("p_min")) and _number(test.get("threshold"))):
        return []
    block_ok = test.get("block_pass")
    if not isinstance(block_ok, bool):
        block_ok = test["p_min"] >= test["threshold"]
    parts = [(block_ok, "block test", f"p_min {test['p_min']:.3g} (threshold {test['threshold']:.3g})"
              + (f", z_max {format_z(test['z_max'], 2)}" if _number(test.get("z_max")) else ""))]
    sc = test.get("scale_test")
    if isinstance(sc, dict) and _number(sc.get("p_min")) and _number(sc.get("threshold")):
        ok = sc.get("pass") if isinstance(sc.get("pass"), bool) else sc["p_min"] >= sc["threshold"]
        parts.append((ok, "scale test", f"{_scale_figures(sc)}p {sc['p_min']:.3g} (threshold {sc['threshold']:.3g})"))
    if test.get("pass") is False and all(ok for ok, _, _ in parts):
        parts.append((False, "finite values", "NaN or Inf in the render"))
    return sorted(parts, key=lambda part: part[0])  # stable: the failing parts first, in this order


def noise_test_failure(test):
    """What failed in a noise test record, each failing part with its own figures ("scale test: B
    0.2 % dark (+- 0.05), p P (threshold T)"), or "" when no part failed."""
    return "; ".join(f"{name}: {figures}" for ok, name, figures in noise_test_parts(test) if not ok)


def noise_test_text(test):
    """The noise test of a run entry (its ``test``) as one line of text, the cell of summary.md,
    report.html, JUnit and the panel: "FAIL: scale test failed: B 0.2 % dark (+- 0.05), p P
    (threshold T); block test passed: p_min P (threshold T), z_max Z" (the failing part first, each
    part with its own figures: ``noise_test_parts``), "pass: block test p_min ...; scale test ...",
    for a record without a scale test "pass: p_min P (threshold T), z_max Z" or "FAIL: ...", "not
    judged: why", "FAIL: why", or "" when there is no test (no character that Markdown or HTML
    would escape). Any value of the wrong type is shown as text or left out, never raises."""
    if not isinstance(test, dict):
        return ""
    passed, reason = test.get("pass"), test.get("reason")
    reason = "" if reason is None else " ".join(str(reason).split())
    if passed is not True and passed is not False:
        return f"not judged: {reason}" if reason else "not judged"
    word = "pass" if passed else "FAIL"
    parts = noise_test_parts(test)
    if not parts:
        return f"{word}: {reason}" if reason else word
    if len(parts) == 1 and parts[0][1] == "block test":  # the block test alone (no scale test): its figures
        return f"{word}: {parts[0][2]}"
    if passed:
        return f"{word}: " + "; ".join(f"{name} {figures}" for _, name, figures in parts)
    return f"{word}: " + "; ".join(f"{name} {'passed' if ok else 'failed'}: {figures}" for ok, name, figures in parts)


def flip_text(run):
    """HDR-FLIP of a run entry as one short text: its mean ("0.0123"), "not computed (verdict ok;
    --flip on computes it)" or "not computed (--flip off)" where the run chose not to compute it
    (``flip_not_computed``), "not computed: why" where it failed (``flip_error``), or "" where there
    was nothing to compare with. Never a blank or a 0 for a render FLIP skipped (issue 45); the
    summary, the report, JUnit and the panel all show this text."""
    if not isinstance(run, dict):
        return ""
    flip = (run.get("metrics") or {}).get("flip") if isinstance(run.get("metrics"), dict) else None
    if _number(flip):
        return f"{flip:.4g}"
    why = run.get("flip_not_computed")
    if isinstance(why, str) and why:
        return f"not computed ({' '.join(why.split())})"
    err = run.get("flip_error")
    if isinstance(err, str) and err:
        return "not computed: " + " ".join(err.split()).removeprefix("FLIP not computed: ")
    return ""


def inside_parts(folder, rel):
    """The parts of ``rel`` (a path from a metrics.json: anyone's text) if it is a relative path to
    a file that exists inside ``folder`` (no absolute path, no drive, no '.' or '..', no link out);
    else None. Shared by every reader that opens or links a file a metrics.json names."""
    text = str(rel) if isinstance(rel, (str, PurePosixPath, PureWindowsPath)) else ""
    if not text or "\0" in text or PurePosixPath(text).is_absolute() or PureWindowsPath(text).anchor:
        return None
    parts = PureWindowsPath(text).parts if "\\" in text else PurePosixPath(text).parts
    if not parts or any(p in ("", ".", "..") for p in parts):
        return None
    try:
        path = (Path(folder) / Path(*parts)).resolve()
        if not path.is_file() or not path.is_relative_to(Path(folder).resolve()):
            return None
    except (OSError, ValueError):
        return None
    return parts
