"""Declared renderers in the Blender panel (issue 19, deliverable 1): the renderers files kept in
the extension's preferences, every renderer they declare listed with what it reads, writes and
models and its availability, chosen like a built-in backend, and passed to the runner as
``--renderers FILE -r NAME``. A broken file is one error line naming it, never a traceback.

The extension is registered in a child Python with bpy (tests/conftest.py run_bpy); its
preferences are made to exist as Blender does when it enables an add-on (``addons.new()``), so the
tests use the real, saved property. Panels are drawn through tests/layout_recorder.py."""
import json

import pytest

import test_extension as ext
from conftest import ROOT, run_bpy
from test_extension import extension_zip  # noqa: F401 - the fixture: the extension built without wheels

pytestmark = pytest.mark.slow  # every test here costs over ~1 s of CPU, its children and module fixtures counted (benchmarks/TESTS.md)

TESTS = str(ROOT / "tests")
TOY = ROOT / "examples" / "your_renderer" / "toy.toml"
TOY_SCRIPT = ROOT / "examples" / "your_renderer" / "toy_renderer.py"

# the extension's preferences, as Blender makes them when it enables the add-on; and a panel drawn
PRELUDE = f"""
    sys.path.insert(0, {TESTS!r})
    import layout_recorder as lr
    from spectral_bench.addon import benchmark, preferences
    bpy.context.preferences.addons.new().module = preferences.ROOT_PACKAGE
    prefs = preferences.settings()
    assert not isinstance(prefs, preferences.Defaults)
    s = bpy.context.window_manager.spectral_bench_run

    def add(*paths):
        for p in paths:
            prefs.renderers_files.add().path = p

    def panel():
        calls = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark, lr.Context())
        return {{
            "labels": [[c[2].get("text"), c[2].get("icon")] for c in calls if c[1] == "label"],
            "toggles": {{c[2]["properties"]["backend"]: [c[2]["text"], c[2]["icon"]] for c in calls
                        if c[1] == "operator" and c[2]["operator"] == "spectral_bench.toggle_backend"}},
            "disabled": [i for i, c in enumerate(calls) if c[1] == "set enabled" and c[2]["value"] is False],
            "calls": len(calls),
        }}
"""


def _ghost(tmp_path):
    """A renderers file declaring a renderer whose program is not there, with a description that
    tries to break the panel's line (newlines, a control character)."""
    path = tmp_path / "ghost.toml"
    path.write_text('[renderers.ghost]\n'
                    'description = "line one\\nline two\\u0007 end"\n'
                    'command = ["/nonexistent/ghost_renderer", "{scene}", "{output}", "{spp}", "{seed}"]\n'
                    'reads = "json"\nwrites = "spectral"\nmodels = ["spectral", "polarization"]\n'
                    'groups = ["spectral"]\n')
    return path


def test_panel_lists_declared_renderers_with_what_they_do_and_their_availability(tmp_path):
    ghost = _ghost(tmp_path)
    out = run_bpy(PRELUDE + f"""
    before = panel()
    add({str(TOY)!r}, {str(ghost)!r})
    after = panel()
    declared = benchmark.declared_renderers(preferences.renderers_files())["renderers"]
    on = {{n: on for n, _ok, _why, on, _decl in benchmark.declared_states(s, declared)}}
    r = bpy.ops.spectral_bench.toggle_backend(backend="toy")
    chosen = panel()["toggles"]
    print(json.dumps({{"before": before, "after": after, "r": list(r), "chosen": chosen, "toggled": s.declared_toggled,
                      "on": on}}))
    """)
    assert not [k for k in out["before"]["toggles"] if k.startswith(("toy", "ghost"))]
    assert ["Declared Renderers: none", None] in out["before"]["labels"]
    after, labels = out["after"], [t for t, _icon in out["after"]["labels"]]
    # toy and toy_spectral run here ({python} is this interpreter): available, off until chosen
    assert after["toggles"]["toy"] == ["toy", "CHECKBOX_DEHLT"]
    assert after["toggles"]["toy_spectral"] == ["toy_spectral", "CHECKBOX_DEHLT"]
    assert "stand-alone example: Mitsuba 3 behind a command line, RGB output " \
           "(reads mitsuba, writes rgb, models spectral)" in labels
    assert any(t.endswith("(reads mitsuba, writes spectral, models spectral)") for t in labels)
    assert [f"{TOY}: toy, toy_spectral", "FILE"] in after["labels"]
    # ghost is listed, disabled, with the reason availability() gives (program, file that declared it)
    text, icon = after["toggles"]["ghost"]
    assert text.startswith("ghost: program '/nonexistent/ghost_renderer' not found") and str(ghost) in text, text
    assert icon == "CHECKBOX_DEHLT" and len(after["disabled"]) == len(out["before"]["disabled"]) + 1
    assert "line one line two  end (reads json, writes spectral, models polarization, spectral)" in labels
    assert all("\n" not in t and "\x07" not in t for t in labels if t)
    # chosen like a built-in backend; by default as the command line's default -r (the group spectral)
    assert out["on"] == {"toy": False, "toy_spectral": False, "ghost": True}
    assert out["r"] == ["FINISHED"] and out["toggled"] == "toy"
    assert out["chosen"]["toy"] == ["toy", "CHECKBOX_HLT"] and out["chosen"]["toy_spectral"][1] == "CHECKBOX_DEHLT"


