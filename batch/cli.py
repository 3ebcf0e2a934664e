"""Command line of the batch runner (the thesis' CLI, section 3.4, plus sampling options).

Identical under ``blender -b scenes.blend -P batch/run.py -- [options]`` and
``python batch/run.py [options]``: everything after ``--`` is ours; without ``--`` everything
after the script is. Every option can also come from a settings file (TOML or JSON, keys are
the long option names with ``_``); options given on the command line win. Repeated ``-i`` and
``--settings`` accumulate (later settings files win over earlier ones).

Every value, from the command line or a settings file, goes through the same checks at parse
(its type and its bounds below); a bad one is a usage error (exit 2) naming the option.
"""
import argparse
import json
import math
import re
import tomllib
from pathlib import Path

from ..exporters import names as scene_names, validate
from .backends import BACKENDS, DEFAULT, GROUPS, command, expand, known_names

DEVICES = ("cpu", "gpu", "auto")  # --device (batch/backends/mitsuba/cuda.py)
FORMATS = ("mitsuba", "art", "json", "cycles", "luxcore", "pbrt")
# Bounds of the options (documented in --help and docs/running.md's option table)
MAX_SPP = validate.render_limit("spp")[1]  # samples per pixel: the scene IR's own bound
MAX_SCALE = 4.0            # resolution scale
MAX_PASSES = 256
MAX_SEED = (1 << 31) - 1
MAX_WORKERS = 256          # --cluster local:N
DEFAULT_CLUSTER_TIMEOUT = 60.0

DEFAULTS = {
    "input": None, "case": None, "scene": None, "renderer": None, "exec": None, "spp": None, "scale": 1.0,
    "out": None, "export_only": False, "format": None, "log": None, "visualize": False, "settings": None,
    "variant": None, "device": "auto", "alpha": 0.01, "block": None, "min_samples": 65536, "timeout": 1800, "passes": 2, "seed": 0, "flip": "auto",
    "detect": None, "max_passes": 16,
    "references": None, "known": None, "list": False, "art_ggx": False, "sweep": False, "ladder": None, "sweep_modes": None, "stability": False,
    "approximate": False, "renderers": None, "cluster": None, "cluster_timeout": DEFAULT_CLUSTER_TIMEOUT, "dashboard": None, "resume": None,
    "junit": None,
    "baseline": None, "study": None, "illuminants": None, "visible_de00": 1.0, "film": "rgb",
}


class UsageError(ValueError):
    """A bad option or settings value (exit 2)."""


class SettingsError(UsageError):
    pass


def split_argv(argv):
    """Our arguments from a full sys.argv, Blender-style (after '--') or plain Python."""
    argv = list(argv)
    if "--" in argv:
        return argv[argv.index("--") + 1:]
    return argv[1:]


# -- value types: one check per option, used for the command line and for settings files -------
class Kind:
    """A value type: ``parse(text)`` for the command line, ``native(value)`` for a settings file
    (the value as TOML/JSON gives it: a number must be a number, not a string), both ending in
    ``check``, which raises ValueError with what is allowed."""

    def __init__(self, name, parse, native, check=lambda v: v):
        self.__name__ = name  # argparse names the type in its messages
        self._parse, self._native, self.check = parse, native, check

    def __call__(self, text):  # argparse: a bad value is "argument --opt: message", exit 2
        try:
            return self.check(self._parse(text))
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None

    def from_settings(self, value):
        return self.check(self._native(value))


def _int_text(text):
    try:
        return int(text.strip())
    except ValueError:
        raise ValueError("must be an integer") from None


def _float_text(text):
    try:
        return float(text.strip())
    except ValueError:
        raise ValueError("must be a number") from None


def _native_int(v):
    if isinstance(v, bool) or not isinstance(v, int):
        raise ValueError(f"must be an integer, got {type(v).__name__} {v!r}")
    return v


def _native_float(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"must be a number, got {type(v).__name__} {v!r}")
    return float(v)


def _native_str(v):
    if not isinstance(v, str):
        raise ValueError(f"must be a string, got {type(v).__name__} {v!r}")
    return v


