"""The Blender UI's operators and logic, headless (panel draw code cannot run without a window,
so it is kept thin and these test what it calls)."""
import json

import numpy as np

from conftest import run_bpy
from spectral_bench.batch import exr


def test_invalid_annotations_give_messages_not_exceptions():
    out = run_bpy("""
        from spectral_bench.addon import validation
        m = bpy.data.materials["ggx_copper"]
        m.spectral_bench.alpha = -1.0
        a = validation.material_problems(m)
        m.spectral_bench.conductor = "Unobtainium"
        b = validation.material_problems(m)
        g = bpy.data.materials["glass_1.52"]
        g.spectral_bench.int_ior = 0.0
        c = validation.material_problems(g)
        light = bpy.data.lights["light"]
        light.spectral_bench.radiance.named = "cie_d66"
        d = validation.light_problems(light)
        ok = validation.material_problems(bpy.data.materials["grey_0.5"])
        print(json.dumps([a, b, c, d, ok]))
    """)
    a, b, c, d, ok = out
    assert any("roughness.alpha" in m and "-1" in m for m in a)
    assert b == ["Unknown conductor 'Unobtainium'"]
    assert any(m.startswith("int_ior") for m in c)
    assert any("radiance.name" in m and "cie_d66" in m for m in d)
    assert ok == []


def test_sampled_spectrum_from_file_and_table(tmp_path):
    spd = tmp_path / "red.spd"
    spd.write_text("# wavelength value\n400 0.05\n500, 0.06\n600 0.5\n700 0.6\n")
    bad = tmp_path / "bad.csv"
    bad.write_text("400 0.1\nnot a number\n")
    out = run_bpy(f"""
        from spectral_bench.exporters import extract_blender
        m = bpy.data.materials["grey_0.5"]
        with bpy.context.temp_override(material=m):
            r1 = bpy.ops.spectral_bench.load_spectrum(filepath={str(spd)!r}, target="material.reflectance")
            bpy.ops.spectral_bench.spectrum_sample(target="material.reflectance", action="ADD")
            bpy.ops.spectral_bench.spectrum_sample(target="material.reflectance", action="REMOVE")
            try:
                r2 = bpy.ops.spectral_bench.load_spectrum(filepath={str(bad)!r}, target="material.reflectance")
            except RuntimeError as e:
                r2 = str(e)
        print(json.dumps({{"r1": list(r1), "r2": r2 if isinstance(r2, str) else list(r2),
                          "ir": extract_blender.spectrum(m.spectral_bench.reflectance)}}))
    """)
    assert out["r1"] == ["FINISHED"]
    assert out["ir"] == {"type": "sampled", "wavelengths": [400.0, 500.0, 600.0, 700.0],
                         "values": [0.05000000074505806, 0.05999999865889549, 0.5, 0.6000000238418579]}
    assert "line 2" in out["r2"]  # the bad file is reported with its line, the spectrum kept


def test_run_from_blender_then_load_result_images(tmp_path):
    out = run_bpy(f"""
        import numpy as np
        from spectral_bench.addon import benchmark
        bpy.context.window_manager.spectral_bench_run.only_active = True
        s = bpy.context.window_manager.spectral_bench_run
        s.spp, s.scale, s.output_parent = 64, 0.125, {str(tmp_path)!r}
        with bpy.context.temp_override(scene=bpy.data.scenes["ggx_copper_80"]):
            r = bpy.ops.spectral_bench.run_benchmark(wait=True)
            loaded = {{}}
            for kind in ("render", "reference", "diff_abs", "flip"):
                bpy.ops.spectral_bench.load_result(scene="ggx_copper_80", backend="mitsuba", kind=kind)
                img = bpy.data.images["ggx_copper_80 mitsuba " + kind]
                w, h = img.size
                px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)
                loaded[kind] = px[::-1, :, :3].tolist()  # Blender stores rows bottom-up
        print(json.dumps({{"r": list(r), "status": s.status, "out": s.output_dir, "loaded": loaded}}))
    """)
    assert out["r"] == ["FINISHED"] and out["status"].startswith("passed: 1/1")
    res = f"{out['out']}/ggx_copper_80/results/mitsuba"
    for kind, name in (("render", "render.exr"), ("reference", "reference.exr"), ("diff_abs", "diff_abs.exr")):
        expected = exr.read_rgb(f"{res}/{name}")
        assert np.allclose(np.array(out["loaded"][kind]), expected, atol=1e-6), kind
    runs = json.loads(open(f"{out['out']}/metrics.json").read())["runs"]
    assert [r["scene"] for r in runs] == ["ggx_copper_80"] and runs[0]["status"] == "ok"


