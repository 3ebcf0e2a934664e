"""The Blender UI headless: every panel's draw code (through tests/layout_recorder.py, which checks
each drawn property, operator, operator property, icon and keyword against Blender's RNA), the
operators (canonical scenes, run, cancel, results, report) and the logic they call."""
import json
import re
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import ALL_SCENES, ROOT, run_batch, run_bpy
from spectral_bench.batch import exr

TESTS = str(ROOT / "tests")


@pytest.mark.slow
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


@pytest.mark.slow
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


# -- drawing -------------------------------------------------------------------------------------
def _write_outputs(out):
    """An outputs folder with every status (and one the panel has never heard of), images for one
    Stokes run and a sweep chart: what the results view must show."""
    statuses = ["ok", "skipped", "fixed", "unsupported", "known", "unjudged", "brand_new_status", "failed"]
    runs = []
    ref_path = ROOT / "references" / "ggx_copper_50.exr"
    for i, status in enumerate(statuses):
        runs.append({"scene": f"scene_{i}_{status}", "case": "c", "backend": "mitsuba", "mode": "m", "status": status,
                     "reason": f"reason for {status}" if status != "ok" else "", "spp": 4, "resolution": [8, 8],
                     "time_s": 0.1, "image": None, "channels": ["R", "G", "B"],
                     "metrics": {"rmse": 0.1, "relmse": 0.2, "mape": 0.3, "flip": 0.4 if i % 2 else None},
                     "probes": [{"name": "p", "expected": 1.0, "measured": 1.1, "error": 0.1, "unit": "dE00",
                                 "pass": [True, False, None][i % 3]}],
                     "test": {"p_min": 0.5, "threshold": 0.001, "z_max": 1.2, "pass": True},
                     "reference": {"path": str(ref_path), "spp": 4096, "backend": "mitsuba", "mode": "llvm_ad_spectral",
                                   "date": "2026-11-22T02:27:31"}})
    stokes = runs[-1]  # the failed one gets images, with Stokes channels
    stokes["channels"] = ["R", "G", "B"] + [f"S{k}.{c}" for k in range(4) for c in "RGB"]
    res = out / stokes["scene"] / "results" / "mitsuba"
    img = np.random.default_rng(0).random((8, 8, 15)).astype(np.float32)
    exr.write_image(res / "render.exr", stokes["channels"], img)
    for name in ("reference", "diff_abs", "diff_rel", "flip", "zscore"):
        exr.write(res / f"{name}.exr", img[..., :3])
    stokes["image"] = str((res / "render.exr").relative_to(out))
    stokes["bands"] = {"model": "box", "centres_nm": [485.0, 495.0], "threshold": 0.01, "regions": [  # issue 33's record
        {"probe": "macbeth", "region": "cyan", "measured": [0.97, 1.0], "se": [0.005, 0.005], "expected": [1.0, 1.0],
         "pass": False, "worst": {"band_nm": [480, 490], "relative": -0.031, "z": -6.2}}]}
    (out / "sweeps").mkdir(parents=True)
    from PIL import Image
    Image.new("RGB", (4, 4)).save(out / "sweeps" / f"{stokes['scene']}.png")
    (out / "metrics.json").write_text(json.dumps({"started": "now", "options": {}, "runs": runs}))
    return statuses