def int_in(lo, hi):
    def check(v):
        if not lo <= v <= hi:
            raise ValueError(f"must be an integer in [{lo}, {hi}], got {v}")
        return v
    return Kind(f"integer in [{lo}, {hi}]", _int_text, _native_int, check)


def number(lo=None, hi=None, lo_open=False, hi_open=False, what=None):
    lo_s = "(" if lo_open else "["
    hi_s = ")" if hi_open else "]"
    rng = what or f"a finite number in {lo_s}{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}{hi_s}"

    def check(v):
        ok = math.isfinite(v) and (lo is None or (v > lo if lo_open else v >= lo)) and \
            (hi is None or (v < hi if hi_open else v <= hi))
        if not ok:
            raise ValueError(f"must be {rng}, got {v!r}")
        return v
    return Kind(rng, _float_text, _native_float, check)


def text_kind(check=lambda v: v, name="text"):
    def parse(text):
        return text
    return Kind(name, parse, _native_str, check)


def _nonempty(v):
    if not v.strip():
        raise ValueError("must not be empty")
    if "\x00" in v:
        raise ValueError("must not contain NUL")
    return v


def _renderer(v):
    """A backend, group or declared renderer's name (declared ones are known only once every
    --renderers file is read: ``parse`` checks the name against them)."""
    if v not in BACKENDS and v not in GROUPS and scene_names.problem(v):
        raise ValueError(f"unknown backend or group (known: {', '.join([*BACKENDS, *GROUPS])}, or a renderer "
                         "declared with --renderers FILE)")
    return v


def _format(v):
    if v not in FORMATS:
        raise ValueError(f"unknown format (known: {', '.join(FORMATS)})")
    return v


def _exec_name(name):
    """Whether the text before '=' in -e is meant as a renderer's name (not part of a path)."""
    return "/" not in name and "\\" not in name


def split_exec(item):
    """(backend or '*', path) from an ``-e [BACKEND=]PATH`` value."""
    name, sep, path = item.partition("=")
    if sep and _exec_name(name):
        return name, path
    return "*", item


def _exec(v):
    _nonempty(v)
    name, sep, path = v.partition("=")
    if sep and _exec_name(name):
        if name not in BACKENDS and scene_names.problem(name):
            raise ValueError(f"unknown backend {name!r} before '=' (form: [BACKEND=]PATH; backends: "
                             f"{', '.join(BACKENDS)} or a declared renderer)")
        if not path.strip():
            raise ValueError(f"no executable after {name}= (form: [BACKEND=]PATH)")
    return v


_HOST = r"(?:[A-Za-z0-9](?:[A-Za-z0-9.-]{0,252})|\[[0-9A-Fa-f:.]+\])"


def _cluster(v):
    if v.startswith("local:"):
        n = v[len("local:"):]
        if not re.fullmatch(r"\d{1,6}", n) or not 1 <= int(n) <= MAX_WORKERS:
            raise ValueError(f"local:N needs a number of workers N in [1, {MAX_WORKERS}]")
        return v
    if not re.fullmatch(rf"(?:(?:tcp|tls|ucx|ws|wss)://)?{_HOST}(?::\d{{1,5}})?", v):
        raise ValueError("must be a scheduler address (tcp://HOST:PORT, tls://HOST:PORT) or local:N")
    port = v.rsplit(":", 1)[-1] if re.search(r":\d{1,5}$", v) else None
    if port is not None and not 1 <= int(port) <= 65535:
        raise ValueError("port must be in [1, 65535]")
    return v


def _dashboard(v):
    m = re.fullmatch(rf"({_HOST})?:(\d{{1,5}})", v)
    if not m or not 0 <= int(m.group(2)) <= 65535:
        raise ValueError("must be [HOST]:PORT, e.g. 127.0.0.1:8787")
    return v


def _comma_list(item_kind, name):
    """'a,b,c' on the command line; a list (or that string) in a settings file."""
    def parse(text):
        parts = [p.strip() for p in text.split(",")]
        if not all(parts):
            raise ValueError("must be a comma-separated list without empty items")
        return [item_kind.check(item_kind._parse(p)) for p in parts]

    def native(v):
        if isinstance(v, str):
            return parse(v)
        if not isinstance(v, list) or not v:
            raise ValueError(f"must be a non-empty list, got {v!r}")
        return [item_kind.from_settings(x) for x in v]
    return Kind(name, parse, native)


