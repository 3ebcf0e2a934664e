"""Build the installable extension zip: the code, the canonical scenes (scenes.blend), the
references of a default subset of the scenes, and the Python dependencies as bundled wheels; beside it
a zip of every reference, for the references folder chosen in the extension's preferences.

    .venv/bin/python scripts/build_extension.py [--platform linux-x64] [--no-wheels]
                                                [--references default|all|none|SCENE,SCENE,...]
                                                [--max-mb 170] [--out dist] [--no-readme]

Blender's own Python must never pip-install at run time (the failure users report most against
mitsuba-blender); the extension platform's way is wheels listed in blender_manifest.toml. The
repository's manifest lists none (so it validates as it is); this script stages a copy, downloads
the pinned wheels for one platform from PyPI (Blender 4.2-5.0 run Python 3.11) into
``build/wheels/<platform>`` (kept between builds: a rebuild downloads nothing), adds them to the
staged manifest with its ``platforms``, and runs Blender's validator and builder on the copy.
numpy is not bundled: Blender ships its own (scipy 1.17 needs numpy >= 1.26.4).

Where the room goes (linux-x64, measured): the wheels take 116 MB (mitsuba 63 MB and scipy 35 MB,
both imported at run time: scipy by the verdict's statistics and by colour-science; zip archives
already, they do not compress further), every reference 79 MB and their observer layers 38 MB (EXRs already ZIP-compressed inside:
deflating them again gains 0 %; a stronger lossless EXR codec such as HTJ2K needs OpenEXR 3.4, which
Blender 4.2's own image reader predates). So the extension ships the references of
``DEFAULT_REFERENCES`` (every case represented, 41 MB with Mitsuba's film's observer layers,
``EXTENSION_LAYERS``) and the build writes every reference with every layer into
``spectral_bench_references-<version>.zip`` beside it: unzipped, it is the references folder of the
extension's preferences ("Folder, Then Extension").

The zip must stay within the extensions platform's upload limit (200 MB assumed: the limit is not
published in the documentation searched; see docs/blender.md, "Install") with margin: the build fails above
``--max-mb`` (default 170) and prints what takes the room. The documented build (wheels, default
references) records its measured size in README.md, between ``<!-- extension-size -->`` and
``<!-- /extension-size -->``, one line per platform (``--no-readme``: leave README.md alone).
"""
import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# name==version as in requirements.txt, plus the dependencies of each (pinned to what pip resolved for
# requirements.txt): what the batch runner imports in Blender's Python (jsonschema: IR validation;
# mitsuba, drjit: the Mitsuba backend; OpenEXR; flip-evaluator; Pillow: previews; scipy: verdict
# statistics; colour-science (+ imageio): CIELAB/CIEDE2000 of the probes). matplotlib (sweep charts)
# is not bundled: the panel does not run sweeps. Jinja2 (+ MarkupSafe): the panel writes report.html;
# filelock: a run claims its output folder.
WHEELS = ["jsonschema", "jsonschema-specifications", "referencing", "rpds-py", "attrs", "typing-extensions",
          "mitsuba", "drjit", "OpenEXR", "flip-evaluator", "Pillow", "scipy", "colour-science", "imageio", "plyfile",
          "Jinja2", "MarkupSafe", "filelock"]
PLATFORMS = {"linux-x64": ["manylinux_2_17_x86_64", "manylinux_2_28_x86_64", "manylinux2014_x86_64"],
             "windows-x64": ["win_amd64"], "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64",
                                                           "macosx_14_0_arm64"]}
_IGNORE_NAMES = shutil.ignore_patterns(".git", ".venv", "__pycache__", "tests", "golden", "benchmarks", "outputs-*",
                                       "dist", "build", "*.blend1", ".ci", "wheels", ".pytest_cache", ".work", ".hypothesis",
                                       ".lock", "pytest.ini")


