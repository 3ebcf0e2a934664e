"""Registers this scene's Python plugins with Mitsuba 3 (written by spectral_bench).

In Python, after choosing a variant:
    import mitsuba as mi; mi.set_variant("llvm_ad_spectral")
    import sys; sys.path.insert(0, "<this folder>"); import load_plugins; load_plugins.register()
    scene = mi.load_file("<this folder>/scene.xml")
From a shell: python load_plugins.py VARIANT [SPP]   renders scene.xml to scene.exr.
The plugins are sb_fluorescent_diffuse, sb_fluorescent_path; the mitsuba executable cannot load Python plugins.
"""
import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def register():
    for path in sorted((HERE / "plugins").glob("*.py")):
        spec = importlib.util.spec_from_file_location(f"spectral_bench_plugin_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        module.register()


if __name__ == "__main__":
    import mitsuba as mi
    mi.set_variant(sys.argv[1] if len(sys.argv) > 1 else "llvm_ad_spectral")
    register()
    scene = mi.load_file(str(HERE / "scene.xml"))
    image = mi.render(scene, spp=int(sys.argv[2]) if len(sys.argv) > 2 else 0)  # 0: the scene's own
    mi.util.write_bitmap(str(HERE / "scene.exr"), image)