SPP = int_in(1, MAX_SPP)


def _mode(v):
    if not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", v):
        raise ValueError("is not a backend mode name (letters, digits, _ and -)")
    return v


_MODE = text_kind(_mode, "mode")
STUDIES = ("spectral-vs-rgb",)  # --study (batch/studies/spectral_vs_rgb.py)


def _one_of(choices, what):
    """A check that a value is one of ``choices`` (the message names ``what`` and lists them)."""
    def check(v):
        if v not in choices:
            raise ValueError(f"is not a {what}: one of {', '.join(choices)}")
        return v
    return check


_study = _one_of(STUDIES, "study")


def _illuminant(v):
    from .studies.spectral_vs_rgb import ILLUMINANTS
    if v not in ILLUMINANTS:
        raise ValueError(f"{v!r} is not an illuminant: one of {', '.join(ILLUMINANTS)}")
    return v


_ILLUMINANT = text_kind(_illuminant, "illuminant")


FLIP_WHEN = {"on": True, "off": False, "auto": "auto"}  # --flip: opts["flip"] (True, False as --no-flip, "auto")


def _flip_text(text):
    if text.strip() not in FLIP_WHEN:
        raise ValueError(f"must be one of {', '.join(FLIP_WHEN)}")
    return FLIP_WHEN[text.strip()]


def _flip_native(v):
    """A settings file's flip: true/false (as before --flip existed) or "on", "off", "auto"."""
    if isinstance(v, bool):
        return v
    if isinstance(v, str) and v in FLIP_WHEN:
        return FLIP_WHEN[v]
    raise ValueError(f"must be true, false, \"on\", \"off\" or \"auto\", got {v!r}")


FILMS = ("rgb", "cmf")  # --film (batch/backends/mitsuba/backend.py FILMS)


_film = _one_of(FILMS, "film")
_device = _one_of(DEVICES, "device")
TYPES = {
    "input": text_kind(_nonempty, "path"), "case": text_kind(_nonempty, "name"), "scene": text_kind(_nonempty, "name"),
    "renderer": text_kind(_renderer, "backend"), "exec": text_kind(_exec, "[BACKEND=]PATH"), "spp": SPP,
    "scale": number(0, MAX_SCALE, lo_open=True), "out": text_kind(_nonempty, "path"), "format": text_kind(_format, "format"),
    "log": text_kind(_nonempty, "path"), "settings": text_kind(_nonempty, "path"), "variant": text_kind(_nonempty, "variant"),
    "device": text_kind(_device, "device"), "alpha": number(0, 1, lo_open=True, hi_open=True), "block": int_in(1, 1 << 16), "min_samples": int_in(1, 1 << 40),
    "timeout": number(0, None, lo_open=True), "passes": int_in(1, MAX_PASSES), "seed": int_in(0, MAX_SEED),
    "detect": number(0, 1, lo_open=True, hi_open=True), "max_passes": int_in(1, MAX_PASSES),
    "references": text_kind(_nonempty, "path"), "known": text_kind(_nonempty, "path"),
    "ladder": _comma_list(SPP, "N,N,..."), "sweep_modes": _comma_list(_MODE, "MODE,..."),
    "cluster": text_kind(_cluster, "address"), "cluster_timeout": number(0, 3600, lo_open=True),
    "dashboard": text_kind(_dashboard, "[HOST]:PORT"), "resume": text_kind(_nonempty, "path"),
    "renderers": text_kind(_nonempty, "path"), "junit": text_kind(_nonempty, "path"),
    "baseline": text_kind(_nonempty, "path"), "flip": Kind("on|off|auto", _flip_text, _flip_native),
    "study": text_kind(_study, "study"), "illuminants": _comma_list(_ILLUMINANT, "NAME,..."),
    "visible_de00": number(0, 100, lo_open=True),
    "film": text_kind(_film, "film"),
}


