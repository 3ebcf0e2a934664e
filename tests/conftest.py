import copy
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
GOLDEN = ROOT / "golden" / "ir"
REFLECTANCE = ["ggx_copper_50", "ggx_copper_60", "ggx_copper_70", "ggx_copper_80", "ggx_glass"]
SPECTRAL_ACCURACY = ["macbeth_chart_D50", "macbeth_chart_D65"]
POLARIZATION = ["polarizing_plane_0", "polarizing_plane_90", "polarizing_spheres"]
FLUORESCENCE = ["fluorescent_sphere_D50_red", "fluorescent_sphere_lone", "fluorescent_sphere_mono_invisible",
                "fluorescent_sphere_mono_red", "yellow_sphere_F8"]
ALL_SCENES = sorted(REFLECTANCE + SPECTRAL_ACCURACY + POLARIZATION + FLUORESCENCE)


@pytest.fixture(scope="session")
def golden():
    from spectral_bench.exporters import ir_json
    return {p.stem: ir_json.load(p) for p in sorted(GOLDEN.glob("*.json"))}


def run_batch(*args, timeout=900):
    """The real command line, in a child process, as a user runs it."""
    proc = subprocess.run([sys.executable, str(ROOT / "batch" / "run.py"), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    return proc


def metrics(out):
    return json.loads((Path(out) / "metrics.json").read_text())


def write_scene(tmp_path, scene, name=None):
    from spectral_bench.exporters import ir_json
    sc = copy.deepcopy(scene)
    if name:
        sc["name"] = name
    return ir_json.write(sc, tmp_path / f"{sc['name']}.json")


def render(scene, tmp_path, spp, size=None):
    """Render an IR scene with the Mitsuba backend; returns (channel names, image)."""
    from spectral_bench.batch import backends, exr
    from spectral_bench.exporters import ir
    sc = copy.deepcopy(scene)
    if size:
        sc["render"]["width"], sc["render"]["height"] = size
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    backend = backends.get("mitsuba")
    xml = backend.export(sc, Path(tmp_path) / "mitsuba")
    backend.render(xml, backend.mode_for(sc)[0], spp, Path(tmp_path) / "render.exr")
    return sc, *exr.read_image(Path(tmp_path) / "render.exr")


def run_bpy(body, timeout=600, env=None):
    """Run ``body`` in a child Python with bpy, scenes.blend open and the extension registered
    (bpy has one global state per process); returns the JSON its last printed line holds."""
    import os
    import textwrap
    code = textwrap.dedent(f"""
        import json, sys
        sys.path.insert(0, {str(ROOT)!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        import bpy
        from spectral_bench.batch import blend_input
        blend_input.load_blend({str(ROOT / 'scenes.blend')!r})
    """) + textwrap.dedent(body)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ, **(env or {})))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])
