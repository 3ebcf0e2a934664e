"""Build the installable extension zip: the code, the canonical scenes (scenes.blend), the
references, and the Python dependencies as bundled wheels.

    .venv/bin/python scripts/build_extension.py [--platform linux-x64] [--no-wheels]
                                                [--references all|none|SCENE,SCENE,...]
                                                [--max-mb 200] [--out dist]

Blender's own Python must never pip-install at run time (the failure users report most against
mitsuba-blender); the extension platform's way is wheels listed in blender_manifest.toml. The
repository's manifest lists none (so it validates as it is); this script stages a copy, downloads
the pinned wheels for one platform from PyPI (Blender 4.2-5.0 run Python 3.11), adds them to the
staged manifest with its ``platforms``, and runs Blender's validator and builder on the copy.
numpy is not bundled: Blender ships its own (scipy 1.17 needs numpy >= 1.26.4).

The zip must stay within the extensions platform's upload limit (``--max-mb``; see README, "In
Blender": the limit is not published in the documentation searched, 200 MB is assumed); the build
fails above it and prints what takes the room, so that ``--references`` can ship a subset (the
rest then comes from the references folder chosen in the extension's preferences).
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
# is not bundled: the panel does not run sweeps. Jinja2 (+ MarkupSafe): the panel writes report.html.
WHEELS = ["jsonschema", "jsonschema-specifications", "referencing", "rpds-py", "attrs", "typing-extensions",
          "mitsuba", "drjit", "OpenEXR", "flip-evaluator", "Pillow", "scipy", "colour-science", "imageio", "plyfile",
          "Jinja2", "MarkupSafe"]
PLATFORMS = {"linux-x64": ["manylinux_2_17_x86_64", "manylinux_2_28_x86_64", "manylinux2014_x86_64"],
             "windows-x64": ["win_amd64"], "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64",
                                                           "macosx_14_0_arm64"]}
IGNORE = shutil.ignore_patterns(".git", ".venv", "__pycache__", "tests", "golden", "benchmarks", "outputs-*",
                                "dist", "build", "*.blend1", ".ci", "wheels", ".pytest_cache")
PLATFORM_LIMIT_MB = 200  # assumed upload limit of extensions.blender.org (see the module docstring)


def pinned_versions():
    pins = {}
    out = subprocess.run([sys.executable, "-m", "pip", "freeze"], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        if "==" in line:
            name, version = line.split("==", 1)
            pins[name.lower().replace("_", "-")] = version
    return pins


def select_references(stage, which):
    """Keep the references named by ``which`` ("all", "none" or "a,b,c") in the staged copy."""
    folder = stage / "references"
    if which == "all" or not folder.is_dir():
        return
    keep = set() if which == "none" else {n.strip() for n in which.split(",") if n.strip()}
    unknown = keep - {p.stem for p in folder.glob("*.exr")}
    if unknown:
        raise SystemExit(f"--references: no reference for {sorted(unknown)} in {ROOT / 'references'}")
    for path in folder.iterdir():
        if path.stem not in keep:
            path.unlink()


def sizes(zip_path):
    """{part: compressed bytes} of a built zip: wheels, references, scenes, code."""
    out = {"wheels": 0, "references": 0, "scenes": 0, "code and data": 0}
    with zipfile.ZipFile(zip_path) as z:
        for info in z.infolist():
            name = info.filename
            part = ("wheels" if "/wheels/" in f"/{name}" else "references" if "/references/" in f"/{name}"
                    else "scenes" if name.endswith(".blend") else "code and data")
            out[part] += info.compress_size
    return out


def build(platform="linux-x64", wheels=True, references="all", out=ROOT / "dist", max_mb=PLATFORM_LIMIT_MB):
    """Build into ``out``; returns the zip's path. Raises SystemExit on a failed check."""
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / "spectral_bench"
        shutil.copytree(ROOT, stage, ignore=IGNORE)
        select_references(stage, references)
        manifest = (stage / "blender_manifest.toml").read_text()
        if wheels:
            pins = pinned_versions()
            specs = [f"{n}=={pins[n.lower()]}" if n.lower() in pins else n for n in WHEELS]
            cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--python-version",
                   "3.11", "-d", str(stage / "wheels")]
            for plat in PLATFORMS[platform]:
                cmd += ["--platform", plat]
            subprocess.run(cmd + specs, check=True)
            names = sorted(p.name for p in (stage / "wheels").glob("*.whl"))
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
    print(f"built {zip_path}: {total / 1e6:.1f} MB ("
          + ", ".join(f"{k} {v / 1e6:.1f} MB" for k, v in parts.items()) + ")")
    if total > max_mb * 1e6:
        raise SystemExit(f"{zip_path.name} is {total / 1e6:.1f} MB, over the {max_mb} MB limit: ship fewer "
                         "references (--references SCENE,...) and point users at a references folder")
    return zip_path


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--platform", default="linux-x64", choices=sorted(PLATFORMS))
    ap.add_argument("--no-wheels", action="store_true",
                    help="build without dependencies (annotations and export still need jsonschema)")
    ap.add_argument("--references", default="all", help="all (default), none, or SCENE,SCENE,... to ship")
    ap.add_argument("--max-mb", type=float, default=PLATFORM_LIMIT_MB, help="fail above this zip size")
    ap.add_argument("--out", default=str(ROOT / "dist"))
    args = ap.parse_args()
    build(args.platform, not args.no_wheels, args.references, args.out, args.max_mb)


if __name__ == "__main__":
    main()