def parser():
    ap = argparse.ArgumentParser(
        prog="batch/run.py",
        description="Export, render and compare the spectral benchmark scenes.",
        epilog="Under Blender: blender -b scenes.blend -P batch/run.py -- [options]",
        argument_default=argparse.SUPPRESS)
    T = TYPES
    ap.add_argument("-i", "--input", action="extend", nargs="+", type=T["input"], metavar="PATH",
                    help="scenes.blend (default) or one or more scene IR JSON files (repeatable: -i A -i B is -i A B)")
    ap.add_argument("-c", "--case", action="append", type=T["case"], metavar="NAME", help="only scenes of this case (repeatable)")
    ap.add_argument("-s", "--scene", action="append", type=T["scene"], metavar="NAME", help="only this scene (repeatable)")
    ap.add_argument("-r", "--renderer", action="append", type=T["renderer"], metavar="NAME",
                    help=f"backend or group (repeatable): {', '.join(BACKENDS)}; groups "
                         f"{', '.join(f'{g} ({chr(43).join(m)})' for g, m in GROUPS.items())}; default: {', '.join(DEFAULT)}")
    ap.add_argument("-e", "--exec", action="append", type=T["exec"], metavar="[BACKEND=]PATH",
                    help="renderer executable, e.g. mitsuba=/opt/mitsuba/mitsuba (a bare PATH needs exactly one backend)")
    ap.add_argument("--spp", type=T["spp"], metavar="N", help=f"samples per pixel, 1 to {MAX_SPP} (default: each scene's own)")
    ap.add_argument("--scale", type=T["scale"], metavar="F", help=f"resolution scale, 0 < F <= {MAX_SCALE:g} (default 1.0); a render is judged against its "
                         "reference box-filtered by an integer factor in each axis, so a scene whose resolution F "
                         "divides into no integer fraction renders at the nearest scale that does, logged (0.125 "
                         "of the 620x420 charts: 0.1, 62x42); above 1 is refused (exit 2)")
    ap.add_argument("-o", "--out", type=T["out"], metavar="DIR",
                    help="output folder (default: outputs-YYYYmmdd-HHMMSS, with -2, -3, ... if taken)")
    ap.add_argument("--export-only", action="store_true", help="export scenes, render nothing")
    ap.add_argument("--format", action="append", type=T["format"], metavar="FORMAT",
                    help=f"export format for --export-only (repeatable: {', '.join(FORMATS)}; default: mitsuba, art, json; "
                         "cycles writes a .blend, luxcore its .scn/.cfg, pbrt a pbrt-v4 scene.pbrt)")
    ap.add_argument("-l", "--log", type=T["log"], metavar="FILE", help="also write the log to FILE")
    ap.add_argument("-v", "--visualize", action="store_true", help="open the results when done")
    ap.add_argument("--settings", action="extend", nargs="+", type=T["settings"], metavar="FILE",
                    help="settings file (TOML or JSON; repeatable, later files win)")
    ap.add_argument("--renderers", action="append", type=T["renderers"], metavar="FILE",
                    help="declare renderers that run as a command ([renderers.NAME] tables in a TOML file; repeatable; "
                         "docs/backends.md: Add your renderer); select them with -r NAME")
    ap.add_argument("--variant", type=T["variant"], help="force a Mitsuba variant (default: cheapest that models the scene)")
    ap.add_argument("--device", type=T["device"], metavar="cpu|gpu|auto",
                    help="where Mitsuba renders: gpu picks its cuda_ad_* variants (an error where CUDA does not render), "
                         "cpu its llvm_ad_*/scalar_* ones, auto the GPU where a CUDA probe renders (default auto)")
    ap.add_argument("--alpha", type=T["alpha"], help="significance level of the noise test, 0 < ALPHA < 1 (default 0.01)")
    ap.add_argument("--block", type=T["block"], help="block side in pixels of the noise test, >= 1 (default: from --min-samples)")
    ap.add_argument("--min-samples", type=T["min_samples"], help="samples pooled per block of the noise test, >= 1 (default 65536)")
    ap.add_argument("--timeout", type=T["timeout"], help="seconds per render before it is stopped, > 0 (default 1800)")
    ap.add_argument("--passes", type=T["passes"],
                    help=f"independent passes per render, 1 to {MAX_PASSES}: its own per-pixel noise for the verdict (default 2; "
                         "with 1, only the reference's own backend is judged against the reference)")
    ap.add_argument("--detect", type=T["detect"], metavar="S",
                    help="render until decided, 0 < S < 1: after --passes passes, double them (no pass rendered twice) "
                         "until the noise test's detectable scale error is <= S (e.g. 0.01), it fails, or --max-passes; "
                         "each of the K planned looks tests at alpha / K (Bonferroni), so the whole procedure false-alarms "
                         "at most at --alpha (default: off)")
    ap.add_argument("--max-passes", type=T["max_passes"], metavar="N",
                    help=f"cap on the passes of --detect, 1 to {MAX_PASSES} (default 16)")
    ap.add_argument("--seed", type=T["seed"], help=f"first sampler seed, 0 to {MAX_SEED} (default 0)")
    ap.add_argument("--no-flip", dest="flip", action="store_false", help="skip HDR-FLIP (as --flip off)")
    ap.add_argument("--flip", dest="flip", type=T["flip"], metavar="on|off|auto",
                    help="HDR-FLIP against the reference: auto (default): only for renders whose verdict is not ok "
                         "(failed, known, fixed, unjudged), where the error map is looked at; on: for every judged render; off")
    ap.add_argument("--references", action="append", type=T["references"], metavar="DIR",
                    help="reference folder (repeatable: for each scene the first folder holding a usable "
                         "reference wins; default: references/)")
    ap.add_argument("--known", type=T["known"], metavar="FILE", help="known deviations (default: known_deviations.toml)")
    ap.add_argument("--list", action="store_true", help="list the jobs and exit")
    ap.add_argument("--cluster", type=T["cluster"], metavar="ADDRESS",
                    help="run the jobs on a Dask scheduler at ADDRESS (tcp://host:8786, tls://host:8786), or 'local:N' for a "
                         "LocalCluster of N workers on 127.0.0.1 (default: this machine, no extra service)")
    ap.add_argument("--cluster-timeout", type=T["cluster_timeout"], metavar="SECONDS",
                    help=f"how long to wait for the scheduler and its first worker (default {DEFAULT_CLUSTER_TIMEOUT:g})")
    ap.add_argument("--dashboard", type=T["dashboard"], metavar="[HOST]:PORT",
                    help="serve the Dask dashboard of a --cluster local:N there (default: no dashboard)")
    ap.add_argument("--resume", type=T["resume"], metavar="OUT",
                    help="finish the interrupted run in OUT with its own options: finished jobs are kept, the rest run")
    ap.add_argument("--junit", type=T["junit"], metavar="FILE",
                    help="also write the jobs as JUnit XML to FILE (one test case per job: failed a failure; skipped, "
                         "unsupported and unjudged skipped; known and fixed passed, naming the deviation)")
    ap.add_argument("--baseline", type=T["baseline"], metavar="OUT_PREV",
                    help="also judge every job against the matching job (scene, backend, mode) of the previous run in "
                         "OUT_PREV, both on their own noise (metrics.json: baseline; summary: changed jobs first); "
                         "does not change a job's status or the exit status")
    ap.add_argument("--sweep", action="store_true",
                    help="also render each scene over a ladder of sample counts and chart error against time")
    ap.add_argument("--ladder", type=T["ladder"], metavar="N,N,...",
                    help="sample counts of the sweep (default 4,16,64,256)")
    ap.add_argument("--sweep-modes", type=T["sweep_modes"], metavar="MODE,...",
                    help="backend modes to sweep (e.g. llvm_ad_spectral,scalar_spectral,llvm_ad_rgb)")
    ap.add_argument("--study", type=T["study"], metavar="NAME",
                    help="run a study instead of the judged jobs: spectral-vs-rgb renders each scene spectrally and in "
                         "RGB (Mitsuba's variants; Cycles/LuxCore when -r names them), no reference needed, and maps "
                         "where and how much they differ (CIEDE2000, against both renders' noise)")
    ap.add_argument("--illuminants", type=T["illuminants"], metavar="NAME,...",
                    help="--study spectral-vs-rgb: also with every light's spectrum swapped for these CIE illuminants "
                         "at the same luminance (A, D50, D55, D65, D75, E, F2, F7, F8, F11, LED-B1..B5, LED-BH1, "
                         "LED-RGB1, LED-V1, LED-V2)")
    ap.add_argument("--visible-de00", type=T["visible_de00"], metavar="DE",
                    help="--study spectral-vs-rgb: the CIEDE2000 95th percentile that counts as visible (default 1.0)")
    ap.add_argument("--film", type=T["film"], metavar="rgb|cmf",
                    help="-r mitsuba: the film spectra are integrated by: rgb, Mitsuba's own (its 5 nm CIE tables and "
                         "matrix: the recorded deviation mitsuba-cie-y-normalisation; default), or cmf, the scene format's "
                         "colour (CIE 1931 at 1 nm, the IEC 61966-2-1 matrix; unpolarised scenes only)")
    ap.add_argument("--stability", action="store_true",
                    help="also run the stability case (grazing GGX, roughness and IOR furnaces, Malus)")
    ap.add_argument("--approximate", action="store_true",
                    help="RGB backends (cycles, luxcore): render what they cannot express (polariser, Stokes output, "
                         "a missing microfacet distribution) as an explicitly labelled approximation (mode rgb-approx) "
                         "instead of reporting it unsupported")
    ap.add_argument("--art-ggx", action="store_true",
                    help="write GGX_MICROFACET_DISTRIBUTION_CONST for an ART build that has GGX (upstream has Blinn only)")
    return ap