@pytest.mark.slow
def test_every_panel_draws_with_real_data(tmp_path):
    """poll() and draw() of every registered panel, the preferences and the File > Export entries,
    over every scene, object and material of scenes.blend, every value of the enums that steer the
    draw code, a results folder holding every status, and a backend the panel has never seen."""
    out_dir = tmp_path / "outputs"
    statuses = _write_outputs(out_dir)
    out = run_bpy(f"""
        sys.path.insert(0, {TESTS!r})
        import types
        import layout_recorder as lr
        from spectral_bench.addon import benchmark, operators, preferences
        from spectral_bench.batch import backends

        class FakeRGB:  # a backend that lands later: it must appear without any panel change
            name, formats = "fake_rgb", ("json",)
            def availability(self):
                return False, "fake_rgb is not installed here"
        backends.BACKENDS["fake_rgb"] = lambda **kw: FakeRGB()

        panels = lr.registered_panels("spectral_bench")
        drawn = {{p.__name__: 0 for p in panels}}
        calls = []
        def draw_all(**ctx):
            context = lr.Context(**ctx)
            for p in panels:
                got = lr.draw(p, context)
                if got is not None:
                    drawn[p.__name__] += 1
                    calls.extend((p.__name__, c) for c in got)

        def spectra_of(owner):
            return [getattr(owner.spectral_bench, f) for f in ("reflectance", "eta", "k", "radiance")
                    if hasattr(owner.spectral_bench, f)]

        s = bpy.context.window_manager.spectral_bench_run
        for scene in bpy.data.scenes:
            for obj in list(scene.objects) + [None]:
                mats = [obj.active_material] if obj is not None and obj.active_material else [None]
                for mat in mats:
                    draw_all(scene=scene, object=obj, material=mat)
        # every branch of the annotation panels
        mat = bpy.data.materials["ggx_copper"]
        light = next(o for o in bpy.data.objects if o.type == "LIGHT")
        camera = next(o for o in bpy.data.objects if o.type == "CAMERA")
        world_scene = next(sc for sc in bpy.data.scenes if sc.world is not None)
        for kind in ("NONE", "DIFFUSE", "CONDUCTOR", "DIELECTRIC"):
            mat.spectral_bench.kind = kind
            for named in (True, False):
                mat.spectral_bench.conductor_named = named
                for dist in ("SMOOTH", "GGX"):
                    mat.spectral_bench.distribution = dist
                    for skind in ("CONSTANT", "SAMPLED", "NAMED", "BLACKBODY"):
                        for spec in spectra_of(mat) + spectra_of(light.data) + spectra_of(world_scene.world):
                            spec.kind = skind
                        for spec in spectra_of(mat):
                            if skind == "SAMPLED" and not len(spec.samples):
                                spec.samples.add()
                        draw_all(scene=world_scene, object=light, material=mat)
        for enabled in (True, False):
            world_scene.world.spectral_bench.enabled = enabled
            camera.data.spectral_bench.polarizer = enabled
            draw_all(scene=world_scene, object=camera)
        # every scene source, and the results folder
        s.output_dir = {str(out_dir)!r}
        for source in ("CANONICAL", "FILE", "ACTIVE"):
            s.scene_source = source
            draw_all(scene=world_scene)
        # the preferences (the extension is not installed here: the class with default values)
        prefs = types.SimpleNamespace(bl_rna=preferences.SpectralBenchPreferences.bl_rna, references_dir="",
                                      renderers_files=[],
                                      reference_source="BOTH")
        pref_calls = lr.draw(preferences.SpectralBenchPreferences, lr.Context(), instance=prefs)
        menu_calls = lr.draw_function(operators._menu, lr.Context(), "TOPBAR_MT_file_export")

        def texts(name, func):
            return [c[2].get("text") for p, c in calls if p == name and c[1] == func]
        results = texts("SPECTRAL_BENCH_PT_benchmark_results", "label")
        print(json.dumps({{
            "drawn": drawn,
            "props": sorted({{c[2]["property"] for p, c in calls if c[1] == "prop"}}),
            "status_order": [t.split(": ", 1)[1] for t in results if t and t.startswith("scene_") and "/" in t][:8],
            "reference_labels": [t for t in results if t and t.startswith("reference (")],
            "noise_labels": sorted({{t for t in results if t and t.startswith("noise test:")}}),
            "judged_labels": sorted({{t for t in results if t and t.startswith("judged by:")}}),
            "worst_labels": sorted({{t for t in results if t and t.startswith("worst band:")}}),
            "load_kinds": sorted({{c[2]["properties"].get("kind") for p, c in calls
                                 if c[1] == "operator" and c[2]["operator"] == "spectral_bench.load_result"}}),
            "backend_buttons": sorted(set(texts("SPECTRAL_BENCH_PT_benchmark", "operator")) - {{None}}),
            "disabled_rows": sum(1 for p, c in calls if c[1] == "set enabled" and c[2]["value"] is False),
            "pref_labels": [c[2].get("text") for c in pref_calls if c[1] == "label"],
            "menu": [c[2]["operator"] for c in menu_calls],
        }}))
    """)
    assert all(n > 0 for n in out["drawn"].values()), out["drawn"]  # every panel's poll() let it draw
    assert len(out["drawn"]) >= 9
    assert {"kind", "scene_source", "canonical_scene", "spp", "scale", "passes", "flip", "output_dir"} <= set(out["props"])
    # the order of summary.md and report.html (batch/verdict/status.py), a status the view does not
    # know last; every status shown as it is
    from spectral_bench.batch import records
    from spectral_bench.batch.verdict import status
    assert out["status_order"] == sorted(statuses, key=status.rank)
    assert out["status_order"][0] == "failed" and out["status_order"][-1] == "brand_new_status"
    # the noise test in the words of summary.md and report.html (batch/records.py noise_test_text)
    assert out["noise_labels"] == ["noise test: " + records.noise_test_text(
        {"p_min": 0.5, "threshold": 0.001, "z_max": 1.2, "pass": True})] == ["noise test: pass: p_min 0.5 (threshold 0.001), z_max 1.20"]
    # what judged each run, in the words of summary.md, report.html and JUnit (batch/report/results.py):
    # scene_2_fixed's only probe was not measured, so its own renderer's reference alone judged it
    assert out["judged_labels"][:2] == [  # known and failed: their probe failed; ok: it passed
        "judged by: 1 probe (0 passed); reference by mitsuba llvm_ad_spectral, 4096 spp, 2026-11-22",
        "judged by: 1 probe (1 passed); reference by mitsuba llvm_ad_spectral, 4096 spp, 2026-11-22"], out["judged_labels"]
    assert [t for t in out["judged_labels"] if "checked against itself: detects change, not error" in t] == [
        "judged by: no probe; reference by mitsuba llvm_ad_spectral, 4096 spp, 2026-11-22 "
        "(checked against itself: detects change, not error)"]
    # a failing spectral region by its worst band, in the words of summary.md (batch/report/spectra.py)
    assert out["worst_labels"] == ["worst band: macbeth cyan 480-490 nm: 3.1 % low, z -6.2"], out["worst_labels"]
    assert out["reference_labels"] and all(t.startswith("reference (extension): mitsuba llvm_ad_spectral 4096 spp")
                                           for t in out["reference_labels"])
    assert out["load_kinds"] == sorted(["render", "reference", "diff_abs", "diff_rel", "flip", "zscore",
                                        "S0", "S1", "S2", "S3"])
    assert "fake_rgb: fake_rgb is not installed here" in out["backend_buttons"] and "mitsuba" in out["backend_buttons"]
    assert out["disabled_rows"] >= 1
    assert any(t.startswith("extension: ") and int(t.split()[1]) > 0 and t.endswith(str(ROOT / "references"))
               for t in out["pref_labels"]), out["pref_labels"]
    assert out["menu"] == ["spectral_bench.export_json", "spectral_bench.export_mitsuba", "spectral_bench.export_art"]


