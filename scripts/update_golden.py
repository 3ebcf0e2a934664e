"""Regenerate golden/ir/<scene>.json from scenes.blend (an explicit request; review the diff).

    .venv/bin/python scripts/update_golden.py
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402


def main():
    pkg = pkg_bootstrap.package()
    from spectral_bench.batch import blend_input
    from spectral_bench.exporters import ir_json
    out = pkg_bootstrap.ROOT / "golden" / "ir"
    for name, result in blend_input.load_blend(pkg_bootstrap.ROOT / "scenes.blend"):
        if isinstance(result, Exception):
            raise SystemExit(f"{name}: {result}")
        print("wrote", ir_json.write(result, out / f"{name}.json"))


if __name__ == "__main__":
    main()