def _settings_value(action, value):
    """A settings file's value for one option, through the option's own type."""
    if action.nargs == 0:  # a flag
        if not isinstance(value, bool):
            raise ValueError(f"must be true or false, got {value!r}")
        return value
    kind = action.type
    many = isinstance(action, (argparse._AppendAction, argparse._ExtendAction))
    if many:
        items = [value] if isinstance(value, str) else value
        if not isinstance(items, list) or not items:
            raise ValueError(f"must be a string or a non-empty list of strings, got {value!r}")
        out = []
        for k, item in enumerate(items):
            try:
                out.append(kind.from_settings(item))
            except ValueError as exc:
                raise ValueError(f"item {k}: {exc}") from None
        return out
    return kind.from_settings(value)


def load_settings(path):
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (OSError, ValueError, RecursionError) as exc:
        raise SettingsError(f"settings file {path}: {exc}") from exc
    if not isinstance(data, dict):
        raise SettingsError(f"settings file {path}: must hold a table/object of options, got {type(data).__name__}")
    data = {str(k).replace("-", "_"): v for k, v in data.items()}
    unknown = sorted(set(data) - set(DEFAULTS) | ({"settings"} & set(data)))
    if unknown:
        raise SettingsError(f"settings file {path}: unknown keys {unknown} (known: {sorted(set(DEFAULTS) - {'settings'})})")
    actions = {a.dest: a for a in parser()._actions}
    out = {}
    for key, value in data.items():
        if key == "renderers":  # declarations ([renderers.NAME] tables) or renderers files, relative to this file
            out[key] = _settings_renderers(value, path)
            continue
        try:
            out[key] = _settings_value(actions[key], value)
        except ValueError as exc:
            raise SettingsError(f"settings file {path}: {key} = {value!r}: {exc}") from None
    return out