def test_a_bad_declaration_file_is_an_error_line_naming_the_file_and_the_rest_works(tmp_path):
    bad_key = tmp_path / "bad_key.toml"
    bad_key.write_text(TOY.read_text().replace("reads = \"mitsuba\"\nwrites = \"rgb\"",
                                               "reads = \"mitsuba\"\nwrites = \"rgb\"\nspp = 4", 1))
    not_toml = tmp_path / "not_toml.toml"
    not_toml.write_text("[renderers.x\ncommand = \n")
    hostile = tmp_path / "hostile.toml"  # a name that is a path and one that is an option
    hostile.write_text('[renderers."../../evil"]\ncommand = ["x", "{scene}", "{output}", "{spp}", "{seed}"]\n'
                       'reads = "json"\nmodels = []\n')
    option = tmp_path / "option.toml"
    option.write_text('[renderers."-o"]\ncommand = ["x", "{scene}", "{output}", "{spp}", "{seed}"]\n'
                      'reads = "json"\nmodels = []\n')
    twice = tmp_path / "twice.toml"  # toy again, declared differently: the runner would refuse both
    twice.write_text(TOY.read_text().replace("timeout = 600", "timeout = 60", 1))
    missing = tmp_path / "missing.toml"
    out = run_bpy(PRELUDE + f"""
    add({str(bad_key)!r}, {str(TOY)!r}, {str(not_toml)!r}, {str(hostile)!r}, {str(option)!r}, {str(twice)!r},
        {str(missing)!r})
    drawn = panel()
    try:
        bpy.ops.spectral_bench.toggle_backend(backend="../../evil")
        evil = None
    except RuntimeError as exc:
        evil = str(exc)
    print(json.dumps({{"drawn": drawn, "evil": evil}}))
    """)
    errors = [t for t, icon in out["drawn"]["labels"] if icon == "ERROR"]
    assert len(errors) == 6, errors
    expect = {bad_key: "unknown key 'spp'", not_toml: "renderers file", hostile: "'/' is not allowed",
              option: "must not start with '.' or '-'", twice: "renderer 'toy' is declared twice",
              missing: "No such file"}
    for path, problem in expect.items():
        assert any(str(path) in e and problem in e for e in errors), (path, problem, errors)
    assert all(len(e) <= 200 for e in errors)
    toggles = out["drawn"]["toggles"]
    assert toggles["toy"] == ["toy", "CHECKBOX_DEHLT"] and "toy_spectral" in toggles  # the good file still works
    assert not [n for n in toggles if "evil" in n or n == "-o"]
    assert "mitsuba" in toggles and out["drawn"]["calls"] > 20  # the whole panel drew, Run button and all
    assert "../../evil" in out["evil"] and "unknown backend" in out["evil"]


def test_run_command_line_holds_every_renderers_file_and_the_chosen_renderer(tmp_path):
    """The operator starts batch/run.py with an argv list: every usable renderers file as
    --renderers FILE (absolute, one item even with spaces and shell characters in its path), the
    chosen renderer as -r NAME; the broken file is left out; the runner's parser accepts it."""
    folder = tmp_path / "my renderers; $(touch pwned)"
    folder.mkdir()
    mine = folder / "mine.toml"
    mine.write_text(TOY.read_text().replace("{here}/toy_renderer.py", str(TOY_SCRIPT))
                    .replace("[renderers.toy]", "[renderers.mine]").replace("[renderers.toy_spectral]",
                                                                            "[renderers.mine_spectral]"))
    broken = tmp_path / "broken.toml"
    broken.write_text("[renderers.b]\n")
    out = run_bpy(PRELUDE + f"""
    from spectral_bench.batch import backends
    add({str(TOY)!r}, {str(broken)!r}, {str(mine)!r})
    s.backends_off = ",".join(backends.BACKENDS)  # built-ins off: only the declared renderer runs
    s.scene_source, s.spp, s.scale, s.passes, s.output_parent = "ACTIVE", 4, 0.0625, 2, {str(tmp_path / "out")!r}
    bpy.ops.spectral_bench.toggle_backend(backend="toy")
    with bpy.context.temp_override(scene=bpy.data.scenes["ggx_copper_80"]):
        r = bpy.ops.spectral_bench.run_benchmark()
    job = benchmark.active_job()
    cmd = list(job.cmd)
    benchmark.cancel_run(bpy.context)
    print(json.dumps({{"r": list(r), "cmd": cmd, "total": job.total, "left_out": job.renderers_problems}}))
    """)
    cmd = out["cmd"]
    assert out["r"] == ["FINISHED"] and out["total"] == 1
    assert cmd[1] == str(ROOT / "batch" / "run.py")

    def has(seq):
        return any(cmd[i:i + len(seq)] == seq for i in range(len(cmd)))
    assert has(["--renderers", str(TOY), "--renderers", str(mine), "-r", "toy"]), cmd
    assert str(broken) not in cmd and cmd.count("-r") == 1
    assert len(out["left_out"]) == 1 and str(broken) in out["left_out"][0]  # reported as a warning
    assert not (tmp_path / "pwned").exists() and not (folder / "pwned").exists()
    # the runner reads the same command line (its parser, its declarations)
    from spectral_bench.batch import cli
    opts = cli.parse(cmd[2:])
    assert opts["renderer"] == ["toy"] and sorted(opts["renderers"]) == ["mine", "mine_spectral", "toy", "toy_spectral"]