def IGNORE(folder, names):
    """What copytree leaves out: the patterns above anywhere, and references/history/ (the replaced
    references batch/make_references.py keeps: never shipped, never a current reference)."""
    left_out = set(_IGNORE_NAMES(folder, names))
    if Path(folder).resolve() == (ROOT / "references").resolve() and "history" in names:
        left_out.add("history")
    return left_out
PLATFORM_LIMIT_MB = 200  # assumed upload limit of extensions.blender.org (see the module docstring)
SIZE_TARGET_MB = 170     # the default --max-mb: margin under that limit (wheels differ between builds)
# the references the extension ships by default: one scene or more of every case (the smaller
# variants of each family); the rest comes from the references zip written beside the extension
DEFAULT_REFERENCES = [
    "beckmann_glass", "ggx_glass", "ggx_copper_50", "ggx_copper_50_isolated", "ggx_copper_60",
    "ggx_copper_60_isolated", "ggx_copper_grazing",                      # reflectance
    "dispersion_fringes", "dispersion_prism",                            # dispersion
    "fluorescent_sphere_lone", "yellow_sphere_F8",                       # fluorescence
    "iridescent_sphere_smooth", "iridescent_spheres_film",               # iridescence
    "macbeth_chart_D65",                                                 # spectral accuracy
    "polarizing_plane_0", "polarizing_plane_90",                         # polarization
    "furnace_colorchecker_yellow", "furnace_spiky",                      # furnace (64 x 64: 240 kB)
    "coated_sphere",                                                     # coated (256 x 256: 1.1 MB)
]
# the observer layers the extension carries: Mitsuba's film (the renderer Blender users run here);
# ART's (art46, 10 MB more) are in the all-references zip
EXTENSION_LAYERS = ("mitsuba3",)
# where a reference's observer layers are (batch/verdict/observer_layers.py FOLDER and NAME: this
# script runs without the package): <references>/layers/<scene>/<observer>.exr
LAYER_FOLDER = "layers"
LAYER_NAME = re.compile(r"[a-z][a-z0-9]{0,31}")
WHEEL_CACHE = ROOT / "build" / "wheels"
README = ROOT / "README.md"
README_BLOCK = re.compile(r"(<!-- extension-size -->\n)(.*?)(<!-- /extension-size -->)", re.S)