@pytest.mark.slow
def test_draw_check_catches_broken_panels():
    """The check's power: each deliberately broken panel fails with a message naming the culprit,
    among them the benchmark panel's old backend loop (it drew ``use_art``, which never existed)."""
    out = run_bpy(f"""
        sys.path.insert(0, {TESTS!r})
        import layout_recorder as lr
        from spectral_bench.batch import backends

        def broken(draw):
            cls = type("SPECTRAL_BENCH_PT_broken", (bpy.types.Panel,), dict(
                bl_label="Broken", bl_space_type="PROPERTIES", bl_region_type="WINDOW", bl_context="scene",
                draw=draw))
            bpy.utils.register_class(cls)
            try:
                lr.draw(cls, lr.Context())
                return None
            except lr.DrawError as exc:
                return str(exc)
            finally:
                bpy.utils.unregister_class(cls)

        def old_backend_loop(self, context):
            s = context.window_manager.spectral_bench_run
            for name in backends.BACKENDS:
                self.layout.row().prop(s, f"use_{{name}}", text=name)

        wm = lambda c: c.window_manager.spectral_bench_run
        cases = {{
            "old_backend_loop": old_backend_loop,
            "missing_property": lambda self, c: self.layout.prop(wm(c), "use_art"),
            "missing_operator": lambda self, c: self.layout.operator("spectral_bench.run_benchmrk"),
            "missing_operator_property": lambda self, c: setattr(
                self.layout.operator("spectral_bench.load_result"), "scenes", "x"),
            "bad_operator_enum": lambda self, c: setattr(
                self.layout.operator("spectral_bench.load_result"), "kind", "S4"),
            "bad_icon": lambda self, c: self.layout.label(text="x", icon="CHECKMARKS"),
            "bad_keyword": lambda self, c: self.layout.prop(wm(c), "spp", txt="Samples"),
            "bad_layout_attribute": lambda self, c: setattr(self.layout.row(), "enable", False),
            "bad_operator_context": lambda self, c: setattr(self.layout.row(), "operator_context", "INVOKE"),
            "not_rna_data": lambda self, c: self.layout.prop({{"spp": 1}}, "spp"),
            "fine": lambda self, c: self.layout.prop(wm(c), "spp", text="Samples"),
        }}
        print(json.dumps({{name: broken(draw) for name, draw in cases.items()}}))
    """)
    assert out.pop("fine") is None
    expect = {"old_backend_loop": "use_mitsuba", "missing_property": "use_art", "missing_operator": "run_benchmrk",
              "missing_operator_property": "scenes", "bad_operator_enum": "S4", "bad_icon": "CHECKMARKS",
              "bad_keyword": "txt", "bad_layout_attribute": "enable", "bad_operator_context": "INVOKE",
              "not_rna_data": "bl_rna"}
    for name, culprit in expect.items():
        assert out[name] is not None and culprit in out[name], (name, out[name])


