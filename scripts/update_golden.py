"""Regenerate golden/ir/<scene>.json from scenes.blend, and golden/mitsuba/<scene>/,
golden/art/<scene>/ and golden/pbrt/<scene>/ from those (an explicit request; review the diff).

    .venv/bin/python scripts/update_golden.py
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402


def main():
    pkg_bootstrap.package()
    from spectral_bench.batch import blend_input
    import shutil
    from spectral_bench.exporters import art_writer, ir_json, mitsuba_writer, pbrt_writer
    golden = pkg_bootstrap.ROOT / "golden"
    for name, result in blend_input.load_blend(pkg_bootstrap.ROOT / "scenes.blend"):
        if isinstance(result, Exception):
            raise SystemExit(f"{name}: {result}")
        print("wrote", ir_json.write(result, golden / "ir" / f"{name}.json"))
        shutil.rmtree(golden / "mitsuba" / name, ignore_errors=True)
        print("wrote", mitsuba_writer.write(result, golden / "mitsuba" / name))
        # the plugins an export carries and their loader come from exporters/mitsuba_plugins (the
        # test checks them against it), so they are not stored again per scene
        shutil.rmtree(golden / "mitsuba" / name / "plugins", ignore_errors=True)
        (golden / "mitsuba" / name / "load_plugins.py").unlink(missing_ok=True)
        shutil.rmtree(golden / "art" / name, ignore_errors=True)
        print("wrote", art_writer.write(result, golden / "art" / name)[0])
        shutil.rmtree(golden / "pbrt" / name, ignore_errors=True)
        print("wrote", pbrt_writer.write(result, golden / "pbrt" / name))


if __name__ == "__main__":
    main()
