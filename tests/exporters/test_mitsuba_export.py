"""Exported Mitsuba folders load in Mitsuba unchanged and render; the radiometry follows the IR."""
import copy
import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from conftest import ALL_SCENES, metrics, run_batch, write_scene
from spectral_bench.batch import exr
from spectral_bench.batch.backends.mitsuba import llvm
from spectral_bench.exporters import ir, mitsuba_writer


def mitsuba(code, timeout=300):
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=llvm.env())
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout.strip().splitlines()[-1]


def variant_for(scene):
    """The Mitsuba variant an export is loaded in: polarised where the scene needs it, LLVM where
    it carries Python plugins (a scalar variant calls a Python plugin per ray)."""
    variant = "scalar_spectral_polarized" if "polarization" in scene["needs"] else "scalar_spectral"
    if {"thin_film", "dispersion", "fluorescence"} & set(scene["needs"]):
        variant = variant.replace("scalar_", "llvm_ad_")
    return variant


# One Mitsuba child loads and renders a share of the exports (one Python start and Mitsuba import
# for several scenes, not one each). Each scene: its variant, its folder's own load_plugins.py
# (imported from its path, under a name of its own), mi.load_file, one sample per pixel; an error
# is that scene's result, so the other scenes still load.
LOAD_EXPORTS = """
import importlib.util, json, pathlib, sys, traceback
import mitsuba as mi, numpy as np
results = {}
for name, variant, xml in json.loads(sys.argv[1]):
    try:
        mi.set_variant(variant)
        loader = pathlib.Path(xml).parent / "load_plugins.py"
        if loader.exists():  # the exported folder's own plugin loader
            spec = importlib.util.spec_from_file_location(f"load_plugins_of_{name}", loader)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            module.register()
        img = np.array(mi.render(mi.load_file(xml), spp=1))
        results[name] = {"shape": list(img.shape[:2]), "lit": float(img[..., :3].mean()) > 0,
                         "finite": bool(np.isfinite(img).all())}
    except Exception:
        results[name] = {"error": traceback.format_exc()[-3000:]}
pathlib.Path(sys.argv[2]).write_text(json.dumps(results))
"""


@pytest.fixture(scope="module")
def loaded_exports(golden, tmp_path_factory):
    """{scene: its export's result in Mitsuba} for every golden scene. Python plugins register
    into one registry per process, so that a scene whose loader missed a plugin cannot borrow it
    from an earlier scene, the scenes that carry plugins are dealt out: no child gets two scenes
    that carry the same plugin (4 children for the golden scenes: 4 fluorescent, 4 iridescent)."""
    from spectral_bench.exporters import mitsuba_plugins
    tmp = tmp_path_factory.mktemp("exports")
    shares = []  # [(plugins registered in that child, [(scene, variant, scene.xml)])]
    for name in ALL_SCENES:
        xml = mitsuba_writer.write(golden[name], tmp / name)
        plugins = {p.stem for p in (tmp / name / "plugins").glob("*.py")}
        assert plugins <= set(mitsuba_plugins.MODULES.values()), plugins
        share = next((s for s in shares if not plugins & s[0]), None)
        if share is None:
            share = (set(), [])
            shares.append(share)
        share[0].update(plugins)
        share[1].append((name, variant_for(golden[name]), str(xml)))
    results = {}
    for i, (_, share) in enumerate(shares):
        out = tmp / f"results{i}.json"
        proc = subprocess.run([sys.executable, "-c", LOAD_EXPORTS, json.dumps(share), str(out)], capture_output=True,
                              text=True, timeout=600, env=llvm.env())
        assert proc.returncode == 0, proc.stderr[-3000:]
        results.update(json.loads(out.read_text()))
    return results


@pytest.mark.slow
@pytest.mark.parametrize("name", ALL_SCENES)
def test_export_loads_with_mi_load_file_and_renders(golden, loaded_exports, name):
    result = loaded_exports[name]
    assert "error" not in result, result.get("error")
    r = golden[name]["render"]
    assert result == {"shape": [r["height"], r["width"]], "lit": True, "finite": True}


def test_mitsuba_command_line_renders_the_export(golden, tmp_path):
    """The folder works with the ``mitsuba`` executable too (-e route of the backend)."""
    exe = Path(sys.executable).with_name("mitsuba")
    sc = copy.deepcopy(golden["ggx_copper_80"])
    sc["render"]["width"] = sc["render"]["height"] = 32
    xml = mitsuba_writer.write(sc, tmp_path / "m")
    proc = subprocess.run([str(exe), "-m", "scalar_spectral", "-Dspp=4", "-o", str(tmp_path / "o.exr"), str(xml)],
                          capture_output=True, text=True, timeout=300, env=llvm.env())
    assert proc.returncode == 0, proc.stderr
    img = exr.read_rgb(tmp_path / "o.exr")
    assert img.shape == (32, 32, 3) and img.mean() > 0