# -- canonical scenes ----------------------------------------------------------------------------
@pytest.mark.slow
def test_canonical_scenes_open_append_and_extract_unchanged(golden):
    out = run_bpy("""
        from spectral_bench.addon import canonical
        from spectral_bench.exporters import extract_blender, ir_json
        bpy.ops.wm.read_homefile(use_empty=True)
        before = [sc.name for sc in bpy.data.scenes]
        listed = canonical.scene_names()
        # extraction for a run reads a temporary BlendData: the open file does not change
        extracted = {n: ir_json.dumps(d) for n, d in canonical.extract(["ggx_copper_50", "polarizing_spheres"])}
        untouched = [sc.name for sc in bpy.data.scenes] == before and not bpy.data.libraries
        r1 = bpy.ops.spectral_bench.append_canonical_scene(scene="ggx_copper_50")
        appended = ir_json.dumps(extract_blender.extract_scene(bpy.data.scenes["ggx_copper_50"]))
        try:
            bpy.ops.spectral_bench.append_canonical_scene(scene="no_such_scene")
            bad = None
        except RuntimeError as exc:
            bad = str(exc)
        undoable = {op: "UNDO" in getattr(bpy.types, op).bl_options for op in (
            "SPECTRAL_BENCH_OT_append_canonical_scene", "SPECTRAL_BENCH_OT_load_result",
            "SPECTRAL_BENCH_OT_load_chart", "SPECTRAL_BENCH_OT_load_spectrum", "SPECTRAL_BENCH_OT_spectrum_sample")}
        r2 = bpy.ops.spectral_bench.open_canonical_scenes()
        print(json.dumps({"before": before, "listed": listed, "extracted": extracted, "untouched": untouched,
                          "r1": list(r1), "appended": appended, "bad": bad, "undoable": undoable, "r2": list(r2),
                          "opened": sorted(sc.name for sc in bpy.data.scenes), "filepath": bpy.data.filepath,
                          "annotated": bpy.data.scenes["ggx_copper_50"].spectral_bench.case}))
    """)
    from spectral_bench.exporters import ir_json
    names = sorted(golden)
    assert out["listed"] == names and out["untouched"]
    for name, text in out["extracted"].items():
        assert text == ir_json.dumps(golden[name]), name
    assert out["r1"] == ["FINISHED"] and out["appended"] == ir_json.dumps(golden["ggx_copper_50"])
    assert "no_such_scene" in out["bad"]
    assert all(out["undoable"].values()), out["undoable"]
    assert out["r2"] == ["FINISHED"] and out["opened"] == names and out["annotated"] == "reflectance"
    assert out["filepath"] != str(ROOT / "scenes.blend")  # a copy: saving never writes into the extension