def _settings_renderers(value, path):
    """{name: declaration} from a settings file's ``renderers``: tables, or files to read."""
    try:
        if isinstance(value, dict):
            return command.tables(value, path)
        files = [value] if isinstance(value, str) else value
        if not isinstance(files, list) or not all(isinstance(f, str) and f.strip() for f in files):
            raise command.DeclarationError(f"settings file {path}: renderers must be [renderers.NAME] tables or "
                                           f"renderers files, got {value!r}")
        return merge_declarations([(Path(path).parent / f, command.load_file(Path(path).parent / f)) for f in files])
    except command.DeclarationError as exc:
        raise SettingsError(str(exc)) from None


def merge_declarations(sources):
    """One {name: declaration} from [(where, {name: declaration})]: a name declared twice is refused."""
    out, origin = {}, {}
    for where, decls in sources:
        for name, decl in decls.items():
            if name in out and out[name] != decl:
                raise command.DeclarationError(f"renderer {name!r} is declared twice: in {origin[name]} and in {where}")
            out[name], origin[name] = decl, where
    return out


def check_option(key, value):
    """``value`` for option ``key`` through the option's own type (as from a settings file; ``exec``
    as the {BACKEND or '*': PATH} it becomes); raises UsageError naming the option."""
    if value is None or value == DEFAULTS.get(key):
        return value
    try:
        if key == "exec":
            if not isinstance(value, dict):
                raise ValueError(f"must be a table of BACKEND = PATH, got {value!r}")
            for name, path in value.items():
                if name != "*" and name not in BACKENDS and scene_names.problem(name) \
                        or not isinstance(path, str) or not path.strip():
                    raise ValueError(f"bad entry {name!r} = {path!r}")
            return dict(value)
        if key == "renderers":
            return command.recheck(value)
        actions = {a.dest: a for a in parser()._actions}
        if key not in actions:
            raise ValueError("unknown option")
        return _settings_value(actions[key], value)
    except ValueError as exc:
        raise UsageError(f"option {key} = {value!r}: {exc}") from None