def pinned_versions():
    pins = {}
    out = subprocess.run([sys.executable, "-m", "pip", "freeze"], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        if "==" in line:
            name, version = line.split("==", 1)
            pins[name.lower().replace("_", "-")] = version
    return pins


def select_references(stage, which):
    """Keep the references named by ``which`` ("default", "all", "none" or "a,b,c") in the staged
    copy; returns (shipped, all) scene names."""
    folder = stage / "references"
    # a reference is <scene>.exr + <scene>.json (a scene name may hold dots), with its observer layers
    # in layers/<scene>/<observer>.exr (batch/verdict/observer_layers.py) if it has them
    every = sorted(p.stem for p in folder.glob("*.exr")) if folder.is_dir() else []
    if which == "all" or not folder.is_dir():
        return every, every
    keep = (set() if which == "none" else set(DEFAULT_REFERENCES) if which == "default"
            else {n.strip() for n in which.split(",") if n.strip()})
    unknown = keep - set(every)
    if unknown:
        raise SystemExit(f"--references: no reference for {sorted(unknown)} in {ROOT / 'references'}")
    for path in folder.iterdir():
        if path.is_file() and path.suffix in (".exr", ".json") and path.stem not in keep:
            path.unlink()
    layers = folder / LAYER_FOLDER
    for path in sorted(layers.iterdir()) if layers.is_dir() else []:
        if path.name not in keep:
            shutil.rmtree(path)
    drop_layers(folder, EXTENSION_LAYERS)
    return sorted(keep), every


def drop_layers(folder, keep):
    """Leave only the observer layers of ``keep`` in a staged references folder: their files and
    their entries in each record (the reference's image and its sha256 are untouched)."""
    import json
    for meta_path in folder.glob("*.json"):
        meta = json.loads(meta_path.read_text())
        layers = meta.get("observer_layers")
        if not isinstance(layers, dict):
            continue
        for obs in [o for o in layers if o not in keep]:
            del layers[obs]
            if LAYER_NAME.fullmatch(str(obs)):  # a record's key names a file only when it is an observer's name
                (folder / LAYER_FOLDER / meta_path.stem / f"{obs}.exr").unlink(missing_ok=True)
        meta_path.write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")


def download_wheels(platform, dest, cache=WHEEL_CACHE):
    """The pinned WHEELS for ``platform``, downloaded into ``cache``/<platform> (pip skips those
    already there) and copied into ``dest``; returns their file names."""
    from packaging.utils import canonicalize_name, parse_wheel_filename
    pins = pinned_versions()
    specs = [f"{n}=={pins[n.lower()]}" if n.lower() in pins else n for n in WHEELS]
    folder = Path(cache) / platform
    folder.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--python-version",
           "3.11", "-d", str(folder)]
    for plat in PLATFORMS[platform]:
        cmd += ["--platform", plat]
    subprocess.run(cmd + specs, check=True)
    wanted = {canonicalize_name(n): pins.get(n.lower()) for n in WHEELS}
    chosen = {}
    for path in sorted(folder.glob("*.whl")):
        name, version, _build, _tags = parse_wheel_filename(path.name)
        if name in wanted and (wanted[name] is None or str(version) == wanted[name]):
            chosen.setdefault(name, path)  # one wheel per package (the cache may hold older pins)
    missing = sorted(set(wanted) - set(chosen))
    if missing:
        raise SystemExit(f"no wheel for {missing} in {folder}")
    dest.mkdir(parents=True, exist_ok=True)
    for path in chosen.values():
        shutil.copy2(path, dest / path.name)
    return sorted(p.name for p in chosen.values())


def write_references_zip(out, version, names):
    """Every reference (EXR, record and every observer layer) of ``names`` into
    out/spectral_bench_references-<version>.zip, under a folder spectral_bench_references/ (the EXRs
    are compressed already: stored as they are)."""
    path = out / f"spectral_bench_references-{version}.zip"
    tmp = path.with_suffix(".zip.part")
    folder = ROOT / "references"
    with zipfile.ZipFile(tmp, "w") as z:
        for name in names:
            layers = folder / LAYER_FOLDER / name
            files = [folder / f"{name}.json", folder / f"{name}.exr",
                     *(sorted(layers.glob("*.exr")) if layers.is_dir() else [])]
            for source in files:
                if source.is_file():
                    how = zipfile.ZIP_DEFLATED if source.suffix == ".json" else zipfile.ZIP_STORED
                    z.write(source, f"spectral_bench_references/{source.relative_to(folder).as_posix()}",
                            compress_type=how)
    tmp.replace(path)
    return path


def record_size(platform, line, readme=README):
    """Put ``line`` as the platform's line of README.md's extension-size block."""
    text = readme.read_text()
    found = README_BLOCK.search(text)
    if found is None:
        print(f"warning: no <!-- extension-size --> block in {readme}: size not recorded")
        return False
    lines = [ln for ln in found.group(2).splitlines() if ln.strip()]
    head = [ln for ln in lines if not ln.startswith("- ")]
    rows = {ln.split(":", 1)[0]: ln for ln in lines if ln.startswith("- ")}
    rows[f"- {platform}"] = f"- {platform}: {line}"
    body = "\n".join(head + [rows[k] for k in sorted(rows)]) + "\n"
    readme.write_text(text[:found.start(2)] + body + text[found.end(2):])
    return True