@pytest.mark.slow
def test_batch_exec_option_uses_the_mitsuba_executable(golden, tmp_path):
    exe = Path(sys.executable).with_name("mitsuba")
    out = tmp_path / "out"
    proc = run_batch("-r", "mitsuba", "-i", write_scene(tmp_path, golden["ggx_copper_80"]), "-e", f"mitsuba={exe}",
                     "--scale", 0.0625, "--spp", 4, "--no-flip", "--variant", "scalar_spectral", "-o", out)
    run = metrics(out)["runs"][0]
    # the version from the executable's banner, so that known deviations of that version apply
    assert run["versions"] == {"mitsuba": "3.9.1", "route": "executable"}, run
    assert run["image"] and (out / run["image"]).is_file()
    assert "render.log" in os.listdir(out / "ggx_copper_80" / "results" / "mitsuba")
    # --passes (default 2) honoured: two runs of the executable, the render's own noise from their spread
    assert run["passes"] == 2 and len(run["pass_times"]) == 2, run
    assert run["test"]["pass"] is not None, run["test"]


def test_emitter_radiance_is_one_at_560nm_times_scale(tmp_path):
    """Radiometry: a camera looking straight at a light of 'cie_d65' scale 3 sees Y equal to
    3 * (D65 luminance relative to D65(560nm)), independent of Mitsuba's own d65 normalisation.
    The expected value is computed from the same CIE table with the CIE 1931 Y function."""
    import colour
    sc = {"format": ir.FORMAT, "version": ir.VERSION, "name": "radiometry", "case": "custom", "needs": [],
          "render": {"spp": 4, "width": 8, "height": 8, "max_depth": 2},
          "camera": {"to_world": ir.identity(), "fov": 10.0, "fov_axis": "x"},
          "environment": None,
          "objects": [{"name": "wall", "bsdf": None,
                       "emitter": {"type": "area", "radiance": {"type": "named", "name": "cie_d65", "scale": 3.0}},
                       "shape": {"type": "rectangle", "to_world": [[5, 0, 0, 0], [0, 5, 0, 0], [0, 0, 1, -2], [0, 0, 0, 1]]}}]}
    xml = mitsuba_writer.write(ir.with_derived_needs(sc), tmp_path / "m")
    out = mitsuba(f"""
        import mitsuba as mi, numpy as np
        mi.set_variant("scalar_spectral")
        img = np.array(mi.render(mi.load_file({str(xml)!r}), spp=64))
        print(float(img[..., 0].mean()), float(img[..., 1].mean()), float(img[..., 2].mean()))
    """)
    rgb = np.array([float(x) for x in out.split()])
    y = rgb @ np.array([0.2126, 0.7152, 0.0722])  # linear sRGB -> Y
    d65 = colour.SDS_ILLUMINANTS["D65"]
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    wl = np.arange(360, 831, 1.0)
    d65v = np.interp(wl, d65.wavelengths, d65.values) / 100.0  # 1.0 at 560 nm
    yb = np.interp(wl, cmfs.wavelengths, cmfs.values[:, 1], left=0, right=0)
    expected = 3.0 * np.sum(d65v * yb) / np.sum(yb)  # Mitsuba's Y of a flat spectrum 1 is 1
    assert y == pytest.approx(expected, rel=0.01), (y, expected)


@pytest.mark.parametrize("name", ALL_SCENES)
def test_writer_output_matches_golden_folder(golden, tmp_path, name):
    """Any change of the Mitsuba writer shows as a reviewable diff of golden/mitsuba/
    (regenerate with scripts/update_golden.py). The Python plugins an export carries in plugins/
    are verbatim copies of exporters/mitsuba_plugins/, and its load_plugins.py is that module's
    loader naming exactly those plugins (checked here, not stored again)."""
    from conftest import ROOT
    from spectral_bench.exporters import mitsuba_plugins
    expected_dir = ROOT / "golden" / "mitsuba" / name
    mitsuba_writer.write(golden[name], tmp_path / name)
    written = sorted(p.relative_to(tmp_path / name) for p in (tmp_path / name).rglob("*") if p.is_file())
    carried = [rel for rel in written if rel.parts[0] == "plugins"]
    for rel in carried:
        assert (tmp_path / name / rel).read_bytes() == (mitsuba_plugins.HERE / rel.name).read_bytes(), rel
    loader = Path("load_plugins.py")
    assert (loader in written) == bool(carried)
    if carried:
        names = sorted(n for n, module in mitsuba_plugins.MODULES.items() if Path("plugins", f"{module}.py") in carried)
        text = (tmp_path / name / loader).read_text()
        variant = re.search(r'mi.set_variant\("([a-z_]+)"\)', text).group(1)
        assert text == mitsuba_plugins.LOADER.format(variant_hint=variant, names=", ".join(names))
    written = [rel for rel in written if rel not in carried and rel != loader]
    expected = sorted(p.relative_to(expected_dir) for p in expected_dir.rglob("*") if p.is_file())
    assert written == expected
    for rel in written:
        assert (tmp_path / name / rel).read_bytes() == (expected_dir / rel).read_bytes(), rel  # meshes are binary PLY