def test_renderers_files_are_added_and_removed_in_the_preferences(tmp_path):
    out = run_bpy(PRELUDE + f"""
    r1 = bpy.ops.spectral_bench.add_renderers_file(filepath={str(TOY)!r})
    r2 = bpy.ops.spectral_bench.add_renderers_file(filepath={str(TOY)!r})  # listed already: once
    listed = [str(p) for p in preferences.renderers_files()]
    drawn = lr.draw(type(prefs), lr.Context(), instance=prefs)
    try:
        bpy.ops.spectral_bench.remove_renderers_file(index=5)
        bad = None
    except RuntimeError as exc:
        bad = str(exc)
    r3 = bpy.ops.spectral_bench.remove_renderers_file(index=0)
    print(json.dumps({{"r": [list(r1), list(r2), list(r3)], "listed": listed, "bad": bad,
                      "after": [str(p) for p in preferences.renderers_files()],
                      "ops": [c[2]["operator"] for c in drawn if c[1] == "operator"]}}))
    """)
    assert out["r"] == [["FINISHED"]] * 3
    assert out["listed"] == [str(TOY)] and out["after"] == []
    assert "position 5" in out["bad"]
    assert out["ops"][:2] == ["spectral_bench.remove_renderers_file", "spectral_bench.add_renderers_file"]


@pytest.mark.slow
def test_declared_renderer_chosen_in_the_panel_renders_and_is_judged(tmp_path):
    out = run_bpy(PRELUDE + f"""
    from spectral_bench.batch import backends
    add({str(TOY)!r})
    s.backends_off = ",".join(backends.BACKENDS)
    s.scene_source, s.spp, s.scale, s.passes, s.output_parent = "ACTIVE", 64, 0.125, 2, {str(tmp_path)!r}
    bpy.ops.spectral_bench.toggle_backend(backend="toy")
    with bpy.context.temp_override(scene=bpy.data.scenes["ggx_copper_80"]):
        r = bpy.ops.spectral_bench.run_benchmark(wait=True)
    print(json.dumps({{"r": list(r), "status": s.status, "out": s.output_dir}}))
    """)
    assert out["r"] == ["FINISHED"], out
    runs = json.loads(open(f"{out['out']}/metrics.json").read())["runs"]
    assert [(r["scene"], r["backend"]) for r in runs] == [("ggx_copper_80", "toy")]
    assert runs[0]["status"] == "ok", runs[0].get("reason")
    assert out["status"].startswith("passed: 1/1 jobs"), out["status"]


@pytest.mark.slow
def test_installed_extension_keeps_renderers_files_with_blenders_preferences(extension_zip, tmp_path):
    """Installed as a user installs it: a renderers file added with the operator is saved with
    Blender's preferences, read back in a new process, and its renderers are in the panel."""
    zip_path = extension_zip
    user = tmp_path / "user"
    first = ext.run_bpy(ext.script(ext.install(zip_path), f"""
        r = bpy.ops.spectral_bench.add_renderers_file(filepath={str(TOY)!r})
        saved = bpy.ops.wm.save_userpref()
        print(json.dumps({{"r": list(r), "saved": list(saved)}}))
    """), user)
    assert first == {"r": ["FINISHED"], "saved": ["FINISHED"]}
    second = ext.run_bpy(f"""
        import json, sys, bpy
        sys.path.insert(0, {TESTS!r})
        import layout_recorder as lr
        bpy.ops.wm.read_userpref()
        from {ext.MODULE}.addon import preferences
        calls = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark, lr.Context())
        print(json.dumps({{"files": [str(p) for p in preferences.renderers_files()],
                          "toggles": [c[2]["properties"]["backend"] for c in calls if c[1] == "operator"
                                      and c[2]["operator"] == "spectral_bench.toggle_backend"]}}))
    """, user)
    assert second["files"] == [str(TOY)]
    assert {"toy", "toy_spectral", "mitsuba"} <= set(second["toggles"])