# -- running -------------------------------------------------------------------------------------
@pytest.mark.slow
def test_run_from_blender_then_load_images_and_open_report(tmp_path):
    opened = tmp_path / "opened.txt"
    browser = tmp_path / "browser.py"
    browser.write_text(f"import sys\nopen({str(opened)!r}, 'w').write(sys.argv[1])\n")
    out = run_bpy(f"""
        import os, time
        import numpy as np
        sys.path.insert(0, {TESTS!r})
        import layout_recorder as lr
        from spectral_bench.addon import benchmark
        from spectral_bench.batch import backends
        s = bpy.context.window_manager.spectral_bench_run
        s.scene_source = "ACTIVE"
        s.backends_off = ",".join(n for n in backends.BACKENDS if n != "mitsuba")  # this test judges Mitsuba
        s.spp, s.scale, s.passes, s.output_parent = 64, 0.125, 2, {str(tmp_path)!r}
        s.flip = "ON"  # the FLIP image of an ok render too (the default, auto, computes it where not ok)
        try:
            bpy.ops.spectral_bench.open_report()
            missing = None
        except RuntimeError as exc:
            missing = str(exc)
        with bpy.context.temp_override(scene=bpy.data.scenes["ggx_copper_80"]):
            r = bpy.ops.spectral_bench.run_benchmark(wait=True)
            loaded = {{}}
            for kind in ("render", "reference", "diff_abs", "flip", "zscore"):
                bpy.ops.spectral_bench.load_result(scene="ggx_copper_80", backend="mitsuba", kind=kind)
                img = bpy.data.images["ggx_copper_80 mitsuba " + kind]
                w, h = img.size
                px = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)
                loaded[kind] = px[::-1, :, :3].tolist()  # Blender stores rows bottom-up
        results = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark_results, lr.Context())
        rep = bpy.ops.spectral_bench.open_report()
        t0 = time.time()
        while not os.path.exists({str(opened)!r}) and time.time() - t0 < 30:
            time.sleep(0.1)
        print(json.dumps({{"r": list(r), "status": s.status, "out": s.output_dir, "loaded": loaded, "missing": missing,
                          "rep": list(rep), "labels": [c[2].get("text") for c in results if c[1] == "label"]}}))
    """, env={"BROWSER": f"{sys.executable} {browser} %s"})
    assert "no report.html" in out["missing"]
    assert out["r"] == ["FINISHED"] and re.fullmatch(r"passed: 1/1 jobs \(1 (ok|known|fixed)\)", out["status"]), out["status"]
    res = f"{out['out']}/ggx_copper_80/results/mitsuba"
    for kind, name in (("render", "render.exr"), ("reference", "../reference_64x64.exr"), ("diff_abs", "diff_abs.exr"),
                       ("zscore", "zscore.exr"), ("flip", "flip.exr")):  # the reference is the scene's shared one;
        # diff_abs written when loaded; flip.exr is one channel Y, which Blender shows grey (R = G = B)
        expected = exr.read_rgb(f"{res}/{name}")
        assert np.allclose(np.array(out["loaded"][kind]), expected, atol=1e-6), kind
    from spectral_bench.batch import records
    data = records.read(f"{out['out']}/metrics.json")  # the reference path, stored relative to the run folder
    runs = data["runs"]
    assert [r["scene"] for r in runs] == ["ggx_copper_80"] and runs[0]["status"] == "ok"
    assert runs[0]["test"]["pass"] and data.path(runs[0]["reference"]["path"]) == ROOT / "references" / "ggx_copper_80.exr"
    assert any(t and t.startswith("reference (extension): mitsuba") for t in out["labels"])
    assert out["rep"] == ["FINISHED"]
    for _ in range(100):
        if opened.exists() and opened.read_text():
            break
        time.sleep(0.1)
    assert opened.read_text() == (Path(out["out"]) / "report.html").resolve().as_uri()


