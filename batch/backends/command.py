"""Declared renderers: any renderer that runs as a command, plugged in by a TOML declaration
instead of code (docs/backends.md, "Add your renderer"; examples/ holds a worked one).

    [renderers.ring]
    command = ["ring", "{scene}", "-o", "{output}", "--spp", "{spp}", "--seed", "{seed}"]
    reads   = "json"            # the export it reads: json | mitsuba | art | luxcore | cycles
    writes  = "rgb"             # rgb (EXR R, G, B [, S0.R ... S3.B]) | spectral (Fichet 2021 EXR)
    models  = ["spectral"]      # the needs it models; a scene needing more is unsupported, naming the need
    version = ["ring", "--version"]   # the first line it prints is recorded (and matched by known deviations)

The declaration is plain data: a job carries it (``backend_options``) and rebuilds the backend
from it on any worker; ``--resume`` compares the one the user gives again with the one metrics.json
records and never runs a recorded one (batch/jobs/plan.py RUNS_CODE). Every key and placeholder is
checked when the declaration is read (``parse``): an unknown key, a missing or unknown
placeholder, a wrong type is a DeclarationError naming the file, the renderer and the key.
The command is run without a shell, one argument per list item; placeholders are replaced inside
items (``"--spp={spp}"`` works) and ``{{``/``}}`` stand for braces.

Each pass is one run of the command (batch/backends/passes.py renders the passes, retries a
failed one once, and computes the mean and the per-pixel standard error): with its seed, its
share of the samples, and its own output file, in its own working folder, in its own session
(``run_captured``: output capped, the whole process group ended with the pass).
"""
import os
import shutil
import string
import sys
from functools import lru_cache
from pathlib import Path

from ...exporters import names as scene_names
from . import passes as passes_mod
from .passes import BackendFailure

READS = ("json", "mitsuba", "art", "luxcore", "cycles")
WRITES = ("rgb", "spectral")
BAND_MODELS = ("hat", "point", "box")  # batch/spectral_exr.py BAND_MODELS (no import at load: the extension lists declarations)
NEEDS = ("spectral", "polarization", "thin_film", "dispersion", "fluorescence")
OBSERVERS = ("cie1931", "cie1964")
# placeholder -> what it becomes (docs/backends.md, "Add your renderer")
PLACEHOLDERS = {
    "scene": "the exported scene file the renderer reads (absolute path)",
    "scene_dir": "the folder of the exported scene (meshes, spectra beside it)",
    "output": "the EXR file this pass must write (absolute path)",
    "spp": "samples per pixel of this pass",
    "seed": "this pass's seed (distinct for every pass: passes must be independent)",
    "width": "image width in pixels", "height": "image height in pixels",
    "threads": "CPU threads the renderer may use",
    "pass": "this pass's number, 0 to passes - 1",
    "here": "the folder of the file that declared the renderer",
    "python": "the Python interpreter running the benchmark",
}
REQUIRED_PLACEHOLDERS = ("output", "spp", "seed")  # and scene or scene_dir
VERSION_TIMEOUT_S = 60


class DeclarationError(ValueError):
    """A declaration that cannot be used (a usage error, exit 2), naming file, renderer and key."""


def _strings(v, what):
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not v or not all(isinstance(x, str) and x.strip() and "\x00" not in x for x in v):
        raise ValueError(f"must be a non-empty list of non-empty strings ({what}), got {v!r}")
    return list(v)


def _choice(options):
    def check(v):
        if v not in options:
            raise ValueError(f"must be one of {', '.join(options)}, got {v!r}")
        return v
    return check


def _needs(v):
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise ValueError(f"must be a list of needs ({', '.join(NEEDS)}), got {v!r}")
    unknown = [x for x in v if x not in NEEDS]
    if unknown:
        raise ValueError(f"unknown needs {unknown} (the IR's needs: {', '.join(NEEDS)})")
    return sorted(set(v))


