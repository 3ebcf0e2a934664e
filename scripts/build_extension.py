"""Build the installable extension zip, with its Python dependencies as bundled wheels.

    .venv/bin/python scripts/build_extension.py [--platform linux-x64] [--no-wheels] [--out dist]

Blender's own Python must never pip-install at run time (the failure users report most against
mitsuba-blender); the extension platform's way is wheels listed in blender_manifest.toml. The
repository's manifest lists none (so it validates as it is); this script stages a copy, downloads
the pinned wheels for one platform from PyPI (Blender 4.2-5.0 run Python 3.11), adds them to the
staged manifest with its ``platforms``, and runs Blender's validator and builder on the copy.
numpy is not bundled: Blender ships its own.
"""
import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# name==version as in requirements.txt, plus jsonschema's own dependencies (pinned to what pip
# resolved for requirements.txt)
WHEELS = ["jsonschema", "jsonschema-specifications", "referencing", "rpds-py", "attrs", "typing-extensions",
          "mitsuba", "drjit", "OpenEXR", "flip-evaluator", "Pillow"]
PLATFORMS = {"linux-x64": ["manylinux_2_17_x86_64", "manylinux_2_28_x86_64", "manylinux2014_x86_64"],
             "windows-x64": ["win_amd64"], "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64"]}
IGNORE = shutil.ignore_patterns(".git", ".venv", "__pycache__", "tests", "references", "golden", "benchmarks",
                                "outputs-*", "dist", "scenes.blend", "*.blend1", ".ci", "wheels")


def pinned_versions():
    pins = {}
    out = subprocess.run([sys.executable, "-m", "pip", "freeze"], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        if "==" in line:
            name, version = line.split("==", 1)
            pins[name.lower().replace("_", "-")] = version
    return pins


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--platform", default="linux-x64", choices=sorted(PLATFORMS))
    ap.add_argument("--no-wheels", action="store_true", help="build without dependencies (annotations and export still need jsonschema)")
    ap.add_argument("--out", default=str(ROOT / "dist"))
    args = ap.parse_args()
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp) / "spectral_bench"
        shutil.copytree(ROOT, stage, ignore=IGNORE)
        manifest = (stage / "blender_manifest.toml").read_text()
        if not args.no_wheels:
            pins = pinned_versions()
            specs = [f"{n}=={pins[n.lower()]}" if n.lower() in pins else n for n in WHEELS]
            cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--python-version", "3.11",
                   "-d", str(stage / "wheels")]
            for plat in PLATFORMS[args.platform]:
                cmd += ["--platform", plat]
            subprocess.run(cmd + specs, check=True)
            wheels = sorted(p.name for p in (stage / "wheels").glob("*.whl"))
            listing = ",\n".join(f'  "./wheels/{w}"' for w in wheels)
            manifest = re.sub(r'(blender_version_min = "[^"]+"\n)',
                              rf'\1\nplatforms = ["{args.platform}"]\nwheels = [\n{listing},\n]\n', manifest)
            manifest = manifest.replace('  "/wheels/",\n', "")
        (stage / "blender_manifest.toml").write_text(manifest)
        import bpy  # noqa: F401  - Blender's extension tooling lives in the bpy module
        from bl_pkg import bl_extension_cli
        if bl_extension_cli.cli_extension_handler(["validate", str(stage)]) != 0:
            raise SystemExit("the staged extension does not validate")
        if bl_extension_cli.cli_extension_handler(["build", "--source-dir", str(stage), "--output-dir", str(out)]) != 0:
            raise SystemExit("build failed")
    print("built into", out)


if __name__ == "__main__":
    main()
