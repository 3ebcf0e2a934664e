"""Mitsuba 3 plugins of this project, in Python (drjit), for what Mitsuba 3.9.1 lacks natively
(thin-film interference, fluorescence, dispersion).

Each plugin is one standalone module in this folder that imports only mitsuba, drjit and numpy,
so the Mitsuba writer copies it verbatim into an exported scene folder (``plugins/``) next to a
``load_plugins.py`` that registers it: the exported folder loads anywhere Mitsuba 3 is installed,
and the backend renders through exactly that route. A plugin module defines

    PLUGIN_NAME = "sb_..."          # the type attribute in scene.xml
    def register(): ...             # mi.register_bsdf / mi.register_integrator; after mi.set_variant

``MODULES`` maps each XML plugin name to its module's file stem.
"""
import importlib.util
import shutil
from pathlib import Path

HERE = Path(__file__).resolve().parent
MODULES = {  # {"sb_<name>": "<module file stem>"}: one entry per plugin
    "sb_thin_film_conductor": "thin_film_conductor",  # conductor under a dielectric film (Airy)
    "sb_dispersive_dielectric": "dispersive_dielectric",  # dielectric with n(lambda)
    "sb_fluorescent_diffuse": "fluorescent_diffuse",  # Lambertian + re-radiation table (fluorescence)
    "sb_fluorescent_path": "fluorescent_path",  # path tracer that re-radiates at those surfaces
}

LOADER = '''"""Registers this scene's Python plugins with Mitsuba 3 (written by spectral_bench).

In Python, after choosing a variant:
    import mitsuba as mi; mi.set_variant("{variant_hint}")
    import sys; sys.path.insert(0, "<this folder>"); import load_plugins; load_plugins.register()
    scene = mi.load_file("<this folder>/scene.xml")
From a shell: python load_plugins.py VARIANT [SPP]   renders scene.xml to scene.exr.
The plugins are {names}; the mitsuba executable cannot load Python plugins.
"""
import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def register():
    for path in sorted((HERE / "plugins").glob("*.py")):
        spec = importlib.util.spec_from_file_location(f"spectral_bench_plugin_{{path.stem}}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        module.register()


if __name__ == "__main__":
    import mitsuba as mi
    mi.set_variant(sys.argv[1] if len(sys.argv) > 1 else "{variant_hint}")
    register()
    scene = mi.load_file(str(HERE / "scene.xml"))
    image = mi.render(scene, spp=int(sys.argv[2]) if len(sys.argv) > 2 else 0)  # 0: the scene's own
    mi.util.write_bitmap(str(HERE / "scene.exr"), image)
'''


def module_path(plugin_name):
    if plugin_name not in MODULES:
        raise KeyError(f"no Mitsuba plugin {plugin_name!r} in this project (known: {', '.join(MODULES) or 'none'})")
    return HERE / f"{MODULES[plugin_name]}.py"


def load(plugin_name):
    """The plugin's module, imported from its file."""
    path = module_path(plugin_name)
    spec = importlib.util.spec_from_file_location(f"spectral_bench_plugin_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def register(plugin_names=None):
    """Register the named plugins (default: all) with Mitsuba; call after mi.set_variant."""
    for name in sorted(plugin_names or MODULES):
        load(name).register()


def write_into(out_dir, plugin_names, variant_hint="llvm_ad_spectral"):
    """Copy the plugins a scene uses into ``out_dir/plugins`` and write ``out_dir/load_plugins.py``."""
    out = Path(out_dir)
    (out / "plugins").mkdir(parents=True, exist_ok=True)
    for name in sorted(plugin_names):
        shutil.copyfile(module_path(name), out / "plugins" / module_path(name).name)
    (out / "load_plugins.py").write_text(LOADER.format(variant_hint=variant_hint, names=", ".join(sorted(plugin_names))))
    return out / "load_plugins.py"


def register_exported(scene_dir):
    """Register the plugins an exported scene folder carries (no-op without load_plugins.py)."""
    loader = Path(scene_dir) / "load_plugins.py"
    if not loader.is_file():
        return False
    spec = importlib.util.spec_from_file_location("spectral_bench_load_plugins", loader)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.register()
    return True