@pytest.mark.slow
def test_cancel_stops_the_run_and_keeps_finished_results(tmp_path):
    out = run_bpy(f"""
        import time
        from spectral_bench.addon import benchmark
        from spectral_bench.batch import backends
        from spectral_bench.batch import run_folder
        s = bpy.context.window_manager.spectral_bench_run
        s.scene_source, s.canonical_scene = "CANONICAL", "__ALL__"
        s.backends_off = ",".join(n for n in backends.BACKENDS if n != "mitsuba")
        # 0.25: an integer fraction of every canonical scene (0.125 of the 620x420 charts is refused)
        s.spp, s.scale, s.passes, s.flip, s.output_parent = 16, 0.25, 1, "OFF", {str(tmp_path)!r}
        bpy.ops.spectral_bench.run_benchmark()   # returns at once; the run goes on in the background
        job = benchmark.active_job()
        t0 = time.time()
        while job.done_jobs() < 1 and time.time() - t0 < 300:
            time.sleep(0.2)
        before = job.done_jobs()
        r = bpy.ops.spectral_bench.cancel_benchmark()
        after = run_folder.load(s.output_dir)
        rows = benchmark.result_rows(s.output_dir)
        print(json.dumps({{"before": before, "after": len(after["runs"]), "total": job.total, "r": list(r),
                          "running": job.running(), "status": s.status, "rows": len(rows),
                          "report": benchmark.report_path(s.output_dir) is not None,
                          "statuses": [r["status"] for r in after["runs"]]}}))
    """)
    assert out["r"] == ["FINISHED"] and not out["running"] and out["status"].startswith("cancelled")
    assert 1 <= out["before"] <= out["after"] < out["total"] == len(ALL_SCENES), out  # one Mitsuba job per scene
    assert out["rows"] == out["after"] and out["report"]  # the results view and report.html show what finished
    assert all(st in ("ok", "failed", "unsupported", "skipped", "unjudged", "known", "fixed") for st in out["statuses"])


@pytest.mark.slow
def test_stokes_components_load_into_images(tmp_path):
    out_dir = tmp_path / "o"
    proc = run_batch("-r", "mitsuba", "-s", "polarizing_spheres", "--scale", "0.125", "--no-flip", "-o", out_dir)
    assert (out_dir / "metrics.json").is_file(), proc.stderr[-2000:]
    out = run_bpy(f"""
        import numpy as np
        s = bpy.context.window_manager.spectral_bench_run
        s.output_dir = {str(out_dir)!r}
        loaded = {{}}
        for k in ("S0", "S1", "S2", "S3"):
            bpy.ops.spectral_bench.load_result(scene="polarizing_spheres", backend="mitsuba", kind=k)
            img = bpy.data.images["polarizing_spheres mitsuba " + k]
            w, h = img.size
            loaded[k] = np.array(img.pixels[:], dtype=np.float32).reshape(h, w, 4)[::-1, :, :3].tolist()
        print(json.dumps(loaded))
    """)
    render = out_dir / "polarizing_spheres" / "results" / "mitsuba" / "render.exr"
    for k in ("S0", "S1", "S2", "S3"):
        expected = exr.read_rgb(render, prefix=f"{k}.")
        assert np.allclose(np.array(out[k]), expected, atol=1e-6), k
    assert np.abs(expected).max() > 0  # S3 of this scene is not all zero: the comparison means something


@pytest.mark.slow
def test_backends_listed_from_the_runner_and_toggled():
    out = run_bpy("""
        from spectral_bench.addon import benchmark
        from spectral_bench.batch import backends
        s = bpy.context.window_manager.spectral_bench_run
        listed = [n for n, *_ in benchmark.backend_states(s)]
        bpy.ops.spectral_bench.toggle_backend(backend="mitsuba")
        off = benchmark.chosen_backends(s)
        bpy.ops.spectral_bench.toggle_backend(backend="mitsuba")
        on = benchmark.chosen_backends(s)
        try:
            bpy.ops.spectral_bench.toggle_backend(backend="nope")
            bad = None
        except RuntimeError as exc:
            bad = str(exc)
        print(json.dumps({"listed": listed, "known": list(backends.BACKENDS), "off": off, "on": on, "bad": bad}))
    """)
    assert out["listed"] == out["known"]
    assert "mitsuba" not in out["off"] and "mitsuba" in out["on"]
    assert "nope" in out["bad"]


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_sweep_chart_loads_into_an_image(tmp_path):
    out = tmp_path / "o"
    run_batch("-r", "mitsuba", "-s", "ggx_copper_80", "--scale", "0.0625", "--sweep", "--ladder", "4,16", "--no-flip",
              "-o", out, timeout=600)
    res = run_bpy(f"""
        s = bpy.context.window_manager.spectral_bench_run
        s.output_dir = {str(out)!r}
        r = bpy.ops.spectral_bench.load_chart(scene="ggx_copper_80")
        img = bpy.data.images["ggx_copper_80 sweep chart"]
        print(json.dumps({{"r": list(r), "size": list(img.size)}}))
    """)
    assert res["r"] == ["FINISHED"] and res["size"][0] > 100