def _timeout(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= 7 * 24 * 3600:
        raise ValueError(f"must be seconds per pass, a number in (0, 604800], got {v!r}")
    return float(v)


def _band_width(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= 100:
        raise ValueError(f"must be a band width in nm, a number in (0, 100], got {v!r}")
    return float(v)


def _env(v):
    if not isinstance(v, dict) or not all(isinstance(k, str) and k and "=" not in k and "\x00" not in k
                                          and isinstance(x, str) and "\x00" not in x for k, x in v.items()):
        raise ValueError(f"must be a table of NAME = \"value\" strings, got {v!r}")
    return dict(v)


def _groups(v):
    names = _strings(v, "group names")
    for n in names:
        if scene_names.problem(n):
            raise ValueError(f"group {n!r}: {scene_names.problem(n)}")
    return names


def _text(v):
    if not isinstance(v, str) or "\x00" in v:
        raise ValueError(f"must be a string, got {v!r}")
    return v


# key -> (required, check, what it means): the declaration's whole vocabulary
KEYS = {
    "command": (True, lambda v: _strings(v, "program and arguments"), "the command line of one pass, one list item per argument"),
    "reads": (True, _choice(READS), "the export the renderer reads"),
    "writes": (False, _choice(WRITES), "rgb: EXR R, G, B (+ S0.R ... S3.B); spectral: the Fichet 2021 spectral EXR layout"),
    "models": (True, _needs, "what the renderer models; a scene needing more is unsupported"),
    "version": (False, lambda v: _strings(v, "a command printing the version"), "a command whose first output line is recorded"),
    "timeout": (False, _timeout, "seconds per pass (default: the run's --timeout)"),
    "env": (False, _env, "environment variables added for the command"),
    "observer": (False, _choice(OBSERVERS), "with writes = spectral: the observer integrating the bands (default cie1931)"),
    "bands": (False, _choice(BAND_MODELS), "with writes = spectral: what a channel holds: hat (default) or point, "
              "samples at its wavelength; box, the mean radiance over its band (edges midway between centres)"),
    "band_width_nm": (False, _band_width, "with bands = box: the bands' width in nm (default: the spacing of the centres)"),
    "groups": (False, _groups, "groups of -r this renderer joins (e.g. spectral: it runs by default)"),
    "description": (False, _text, "one line shown in lists and the Blender panel"),
}


def placeholders(item):
    """The placeholder names in one command item; ValueError for anything but a plain {name}."""
    found = []
    try:
        parsed = list(string.Formatter().parse(item))
    except ValueError as exc:
        raise ValueError(f"{item!r}: {exc} (write {{{{ and }}}} for literal braces)") from None
    for _literal, field, spec, conversion in parsed:
        if field is None:
            continue
        if field not in PLACEHOLDERS or spec or conversion:
            raise ValueError(f"{item!r}: unknown placeholder {{{field}{'!' + conversion if conversion else ''}"
                             f"{':' + spec if spec else ''}}} (known: {', '.join('{' + p + '}' for p in PLACEHOLDERS)})")
        found.append(field)
    return found


def parse(name, table, source="(settings)", here=None):
    """A checked, plain-data declaration of renderer ``name`` from its TOML table; ``source``: the
    file it came from (named in errors), ``here``: its folder ({here}). Raises DeclarationError."""
    where = f"{source}: renderer {name!r}"
    problem = scene_names.problem(name, "renderer name")
    if problem:
        raise DeclarationError(f"{source}: [renderers.{name}]: {problem}")
    from . import BACKENDS, GROUPS
    if name in BACKENDS or name in GROUPS:
        raise DeclarationError(f"{where}: the name is taken by a built-in backend or group "
                               f"({', '.join([*BACKENDS, *GROUPS])}); choose another")
    if not isinstance(table, dict):
        raise DeclarationError(f"{where}: must be a table of keys ({', '.join(KEYS)}), got {table!r}")
    unknown = sorted(set(table) - set(KEYS) - {"here", "source"})
    if unknown:
        raise DeclarationError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(KEYS)})")
    decl = {}
    for key, (required, check, _what) in KEYS.items():
        if key not in table:
            if required:
                raise DeclarationError(f"{where}: missing key {key!r} ({KEYS[key][2]})")
            continue
        try:
            decl[key] = check(table[key])
        except ValueError as exc:
            raise DeclarationError(f"{where}: {key}: {exc}") from None
    decl.setdefault("writes", "rgb")
    for key in ("observer", "bands", "band_width_nm"):
        if key in decl and decl["writes"] != "spectral":
            raise DeclarationError(f"{where}: {key}: only a renderer that writes = \"spectral\" is integrated by the benchmark")
    if "band_width_nm" in decl and decl.get("bands") != "box":
        raise DeclarationError(f"{where}: band_width_nm: only with bands = \"box\" (a sample has no width)")
    used = []
    for key in ("command", "version"):
        for item in decl.get(key, []):
            try:
                found = placeholders(item)
            except ValueError as exc:
                raise DeclarationError(f"{where}: {key}: {exc}") from None
            if key == "version" and set(found) - {"here", "python"}:
                raise DeclarationError(f"{where}: version: only {{here}} and {{python}} mean something there")
            used += found if key == "command" else []
    missing = [p for p in REQUIRED_PLACEHOLDERS if p not in used]
    if "scene" not in used and "scene_dir" not in used:
        missing.insert(0, "scene")
    if missing:
        raise DeclarationError(f"{where}: command: missing placeholder {', '.join('{' + m + '}' for m in missing)} "
                               f"({PLACEHOLDERS[missing[0]]})")
    decl["here"] = str(Path(here if here is not None else table.get("here", ".")).resolve())
    decl["source"] = str(table.get("source", source))
    return decl


