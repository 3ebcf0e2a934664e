""".blend files run nothing in the runner or the extension, even with Blender's Auto Run preference on.

A hostile .blend (built here with real bpy) carries a text block registered as a module (run when
the file is opened with Auto Run on; it writes a marker and registers a driver function) and three
drivers whose scripted expressions need Python: one calls the text block's function, one calls
``__import__`` directly (Blender's simple-expression evaluator cannot run it, Python does), one on a
world's embedded node tree. Each writes its own marker file.

Every child process switches Auto Run on (``preferences.filepaths.use_scripts_auto_execute``), as a
user who trusts their own files would have it. First the file is shown to be live: a plain open
writes every marker, and so does a plain library load (append) once the scene is evaluated. Then
the runner (``batch/run.py -i evil.blend --export-only``) and the extension (canonical scenes listed,
extracted for a run, appended and evaluated, opened) read the same file and write no marker; a
control at the end of the extension's process, a plain append again, writes one (Auto Run was on
the whole time).
"""
import json
import subprocess
import sys
import textwrap

import pytest

from conftest import ALL_SCENES, ROOT

pytestmark = pytest.mark.slow  # every test here costs over ~1 s of CPU, its children and module fixtures counted (benchmarks/TESTS.md)

SCENE = "ggx_copper_50"
MARKERS = {"text", "driver_namespace", "driver_import", "driver_node_tree"}


def run_child(code, timeout=300, auto_run=True):
    """Run ``code`` in a child Python with bpy and the package importable, Auto Run switched on
    first (``auto_run``); returns the JSON its last printed line holds."""
    prelude = textwrap.dedent(f"""
        import json, os, sys
        sys.path.insert(0, {str(ROOT)!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        import bpy
        bpy.context.preferences.filepaths.use_scripts_auto_execute = {auto_run!r}  # the user's preference
    """)
    proc = subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def evil_blend(tmp_path_factory):
    """(the hostile .blend, its marker folder): canonical scene SCENE plus the code it carries;
    built once for the module (a bpy child), read by every test (none writes to it)."""
    tmp_path = tmp_path_factory.mktemp("evil")
    markers = tmp_path / "markers"
    markers.mkdir()
    blend = tmp_path / "evil.blend"
    text = textwrap.dedent(f"""
        import bpy, pathlib
        MARKERS = pathlib.Path({str(markers)!r})
        (MARKERS / "text").touch()
        def evil_driver(x):
            (MARKERS / "driver_namespace").touch()
            return x
        bpy.app.driver_namespace["evil_driver"] = evil_driver
    """)
    run_child(f"""
        with bpy.data.libraries.load({str(ROOT / "scenes.blend")!r}, link=False) as (src, dst):
            dst.scenes = [{SCENE!r}]
        scene = dst.scenes[0]
        for other in [s for s in bpy.data.scenes if s != scene]:
            bpy.data.scenes.remove(other)
        block = bpy.data.texts.new("evil.py")
        block.write({text!r})
        block.use_module = True
        def python_driver(owner, path, expression):
            fcurve = owner.driver_add(path)
            fcurve.driver.type = "SCRIPTED"
            fcurve.driver.expression = expression
            assert not fcurve.driver.is_simple_expression
        scene["evil_namespace"] = 0.0
        python_driver(scene, '["evil_namespace"]', "evil_driver(frame)")
        camera = scene.camera
        camera["evil_import"] = 0.0
        touch = "__import__('pathlib').Path({str(markers)!r})"
        python_driver(camera, '["evil_import"]', touch + " .joinpath('driver_import').touch() or frame")
        if scene.world is None:
            scene.world = bpy.data.worlds.new("evil world")
        scene.world.use_nodes = True
        tree = scene.world.node_tree
        tree["evil"] = 0.0
        python_driver(tree, '["evil"]', touch + " .joinpath('driver_node_tree').touch() or frame")
        bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})
        print(json.dumps(sorted(os.listdir({str(markers)!r}))))
    """, auto_run=False)
    assert not any(markers.iterdir())  # building it ran nothing
    return blend, markers


@pytest.fixture
def evil(evil_blend):
    """The module's hostile .blend with its marker folder emptied: each test sees only the markers
    its own children write."""
    blend, markers = evil_blend
    for marker in markers.iterdir():
        marker.unlink()
    return blend, markers


def test_the_hostile_blend_runs_its_code_when_opened_or_appended_plainly(evil):
    """The file is live: with Auto Run on, Blender's plain open runs the text block and every
    driver, and a plain append runs the drivers that need no text block once the scene is evaluated."""
    blend, markers = evil
    opened = run_child(f"""
        bpy.ops.wm.open_mainfile(filepath={str(blend)!r}, load_ui=False)
        bpy.context.scene.frame_set(2)
        print(json.dumps(sorted(os.listdir({str(markers)!r}))))
    """)
    assert set(opened) == MARKERS
    for m in markers.iterdir():
        m.unlink()
    appended = run_child(f"""
        with bpy.data.libraries.load({str(blend)!r}, link=False) as (src, dst):
            dst.scenes = [{SCENE!r}]
        dst.scenes[0].frame_set(2)
        print(json.dumps(sorted(os.listdir({str(markers)!r}))))
    """)
    assert set(appended) == {"driver_import", "driver_node_tree"}


