"""Command line of the batch runner (the thesis' CLI, section 3.4, plus sampling options).

Identical under ``blender -b scenes.blend -P batch/run.py -- [options]`` and
``python batch/run.py [options]``: everything after ``--`` is ours; without ``--`` everything
after the script is. Every option can also come from a settings file (TOML or JSON, keys are
the long option names with ``_``); options given on the command line win.
"""
import argparse
import json
import tomllib
from pathlib import Path

from .backends import BACKENDS, DEFAULT, GROUPS

FORMATS = ("mitsuba", "art", "json", "cycles", "luxcore")

DEFAULTS = {
    "input": None, "case": None, "scene": None, "renderer": None, "exec": None, "spp": None, "scale": 1.0,
    "out": None, "export_only": False, "format": None, "log": None, "visualize": False, "settings": None,
    "variant": None, "alpha": 0.01, "block": None, "min_samples": 65536, "timeout": 1800, "passes": 2, "seed": 0, "flip": True,
    "references": None, "known": None, "list": False, "art_ggx": False, "sweep": False, "ladder": None, "sweep_modes": None, "stability": False,
    "approximate": False, "cluster": None, "resume": None,
}


def split_argv(argv):
    """Our arguments from a full sys.argv, Blender-style (after '--') or plain Python."""
    argv = list(argv)
    if "--" in argv:
        return argv[argv.index("--") + 1:]
    return argv[1:]


def parser():
    ap = argparse.ArgumentParser(
        prog="batch/run.py",
        description="Export, render and compare the spectral benchmark scenes.",
        epilog="Under Blender: blender -b scenes.blend -P batch/run.py -- [options]",
        argument_default=argparse.SUPPRESS)
    ap.add_argument("-i", "--input", nargs="+", metavar="PATH",
                    help="scenes.blend (default) or one or more scene IR JSON files")
    ap.add_argument("-c", "--case", action="append", metavar="NAME", help="only scenes of this case (repeatable)")
    ap.add_argument("-s", "--scene", action="append", metavar="NAME", help="only this scene (repeatable)")
    ap.add_argument("-r", "--renderer", action="append", metavar="NAME",
                    help=f"backend or group (repeatable): {', '.join(BACKENDS)}; groups "
                         f"{', '.join(f'{g} ({chr(43).join(m)})' for g, m in GROUPS.items())}; default: {', '.join(DEFAULT)}")
    ap.add_argument("-e", "--exec", action="append", metavar="[BACKEND=]PATH",
                    help="renderer executable, e.g. mitsuba=/opt/mitsuba/mitsuba")
    ap.add_argument("--spp", type=int, metavar="N", help="samples per pixel (default: each scene's own)")
    ap.add_argument("--scale", type=float, metavar="F", help="resolution scale (default 1.0)")
    ap.add_argument("-o", "--out", metavar="DIR", help="output folder (default: outputs-YYYYmmdd-HHMMSS)")
    ap.add_argument("--export-only", action="store_true", help="export scenes, render nothing")
    ap.add_argument("--format", action="append", choices=FORMATS,
                    help="export format for --export-only (repeatable; default: mitsuba, art, json; "
                         "cycles writes a .blend, luxcore its .scn/.cfg)")
    ap.add_argument("-l", "--log", metavar="FILE", help="also write the log to FILE")
    ap.add_argument("-v", "--visualize", action="store_true", help="open the results when done")
    ap.add_argument("--settings", metavar="FILE", help="settings file (TOML or JSON)")
    ap.add_argument("--variant", help="force a Mitsuba variant (default: cheapest that models the scene)")
    ap.add_argument("--alpha", type=float, help="significance level of the noise test (default 0.01)")
    ap.add_argument("--block", type=int, help="block side in pixels of the noise test (default: from --min-samples)")
    ap.add_argument("--min-samples", type=int, help="samples pooled per block of the noise test (default 65536)")
    ap.add_argument("--timeout", type=float, help="seconds per render before it is stopped (default 1800)")
    ap.add_argument("--passes", type=int,
                    help="independent passes per render: its own per-pixel noise for the verdict (default 2; "
                         "with 1, only the reference's own backend is judged against the reference)")
    ap.add_argument("--seed", type=int, help="first sampler seed (default 0)")
    ap.add_argument("--no-flip", dest="flip", action="store_false", help="skip HDR-FLIP")
    ap.add_argument("--references", action="append", metavar="DIR",
                    help="reference folder (repeatable: for each scene the first folder holding a usable "
                         "reference wins; default: references/)")
    ap.add_argument("--known", metavar="FILE", help="known deviations (default: known_deviations.toml)")
    ap.add_argument("--list", action="store_true", help="list the jobs and exit")
    ap.add_argument("--cluster", metavar="ADDRESS",
                    help="run the jobs on a Dask scheduler at ADDRESS (tcp://host:8786), or 'local:N' for a "
                         "LocalCluster of N workers (default: this machine, no extra service)")
    ap.add_argument("--resume", metavar="OUT",
                    help="finish the interrupted run in OUT with its own options: finished jobs are kept, the rest run")
    ap.add_argument("--sweep", action="store_true",
                    help="also render each scene over a ladder of sample counts and chart error against time")
    ap.add_argument("--ladder", type=lambda t: [int(x) for x in t.split(",")], metavar="N,N,...",
                    help="sample counts of the sweep (default 4,16,64,256)")
    ap.add_argument("--sweep-modes", type=lambda t: t.split(","), metavar="MODE,...",
                    help="backend modes to sweep (e.g. llvm_ad_spectral,scalar_spectral,llvm_ad_rgb)")
    ap.add_argument("--stability", action="store_true",
                    help="also run the stability case (grazing GGX, roughness and IOR furnaces, Malus)")
    ap.add_argument("--approximate", action="store_true",
                    help="RGB backends (cycles, luxcore): render what they cannot express (polariser, Stokes output, "
                         "a missing microfacet distribution) as an explicitly labelled approximation (mode rgb-approx) "
                         "instead of reporting it unsupported")
    ap.add_argument("--art-ggx", action="store_true",
                    help="write GGX_MICROFACET_DISTRIBUTION_CONST for an ART build that has GGX (upstream has Blinn only)")
    return ap


class SettingsError(ValueError):
    pass


def load_settings(path):
    path = Path(path)
    try:
        text = path.read_text()
        data = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (OSError, ValueError) as exc:
        raise SettingsError(f"settings file {path}: {exc}") from exc
    data = {k.replace("-", "_"): v for k, v in data.items()}
    unknown = sorted(set(data) - set(DEFAULTS))
    if unknown:
        raise SettingsError(f"settings file {path}: unknown keys {unknown} (known: {sorted(DEFAULTS)})")
    for key in ("input", "case", "scene", "renderer", "exec", "format", "references"):
        if isinstance(data.get(key), str):
            data[key] = [data[key]]
    return data


def parse(args):
    """Options dict: defaults < settings file < command line."""
    cli = vars(parser().parse_args(args))
    opts = dict(DEFAULTS)
    if cli.get("settings"):
        opts.update(load_settings(cli["settings"]))
    opts.update(cli)
    execs = {}
    for item in opts["exec"] or []:
        name, _, path = item.rpartition("=")
        execs[name or "*"] = path
    opts["exec"] = execs
    return opts