def test_cancel_stops_the_run_and_keeps_finished_results(tmp_path):
    out = run_bpy(f"""
        import time
        from spectral_bench.addon import benchmark
        from spectral_bench.batch.report import results
        s = bpy.context.window_manager.spectral_bench_run
        s.spp, s.scale, s.output_parent = 16, 0.125, {str(tmp_path)!r}
        bpy.ops.spectral_bench.run_benchmark()   # returns at once; the run goes on in the background
        job = benchmark._ACTIVE["job"]
        t0 = time.time()
        while job.done_jobs() < 1 and time.time() - t0 < 300:
            time.sleep(0.2)
        before = job.done_jobs()
        bpy.ops.spectral_bench.cancel_benchmark()
        time.sleep(1.0)
        after = results.load(s.output_dir)
        print(json.dumps({{"before": before, "after": len(after["runs"]), "total": job.total,
                          "running": job.running(), "status": s.status,
                          "statuses": [r["status"] for r in after["runs"]]}}))
    """)
    assert not out["running"] and out["status"].startswith("cancelled")
    assert 1 <= out["before"] <= out["after"] < out["total"], out
    assert all(st in ("ok", "failed", "unsupported", "skipped") for st in out["statuses"])


def test_register_unregister_leaves_no_trace():
    out = run_bpy("""
        import spectral_bench
        spectral_bench.unregister()
        gone = {
            "props": [t for t in ("Material", "Light", "World", "Camera", "Object", "Scene")
                      if hasattr(getattr(bpy.types, t), "spectral_bench")],
            "wm": hasattr(bpy.types.WindowManager, "spectral_bench_run"),
            "ops": [n for n in dir(bpy.types) if n.startswith("SPECTRAL_BENCH_")],
        }
        spectral_bench.register()
        back = hasattr(bpy.types.WindowManager, "spectral_bench_run")
        print(json.dumps({"gone": gone, "back": back}))
    """)
    assert out["gone"] == {"props": [], "wm": False, "ops": []}
    assert out["back"]


def test_file_export_operators_write_loadable_folders(tmp_path):
    out = run_bpy(f"""
        res = {{}}
        with bpy.context.temp_override(scene=bpy.data.scenes["ggx_copper_70"]):
            res["art"] = list(bpy.ops.spectral_bench.export_art(filepath={str(tmp_path / 'art')!r}))
            res["mitsuba"] = list(bpy.ops.spectral_bench.export_mitsuba(filepath={str(tmp_path / 'mi')!r}))
            res["json"] = list(bpy.ops.spectral_bench.export_json(filepath={str(tmp_path / 'ir.json')!r}))
        print(json.dumps(res))
    """)
    assert out == {"art": ["FINISHED"], "mitsuba": ["FINISHED"], "json": ["FINISHED"]}
    assert "ARM_MAIN_FUNCTION(scene)" in (tmp_path / "art" / "scene.arm").read_text()
    assert (tmp_path / "mi" / "scene.xml").is_file()
    from spectral_bench.exporters import ir_json
    assert ir_json.load(tmp_path / "ir.json")["name"] == "ggx_copper_70"


def test_sweep_chart_loads_into_an_image(tmp_path):
    import subprocess, sys
    from conftest import ROOT
    out = tmp_path / "o"
    subprocess.run([sys.executable, str(ROOT / "batch" / "run.py"), "-r", "mitsuba", "-s", "ggx_copper_80", "--scale",
                    "0.0625", "--sweep", "--ladder", "4,16", "--no-flip", "-o", str(out)], check=False, timeout=600,
                   capture_output=True)
    res = run_bpy(f"""
        s = bpy.context.window_manager.spectral_bench_run
        s.output_dir = {str(out)!r}
        r = bpy.ops.spectral_bench.load_chart(scene="ggx_copper_80")
        img = bpy.data.images["ggx_copper_80 sweep chart"]
        print(json.dumps({{"r": list(r), "size": list(img.size)}}))
    """)
    assert res["r"] == ["FINISHED"] and res["size"][0] > 100
