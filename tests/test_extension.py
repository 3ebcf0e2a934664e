"""The extension validates with Blender's own validator, builds, installs and enables in the
bpy module, registers its annotations and operators, and unregisters without a trace.

Runs in child processes with BLENDER_USER_RESOURCES in a temporary folder, so nothing is
installed into the user's real Blender configuration."""
import json
import os
import subprocess
import sys
import textwrap

from conftest import ROOT


def run_bpy(code, tmp_path, timeout=300):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_validate_build_install_enable_unregister(tmp_path):
    dist = tmp_path / "dist"
    dist.mkdir()
    out = run_bpy(f"""
        import json, os, bpy, addon_utils
        from bl_pkg import bl_extension_cli
        ok_validate = bl_extension_cli.cli_extension_handler(["validate", {str(ROOT)!r}])
        ok_build = bl_extension_cli.cli_extension_handler(["build", "--source-dir", {str(ROOT)!r},
                                                           "--output-dir", {str(dist)!r}])
        zips = sorted(os.listdir({str(dist)!r}))
        res = bpy.ops.extensions.package_install_files(filepath=os.path.join({str(dist)!r}, zips[0]),
                                                       repo="user_default", enable_on_install=True)
        module = "bl_ext.user_default.spectral_bench"
        enabled = module in bpy.context.preferences.addons
        props = {{t: hasattr(getattr(bpy.types, t), "spectral_bench")
                  for t in ("Material", "Light", "World", "Camera", "Object", "Scene")}}
        ops = hasattr(bpy.ops.spectral_bench, "export_json") and hasattr(bpy.ops.spectral_bench, "export_mitsuba")
        # the installed copy can export: annotate the default scene and write its JSON
        sc = bpy.context.scene
        bpy.ops.mesh.primitive_plane_add(size=2)
        obj = bpy.context.object
        mat = bpy.data.materials.new("m"); obj.data.materials.append(mat)
        mat.spectral_bench.kind = "DIFFUSE"
        bpy.ops.object.camera_add(location=(0, -4, 1))
        sc.camera = bpy.context.object
        for o in list(sc.objects):
            if o.type == "LIGHT" or o.name == "Cube":
                bpy.data.objects.remove(o)
        path = {str(tmp_path / "exported.json")!r}
        exported = bpy.ops.spectral_bench.export_json(filepath=path)
        mitsuba = bpy.ops.spectral_bench.export_mitsuba(filepath={str(tmp_path / "mitsuba_export")!r})
        addon_utils.disable(module, default_set=True)
        gone = {{t: hasattr(getattr(bpy.types, t), "spectral_bench")
                 for t in ("Material", "Light", "World", "Camera", "Object", "Scene")}}
        gone_ops = hasattr(bpy.types, "SPECTRAL_BENCH_OT_export_json")
        print(json.dumps({{"validate": ok_validate, "build": ok_build, "zips": zips, "install": list(res),
                          "enabled": enabled, "props": props, "ops": ops, "exported": list(exported),
                          "mitsuba": list(mitsuba), "gone": gone, "gone_ops": gone_ops}}))
    """, tmp_path)
    assert out["validate"] == 0 and out["build"] == 0, out
    assert out["zips"] == ["spectral_bench-0.1.0.zip"]
    assert out["install"] == ["FINISHED"] and out["enabled"]
    assert all(out["props"].values()) and out["ops"]
    assert out["exported"] == ["FINISHED"] and out["mitsuba"] == ["FINISHED"]
    scene = json.loads((tmp_path / "exported.json").read_text())
    assert scene["objects"][0]["bsdf"]["type"] == "diffuse"
    assert (tmp_path / "mitsuba_export" / "scene.xml").is_file()
    assert not any(out["gone"].values()) and not out["gone_ops"]


def test_manifest_rejected_when_broken(tmp_path):
    """The validator is a real check: a manifest with a bad field fails it."""
    src = tmp_path / "ext"
    src.mkdir()
    (src / "__init__.py").write_text("def register(): pass\ndef unregister(): pass\n")
    text = (ROOT / "blender_manifest.toml").read_text().replace('id = "spectral_bench"', 'id = "spectral bench!"')
    (src / "blender_manifest.toml").write_text(text)
    out = run_bpy(f"""
        import json, bpy
        from bl_pkg import bl_extension_cli
        print(json.dumps(bl_extension_cli.cli_extension_handler(["validate", {str(src)!r}])))
    """, tmp_path)
    assert out != 0