def test_reference_search_first_usable_folder_wins(tmp_path, golden):
    """The order the extension passes folders in (the preferences' folder, then its own): a stale
    reference in the first folder is passed over for a usable one in the next, and still reported
    as stale when it is the only one; each reference's origin is named."""
    import shutil
    from spectral_bench.addon import reference_sources
    from spectral_bench.batch import cli
    from spectral_bench.batch.verdict import references
    stale = tmp_path / "stale"
    stale.mkdir()
    shutil.copy(ROOT / "references" / "ggx_copper_50.exr", stale)
    meta = json.loads((ROOT / "references" / "ggx_copper_50.json").read_text())
    (stale / "ggx_copper_50.json").write_text(json.dumps(dict(meta, fingerprint="0" * 64)))
    scene = golden["ggx_copper_50"]
    search = reference_sources.folders("BOTH", stale)
    assert [o for o, _ in search] == ["folder", "extension"]
    used = references.load("ggx_copper_50", [f for _, f in search], scene=scene)
    assert used.path == references.REFERENCE_DIR / "ggx_copper_50.exr" and references.check_usable(used, scene) is None
    assert reference_sources.origin_of(used.path, search) == "extension"
    only = references.load("ggx_copper_50", [stale], scene=scene)
    assert only.path == stale / "ggx_copper_50.exr" and "stale" in references.check_usable(only, scene)
    assert reference_sources.origin_of(only.path, search) == "folder"
    assert references.load("ggx_copper_50", [tmp_path / "empty"], scene=scene) is None
    assert reference_sources.folders("FOLDER", None) == [] and reference_sources.folders("EXTENSION", stale) == [
        ("extension", references.REFERENCE_DIR)]
    catalog = reference_sources.catalog(search)
    assert [r["origin"] for r in catalog["ggx_copper_50"]] == ["folder", "extension"]
    assert cli.parse(["--references", "a", "--references", "b"])["references"] == ["a", "b"]


def test_references_save_noise_as_half_and_mean_exactly(tmp_path, golden):
    """What the extension ships: the mean bit for bit as float32, the standard error as half (float32
    where a value does not fit in half)."""
    import OpenEXR
    from spectral_bench.batch.verdict import references
    rng = np.random.default_rng(3)
    mean = rng.random((8, 8, 3)).astype(np.float32)
    stderr = (1e-3 + rng.random((8, 8, 3)) * 1e-2).astype(np.float32)  # within half's normal range
    scene = golden["ggx_copper_50"]
    for name, err, want in (("small", stderr, OpenEXR.HALF), ("huge", stderr * 1e7, OpenEXR.FLOAT)):
        folder = tmp_path / name
        path = references.save(scene, ["R", "G", "B"], mean, err, {"spp": 4, "passes": 8}, folder)
        with OpenEXR.File(str(path), separate_channels=True) as f:
            types = {n: c.pixels.dtype for n, c in f.channels().items()}
        assert all(types[c] == np.float32 for c in "RGB")
        assert all(types[f"stderr.{c}"] == (np.float16 if want == OpenEXR.HALF else np.float32) for c in "RGB")
        ref = references.load(scene["name"], folder, scene=scene)
        assert np.array_equal(ref.mean, mean) and references.check_usable(ref, scene) is None
        assert np.allclose(ref.stderr, err, rtol=2 ** -11, atol=0)