def load_file(path):
    """{name: declaration} of a renderers file (TOML: ``[renderers.NAME]`` tables and nothing else)."""
    import tomllib
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise DeclarationError(f"renderers file {path}: {exc}") from None
    other = sorted(set(data) - {"renderers"})
    if other or not isinstance(data.get("renderers"), dict) or not data["renderers"]:
        raise DeclarationError(f"renderers file {path}: must hold [renderers.NAME] tables only"
                               + (f" (unknown key {other[0]!r})" if other else ""))
    return tables(data["renderers"], path)


def tables(renderers, source):
    """{name: declaration} from a ``renderers`` table (of a renderers or settings file)."""
    if not isinstance(renderers, dict):
        raise DeclarationError(f"{source}: renderers must be [renderers.NAME] tables, got {renderers!r}")
    return {name: parse(name, table, str(source), Path(source).resolve().parent) for name, table in renderers.items()}


def recheck(declared):
    """Declarations read back (metrics.json of a resumed run): every one through ``parse`` again."""
    if not isinstance(declared, dict):
        raise DeclarationError(f"renderers must be a table of declarations, got {declared!r}")
    return {name: parse(name, table, table.get("source", "(recorded)") if isinstance(table, dict) else "(recorded)")
            for name, table in declared.items()}


def expand_command(items, values):
    """The command with its placeholders replaced (each item stays one argument)."""
    return [item.format(**values) for item in items]