class Options(dict):
    """The options (a plain dict to every reader) and which of them this command gave
    (``given``: from the command line or a settings file); ``defaults`` and ``check`` (each
    option through its own type) travel with them, for ``--resume`` (batch/jobs/plan.py), which
    imports no entry point."""
    given = frozenset()
    defaults = DEFAULTS

    @staticmethod
    def check(key, value):
        return check_option(key, value)


def parse(args):
    """Options dict: defaults < settings files < command line. Raises UsageError (argparse itself
    exits 2 on a bad command-line value, naming the option)."""
    ap = parser()
    cli = vars(ap.parse_args(args))
    opts = Options(DEFAULTS)
    given = set(cli)
    declared, loaded = [], []
    for path in cli.get("settings") or []:
        settings = load_settings(path)
        given |= set(settings)
        if "renderers" in settings:
            declared.append((path, settings.pop("renderers")))
        loaded.append((path, settings))
        opts.update(settings)
    try:
        declared += [(f, command.load_file(f)) for f in cli.pop("renderers", None) or []]
        opts["renderers"] = merge_declarations(declared) or None
    except command.DeclarationError as exc:
        raise UsageError(str(exc)) from None
    # names of declared renderers are known only now: -r and -e NAME= are checked against them
    known = known_names(opts["renderers"])
    for path, settings in loaded:
        for key, names in (("renderer", settings.get("renderer") or []),
                           ("exec", [split_exec(e)[0] for e in settings.get("exec") or []])):
            bad = [n for n in names if n != "*" and n not in known]
            if bad:
                raise SettingsError(f"settings file {path}: {key}: {bad[0]!r} is no backend, group or declared "
                                    f"renderer (known: {', '.join(known)})")
    for name in cli.get("renderer") or []:
        if name not in known:
            ap.error(f"argument -r/--renderer: {name!r}: unknown backend, group or declared renderer "
                     f"(known: {', '.join(known)})")
    for item in cli.get("exec") or []:
        name = split_exec(item)[0]
        if name != "*" and name not in known:
            ap.error(f"argument -e/--exec: {item!r}: {name!r} is no backend or declared renderer (known: {', '.join(known)})")
    opts.update(cli)
    opts.given = frozenset(given)
    execs = {}
    for item in opts["exec"] or []:
        name, path = split_exec(item)
        execs[name] = path
    if "*" in execs and len(expand(opts["renderer"], opts["renderers"])) != 1:
        raise UsageError(f"-e {execs['*']}: a PATH without BACKEND= needs exactly one backend (-r NAME); "
                         f"write BACKEND=PATH (backends: {', '.join(BACKENDS)})")
    if opts["resume"] and opts["out"] and Path(opts["out"]).resolve() != Path(opts["resume"]).resolve():
        raise UsageError(f"--resume {opts['resume']} writes to that folder: -o {opts['out']} cannot go with it")
    if opts["dashboard"] and not (opts["cluster"] or "").startswith("local:"):
        raise UsageError("--dashboard serves the dashboard of a --cluster local:N only")
    opts["exec"] = execs
    return opts