def sizes(zip_path):
    """{part: compressed bytes} of a built zip: wheels, references, scenes, code and data."""
    out = {"wheels": 0, "references": 0, "scenes": 0, "code and data": 0}
    with zipfile.ZipFile(zip_path) as z:
        for info in z.infolist():
            name = info.filename
            part = ("wheels" if "/wheels/" in f"/{name}" else "references" if "/references/" in f"/{name}"
                    else "scenes" if name.endswith(".blend") else "code and data")
            out[part] += info.compress_size
    return out


def build(platform="linux-x64", wheels=True, references="default", out=ROOT / "dist", max_mb=SIZE_TARGET_MB,
          readme=True):
    """Build into ``out``; returns the zip's path. Raises SystemExit on a failed check."""
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / "spectral_bench"
        shutil.copytree(ROOT, stage, ignore=IGNORE)
        shipped, every = select_references(stage, references)
        manifest = (stage / "blender_manifest.toml").read_text()
        version = re.search(r'^version = "([^"]+)"', manifest, re.M).group(1)
        if wheels:
            names = download_wheels(platform, stage / "wheels")
            listing = ",\n".join(f'  "./wheels/{w}"' for w in names)
            manifest = re.sub(r'(blender_version_min = "[^"]+"\n)',
                              rf'\1\nplatforms = ["{platform}"]\nwheels = [\n{listing},\n]\n', manifest)
            manifest = manifest.replace('  "/wheels/",\n', "")
        (stage / "blender_manifest.toml").write_text(manifest)
        import bpy  # noqa: F401  - Blender's extension tooling lives in the bpy module
        from bl_pkg import bl_extension_cli
        if bl_extension_cli.cli_extension_handler(["validate", str(stage)]) != 0:
            raise SystemExit("the staged extension does not validate")
        for old in out.glob("spectral_bench-*.zip"):
            old.unlink()
        if bl_extension_cli.cli_extension_handler(["build", "--source-dir", str(stage), "--output-dir", str(out)]) != 0:
            raise SystemExit("build failed")
    (zip_path,) = out.glob("spectral_bench-*.zip")
    parts = sizes(zip_path)
    total = zip_path.stat().st_size
    summary = (f"{total / 1e6:.1f} MB: wheels {parts['wheels'] / 1e6:.1f} MB, references "
               f"{parts['references'] / 1e6:.1f} MB ({len(shipped)} of {len(every)} scenes), scenes "
               f"{parts['scenes'] / 1e6:.1f} MB, code and data {parts['code and data'] / 1e6:.1f} MB")
    print(f"built {zip_path}: {summary}")
    if set(shipped) != set(every):
        refs = write_references_zip(out, version, every)
        print(f"every reference ({len(every)} scenes): {refs} ({refs.stat().st_size / 1e6:.1f} MB)")
    if total > max_mb * 1e6:
        raise SystemExit(f"{zip_path.name} is {total / 1e6:.1f} MB, over the {max_mb:g} MB limit: ship fewer "
                         "references (--references SCENE,...) and point users at a references folder")
    if readme and wheels and references == "default":
        record_size(platform, summary)
    return zip_path


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--platform", default="linux-x64", choices=sorted(PLATFORMS))
    ap.add_argument("--no-wheels", action="store_true",
                    help="build without dependencies (annotations and export still need jsonschema)")
    ap.add_argument("--references", default="default",
                    help="default (DEFAULT_REFERENCES), all, none, or SCENE,SCENE,... to ship in the extension")
    ap.add_argument("--max-mb", type=float, default=SIZE_TARGET_MB,
                    help=f"fail above this zip size (default {SIZE_TARGET_MB}: margin under the platform's "
                         f"{PLATFORM_LIMIT_MB} MB)")
    ap.add_argument("--out", default=str(ROOT / "dist"))
    ap.add_argument("--no-readme", action="store_true",
                    help="do not record the measured size in README.md (the documented build records it)")
    args = ap.parse_args()
    build(args.platform, not args.no_wheels, args.references, args.out, args.max_mb, not args.no_readme)


if __name__ == "__main__":
    main()