class CommandBackend:
    """A declared renderer: exports what it reads, renders each pass by running its command."""

    def __init__(self, name, declaration, executable=None):
        self.name, self.decl, self.executable = name, dict(declaration), executable
        self.formats = (self.decl["reads"],)
        self.options = {"declaration": self.decl, "executable": executable}  # what rebuilds this backend

    # -- what it can run --------------------------------------------------------------------
    def _values(self, **kw):
        base = {"here": self.decl["here"], "python": sys.executable}
        base.update(kw)
        return base

    def program(self):
        """The program the command runs (``-e NAME=PATH`` replaces it), resolved as the system
        would: a bare name on PATH, a path relative to the declaring file's folder."""
        first = self.executable or self.decl["command"][0].format(**self._values(**{p: "" for p in PLACEHOLDERS
                                                                                      if p not in ("here", "python")}))
        if os.sep in first or (os.altsep and os.altsep in first):
            p = Path(first)
            return p if p.is_absolute() else Path(self.decl["here"]) / p
        found = shutil.which(first)
        return Path(found) if found else None

    def availability(self):
        prog = self.program()
        if prog is None or not prog.is_file():
            return False, (f"{self.name}: program {self.executable or self.decl['command'][0]!r} not found "
                           f"(declared in {self.decl['source']}; give it with -e {self.name}=PATH or put it on PATH)")
        if not os.access(prog, os.X_OK):
            return False, f"{self.name}: {prog} is not executable"
        return True, ""

    def mode_for(self, scene):
        missing = sorted(set(scene.get("needs", [])) - set(self.decl["models"]))
        if missing:
            return None, (f"{self.name} does not model {', '.join(missing)} (its declaration in {self.decl['source']} "
                          f"lists models = {self.decl['models']})")
        return self.decl["writes"], None

    def export(self, scene, out_dir):
        return EXPORTS[self.decl["reads"]](scene, Path(out_dir))

    # -- rendering --------------------------------------------------------------------------
    def render(self, path, mode, spp, out_exr, passes=1, seed=0, timeout=1800, log_path=None):
        """Render in independent passes (batch/backends/passes.py); returns the render record."""
        return passes_mod.render(self, path, mode, spp, out_exr, passes, seed, timeout, log_path)

    def session(self, path, mode, log):
        info = {"versions": {self.name: self.version()}, "declared_in": self.decl["source"]}
        return passes_mod.OneProcessPerPass(lambda spp, seed, out, timeout, log: self._pass(path, spp, seed, out, timeout, log),
                                            log, info)

    def _pass(self, path, spp, seed, out, timeout, log):
        path, out = Path(path).resolve(), Path(out).resolve()
        width, height = _size(path.parent)
        work = out.parent / f"{out.stem}.work"
        work.mkdir(parents=True, exist_ok=True)
        values = self._values(scene=str(path), scene_dir=str(path.parent), output=str(out), spp=spp, seed=seed,
                              width=width, height=height, threads=os.cpu_count() or 1, **{"pass": _pass_number(out)})
        cmd = expand_command(self.decl["command"], values)
        if self.executable:
            cmd[0] = self.executable
        elif not os.path.isabs(cmd[0]) and os.sep in cmd[0]:
            cmd[0] = str(Path(self.decl["here"]) / cmd[0])
        env = dict(os.environ, **self.decl.get("env", {}))
        wall = passes_mod.run_command(cmd, self.decl.get("timeout", timeout), log, self.name, env=env, cwd=work)
        if not out.is_file():
            raise BackendFailure(f"{self.name} exited with 0 but wrote no {out.name} (the command's {{output}})")
        try:
            names, img, spectral = read_output(out, self.decl["writes"], self.decl.get("observer", "cie1931"),
                                               (width, height) if width else None, self.band_model())
        except Exception as exc:  # noqa: BLE001 - whatever the EXR reader raises on a corrupt file fails this pass (retried)
            raise BackendFailure(f"{self.name} wrote {out} ({{output}}), which cannot be read as a "
                                 f"{self.decl['writes']} EXR: {type(exc).__name__}: {str(exc)[:300]}") from exc
        if img.shape[:2] != (height, width) and width:
            raise BackendFailure(f"{self.name} wrote a {img.shape[1]}x{img.shape[0]} image; the scene is {width}x{height}")
        shutil.rmtree(work, ignore_errors=True)
        return {"names": names, "image": img, "time_s": wall, "spectral": spectral}

    def band_model(self):
        """(model, band width in nm or None) of a spectral renderer's channels (spectral_exr.BAND_MODELS)."""
        return self.decl.get("bands", "hat"), self.decl.get("band_width_nm")

    def version(self):
        if not self.decl.get("version"):
            return "not declared"
        cmd = expand_command(self.decl["version"], self._values())
        return _version(tuple(cmd), self.decl["here"], tuple(sorted(self.decl.get("env", {}).items())))