def test_the_runner_reads_a_hostile_blend_without_running_it(evil, tmp_path):
    blend, markers = evil
    out = tmp_path / "out"
    result = run_child(f"""
        import runpy
        sys.argv = ["run.py", "-i", {str(blend)!r}, "--export-only", "-o", {str(out)!r}]
        try:
            runpy.run_path({str(ROOT / "batch" / "run.py")!r}, run_name="__main__")
        except SystemExit as exc:
            code = exc.code
        else:
            code = 0
        bpy.context.scene.frame_set(3)  # whatever is evaluated later runs nothing either
        print(json.dumps({{"code": code, "markers": sorted(os.listdir({str(markers)!r}))}}))
    """)
    assert result["markers"] == []
    assert result["code"] in (0, None)
    exported = json.loads(next(out.rglob(f"{SCENE}.json")).read_text())  # the scene itself is read
    assert exported["name"] == SCENE


def test_the_extension_lists_runs_appends_and_opens_a_hostile_canonical_file_without_running_it(evil):
    """The extension's canonical scenes pointed at the hostile file: listed, extracted for a run
    (the panel's scenes_to_run), appended (and the appended scene evaluated, as the window does
    when it shows it) and opened through the operators. Nothing runs; the append reports what it
    removed; a plain append in the same process afterwards does run a driver (Auto Run was on)."""
    blend, markers = evil
    result = run_child(f"""
        from pathlib import Path
        from spectral_bench import register
        register()
        from spectral_bench.addon import benchmark, canonical
        from spectral_bench.exporters import validate
        canonical.BLEND = Path({str(blend)!r})
        listed = canonical.scene_names()
        s = bpy.context.window_manager.spectral_bench_run
        s.scene_source, s.canonical_scene = "CANONICAL", canonical.ALL
        to_run = benchmark.scenes_to_run(bpy.context, s)
        extracted = {{n: (r["name"] if isinstance(r, dict) else str(r)) for n, r in to_run}}
        appended = bpy.ops.spectral_bench.append_canonical_scene(scene={SCENE!r})
        new = [sc for sc in bpy.data.scenes if sc.name.startswith({SCENE!r})]
        for sc in new:
            sc.frame_set(2)
        left = [f.driver.expression for sc in new for owner in (sc, sc.camera, sc.world.node_tree)
                if owner.animation_data for f in owner.animation_data.drivers]
        after_append = sorted(os.listdir({str(markers)!r}))
        bpy.context.preferences.filepaths.use_scripts_auto_execute = True
        opened = bpy.ops.spectral_bench.open_canonical_scenes()
        bpy.context.scene.frame_set(3)
        after_open = sorted(os.listdir({str(markers)!r}))
        bpy.context.preferences.filepaths.use_scripts_auto_execute = True
        with bpy.data.libraries.load({str(blend)!r}, link=False) as (src, dst):
            dst.scenes = [{SCENE!r}]
        dst.scenes[0].frame_set(4)
        control = sorted(os.listdir({str(markers)!r}))
        print(json.dumps({{"listed": listed, "extracted": extracted, "appended": list(appended), "left": left,
                          "after_append": after_append, "opened": list(opened), "scene": bpy.context.scene.name,
                          "after_open": after_open, "control": control}}))
    """)
    assert result["after_append"] == [] and result["after_open"] == []
    assert result["listed"] == [SCENE] and result["extracted"] == {SCENE: SCENE}
    assert result["appended"] == ["FINISHED"] and result["left"] == []
    assert result["opened"] == ["FINISHED"] and result["scene"] == SCENE
    assert set(result["control"]) == {"driver_import", "driver_node_tree"}


def test_reading_a_blend_registers_only_the_annotation_properties():
    """batch/blend_input.py registers what the extraction reads, nothing of the UI: no operator,
    panel or preference of the extension exists after reading scenes.blend headless (which holds
    every canonical scene: conftest's list, not a count to keep in step by hand)."""
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    code = (f"import sys, json; sys.path.insert(0, {str(root)!r}); import pkg_bootstrap; pkg_bootstrap.package(); "
            "import bpy; from spectral_bench.batch import blend_input; "
            f"n = len(blend_input.load_blend({str(root / 'scenes.blend')!r})); "
            "print(json.dumps({'scenes': n, 'props': hasattr(bpy.types.Scene, 'spectral_bench'), "
            "'ops': [n for n in dir(bpy.types) if n.startswith('SPECTRAL_BENCH_OT')], "
            "'panels': [n for n in dir(bpy.types) if n.startswith('SPECTRAL_BENCH_PT')]}))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["scenes"] == len(ALL_SCENES) and out["props"] is True
    assert out["ops"] == [] and out["panels"] == []