@lru_cache(maxsize=None)
def _version(cmd, here, env):
    """The first non-empty line a version command prints (stdout, else stderr), or why not."""
    try:  # in its own session, output capped, its group ended with it: as a pass (batch/backends/passes.py)
        code, out, err = passes_mod.run_captured(list(cmd), VERSION_TIMEOUT_S, dict(os.environ, **dict(env)), here)
    except (OSError, BackendFailure) as exc:
        return f"unknown ({type(exc).__name__}: {exc.args[0] if exc.args else exc})"[:200]
    if code is None:
        return f"unknown (the version command ran past {VERSION_TIMEOUT_S} s)"
    for text in (out.text(), err.text()):
        for line in text.splitlines():
            if line.strip():
                return line.strip()[:200]
    return f"unknown (the version command printed nothing, exit {code})"


def read_output(path, writes, observer, expect=None, band_model=("hat", None)):
    """(channel names, H x W x C, spectral or None) of what a pass wrote: an RGB EXR's R, G, B
    (+ S0.R ... S3.B), or a Fichet 2021 spectral EXR integrated to the same channels under its band
    model (batch/spectral_exr.py), with its S0 bands kept for the band checks (``spectral``:
    {"wavelengths_nm", "cube": H x W x N, "bands", "band_width_nm"}). ``expect``: the scene's
    (width, height), checked in the EXR's header before any pixel is read."""
    if writes == "spectral":
        from .. import spectral_exr
        image = spectral_exr.read(path, expect)
        names, img = spectral_exr.to_rgb(image, observer, *band_model)
        return names, img, spectral_exr.pass_bands(image, *band_model)
    from .. import exr
    names, img = exr.read_image(path, expect=expect)
    keep = [i for i, n in enumerate(names) if n not in ("A", "W")]
    return [names[i] for i in keep], img[..., keep], None


def _pass_number(out):
    stem = Path(out).stem
    return int(stem[4:]) if stem.startswith("pass") and stem[4:].isdigit() else 0


def _size(export_dir):
    """(width, height) the export was written for (recorded beside it by ``_export``)."""
    import json
    try:
        meta = json.loads((Path(export_dir) / ".render_size.json").read_text())
        return int(meta["width"]), int(meta["height"])
    except (OSError, ValueError, KeyError):
        return 0, 0


def _export(write):
    """An export for a declared renderer: the writer's file, with the size it renders recorded."""
    def run(scene, out_dir):
        import json
        path = write(scene, out_dir)
        r = scene["render"]
        (Path(path).parent / ".render_size.json").write_text(json.dumps({"width": r["width"], "height": r["height"]}))
        return path
    return run


def _json(scene, out_dir):
    from ...exporters import ir_json, names
    return ir_json.write(scene, out_dir / f"{names.file_stem(scene['name'])}.json")


def _mitsuba(scene, out_dir):
    from ...exporters import mitsuba_writer
    return mitsuba_writer.write(scene, out_dir)


def _art(scene, out_dir):
    from ...exporters import art_writer
    return art_writer.write(scene, out_dir)[0]


def _rgb(backend_name):
    def write(scene, out_dir):
        from . import get
        return get(backend_name, approximate=False).export(scene, out_dir)
    return write


EXPORTS = {"json": _export(_json), "mitsuba": _export(_mitsuba), "art": _export(_art),
           "luxcore": _export(_rgb("luxcore")), "cycles": _export(_rgb("cycles"))}
