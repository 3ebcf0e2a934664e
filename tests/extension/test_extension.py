"""The extension as a user gets it: validated by Blender's own validator, built by
scripts/build_extension.py (scenes.blend and the references inside), installed into a throwaway
Blender user folder (BLENDER_USER_RESOURCES in a temporary folder, so nothing reaches the user's
real configuration), then used: the canonical scenes opened from the installed copy, one scene
run through the panel's operator and judged against a reference shipped in the extension, every
panel drawn, the references folder preference saved with Blender's preferences and used, and the
platform zip built by the README's command (in a copy of the repository), with margin under the
platform's size limit, its size recorded in README.md, and sufficient on its own to run the benchmark.

Each test runs in child processes (bpy has one global state per process). Building the zip with
wheels is slow (it downloads them on first use, into build/wheels/): it happens once per session,
for one test (slow); the others install the zip without wheels (the test venv provides the packages).
"""
import importlib.util
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import textwrap
import zipfile

import pytest

from conftest import ROOT, metrics

TESTS = str(ROOT / "tests")
MODULE = "bl_ext.user_default.spectral_bench"
SITE = "extensions/.local/lib/python3.11/site-packages"  # where Blender installs an extension's wheels


def _build_script():
    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def script(*parts):
    return "\n".join(textwrap.dedent(p) for p in parts)


def run_bpy(code, user_dir, timeout=600, env=None):
    """Run ``code`` with bpy in a child Python whose Blender user folder is ``user_dir``; returns the
    JSON its last printed line holds."""
    environ = dict(os.environ, BLENDER_USER_RESOURCES=str(user_dir), **(env or {}))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=environ)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def install(zip_path):
    """Code that installs and enables ``zip_path`` and binds the installed package's modules."""
    return textwrap.dedent(f"""
        import json, os, sys, time, bpy, addon_utils
        sys.path.insert(0, {TESTS!r})
        import layout_recorder as lr
        installed = bpy.ops.extensions.package_install_files(filepath={str(zip_path)!r}, repo="user_default",
                                                             enable_on_install=True)
        EXT_DIR = os.path.dirname(sys.modules[{MODULE!r}].__file__)
        from {MODULE}.addon import benchmark, canonical, preferences
        from {MODULE}.batch import backends
        s = bpy.context.window_manager.spectral_bench_run
        s.backends_off = ",".join(n for n in backends.BACKENDS if n != "mitsuba")  # these tests judge Mitsuba
    """)


def draw_everything():
    """Code that draws every panel of the installed extension and its real preferences."""
    return textwrap.dedent(f"""
        drawn = {{}}
        context_sets = [dict(scene=sc, object=ob, material=ob.active_material if ob else None)
                        for sc in bpy.data.scenes for ob in list(sc.objects) + [None]]
        for p in lr.registered_panels({MODULE!r}):
            drawn[p.__name__] = sum(lr.draw(p, lr.Context(**c)) is not None for c in context_sets)
        addon = bpy.context.preferences.addons[{MODULE!r}]
        pref_calls = lr.draw(type(addon.preferences), lr.Context(), instance=addon.preferences)
        pref_labels = [c[2].get("text") for c in pref_calls if c[1] == "label"]
    """)


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory):
    """The extension without wheels (code, scenes.blend, every reference), built once."""
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--no-wheels", "--out",
                           str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    (zip_path,) = out.glob("spectral_bench-*.zip")
    return zip_path


DOCUMENTED_BUILD = [".venv/bin/python", "scripts/build_extension.py", "--platform", "linux-x64"]  # README, "Install"


def readme_sizes(text):
    """{platform: recorded MB} of README.md's extension-size block."""
    block = _build_script().README_BLOCK.search(text)
    assert block is not None, "README.md lacks its <!-- extension-size --> block"
    return {m[0]: float(m[1]) for m in re.findall(r"^- ([\w-]+): ([\d.]+) MB", block.group(2), re.M)}


@pytest.fixture(scope="session")
def platform_build(tmp_path_factory):
    """The README's build command, exactly, run in a copy of the repository (so that the README it
    rewrites is the copy's); its wheel cache is this checkout's build/wheels. Returns the copy."""
    if sys.platform != "linux" or platform.machine() != "x86_64":
        pytest.skip("the platform build is checked on linux-x64 only (its wheels must run here)")
    build = _build_script()
    clone = tmp_path_factory.mktemp("clone") / "spectral_bench"
    shutil.copytree(ROOT, clone, ignore=build.IGNORE)
    os.symlink(sys.prefix, clone / ".venv")
    build.WHEEL_CACHE.mkdir(parents=True, exist_ok=True)
    (clone / "build").mkdir()
    os.symlink(build.WHEEL_CACHE, clone / "build" / "wheels")
    proc = subprocess.run(DOCUMENTED_BUILD, cwd=clone, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return clone


@pytest.fixture(scope="session")
def platform_zip(platform_build):
    """The extension for this platform with every wheel (what would be uploaded), built once."""
    (zip_path,) = (platform_build / "dist").glob("spectral_bench-*.zip")
    return zip_path


def test_size_record_keeps_other_platforms_and_the_text_around(tmp_path):
    build = _build_script()
    readme = tmp_path / "README.md"
    readme.write_text("before\n<!-- extension-size -->\n- windows-x64: 98.7 MB: old\n- linux-x64: 1.0 MB: old\n"
                      "<!-- /extension-size -->\nafter\n")
    assert build.record_size("linux-x64", "149.2 MB: new", readme)
    assert build.record_size("macos-arm64", "95.1 MB: new", readme)
    assert readme.read_text() == ("before\n<!-- extension-size -->\n- linux-x64: 149.2 MB: new\n"
                                  "- macos-arm64: 95.1 MB: new\n- windows-x64: 98.7 MB: old\n"
                                  "<!-- /extension-size -->\nafter\n")
    assert readme_sizes(readme.read_text()) == {"linux-x64": 149.2, "macos-arm64": 95.1, "windows-x64": 98.7}


def test_default_references_exist_and_every_case_keeps_one(golden):
    """The shipped subset names real references, and no case is left without one."""
    build = _build_script()
    assert set(build.DEFAULT_REFERENCES) <= {p.stem for p in (ROOT / "references").glob("*.exr")}
    assert {golden[n]["case"] for n in build.DEFAULT_REFERENCES} == {scene["case"] for scene in golden.values()}


def test_staged_references_keep_dotted_scene_names_and_only_their_own_layers(tmp_path):
    """The extension's copy of references/ (issue 40): a scene name may hold dots, so a scene's files
    are <scene>.exr, <scene>.json and layers/<scene>/, never "everything before the first dot";
    the layers of scenes left out go, and only EXTENSION_LAYERS' stay (files and record entries).
    The real references, linked into a staged folder, with a copy of one named with dots."""
    build = _build_script()
    folder = tmp_path / "stage" / "references"
    link_images = lambda src, dst: os.link(src, dst) if src.endswith(".exr") else shutil.copy2(src, dst)  # noqa: E731
    shutil.copytree(ROOT / "references", folder, copy_function=link_images, ignore=shutil.ignore_patterns(".work", "history"))
    dotted = "ggx_copper_50.mitsuba3"  # a scene named like the old layer file of ggx_copper_50
    shutil.copy(folder / "ggx_copper_50.exr", folder / f"{dotted}.exr")
    meta = json.loads((folder / "ggx_copper_50.json").read_text())
    (folder / f"{dotted}.json").write_text(json.dumps(dict(meta, scene=dotted, observer_layers={})))
    shipped, every = build.select_references(tmp_path / "stage", f"ggx_copper_50,{dotted}")
    assert shipped == sorted(["ggx_copper_50", dotted]) and dotted in every and "ggx_copper_50" in every
    assert sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()) == sorted(
        ["ggx_copper_50.exr", "ggx_copper_50.json", f"{dotted}.exr", f"{dotted}.json",
         *[f"layers/ggx_copper_50/{o}.exr" for o in build.EXTENSION_LAYERS]])
    kept = json.loads((folder / "ggx_copper_50.json").read_text())["observer_layers"]
    assert set(kept) == set(build.EXTENSION_LAYERS)
    assert all((folder / item["file"]).is_file() for item in kept.values())
    zipped = zipfile.ZipFile(build.write_references_zip(tmp_path, "0", ["ggx_copper_50"])).namelist()
    assert sorted(zipped) == sorted(f"spectral_bench_references/{n}" for n in
                                    ["ggx_copper_50.json", "ggx_copper_50.exr",
                                     *[f"layers/ggx_copper_50/{o}" for o in os.listdir(ROOT / "references" / "layers" / "ggx_copper_50")]])


@pytest.mark.slow
def test_the_documented_build_fits_with_margin_records_its_size_and_ships_every_reference_beside(platform_build):
    """The README's command: a zip within SIZE_TARGET_MB (margin under the platform's limit), its
    measured size written into the copy's README.md (and the committed README agrees with it to
    within 1 MB), the default references inside and every reference in the zip beside it."""
    import zipfile
    build = _build_script()
    (zip_path,) = (platform_build / "dist").glob("spectral_bench-*.zip")
    size_mb = zip_path.stat().st_size / 1e6
    assert size_mb <= build.SIZE_TARGET_MB < build.PLATFORM_LIMIT_MB
    recorded = readme_sizes((platform_build / "README.md").read_text())
    assert recorded["linux-x64"] == round(size_mb, 1)
    committed = readme_sizes((ROOT / "README.md").read_text())
    assert abs(committed["linux-x64"] - size_mb) <= 1.0, (committed, size_mb)
    names = zipfile.ZipFile(zip_path).namelist()
    shipped = [n[len("references/"):-4] for n in names if n.startswith("references/") and n.endswith(".exr")]
    assert sorted(n for n in shipped if "/" not in n) == sorted(build.DEFAULT_REFERENCES)
    # the observer layers of EXTENSION_LAYERS only, each in layers/<scene>/ and listed in its record
    layers = sorted(n for n in shipped if "/" in n)
    assert layers and {n.split("/")[2] for n in layers} == set(build.EXTENSION_LAYERS)
    with zipfile.ZipFile(zip_path) as z:
        for n in layers:
            _folder, scene, obs = n.split("/")
            assert set(json.loads(z.read(f"references/{scene}.json"))["observer_layers"]) == {obs}, n
    (refs,) = (platform_build / "dist").glob("spectral_bench_references-*.zip")
    folder = ROOT / "references"
    every = sorted([p.name for p in folder.iterdir() if p.suffix in (".exr", ".json")]
                   + [p.relative_to(folder).as_posix() for p in (folder / "layers").glob("*/*.exr")])
    assert sorted(n.split("/", 1)[1] for n in zipfile.ZipFile(refs).namelist()) == every




@pytest.fixture(scope="module")
def manifest_checks(tmp_path_factory):
    """Blender's own extension validator (bl_pkg's ``validate``) on the repository and on a copy of
    its manifest with a bad id, both in one bpy child: {"repository": exit code, "broken": exit code}."""
    tmp_path = tmp_path_factory.mktemp("manifests")
    src = tmp_path / "ext"
    src.mkdir()
    (src / "__init__.py").write_text("def register(): pass\ndef unregister(): pass\n")
    text = (ROOT / "blender_manifest.toml").read_text().replace('id = "spectral_bench"', 'id = "spectral bench!"')
    (src / "blender_manifest.toml").write_text(text)
    return run_bpy(f"""
        import json, bpy
        from bl_pkg import bl_extension_cli
        print(json.dumps({{"repository": bl_extension_cli.cli_extension_handler(["validate", {str(ROOT)!r}]),
                          "broken": bl_extension_cli.cli_extension_handler(["validate", {str(src)!r}])}}))
    """, tmp_path / "user")


def test_repository_manifest_validates(manifest_checks):
    assert manifest_checks["repository"] == 0


def test_manifest_rejected_when_broken(manifest_checks):
    """The validator is a real check: a manifest with a bad field fails it."""
    assert manifest_checks["broken"] != 0


@pytest.mark.slow
def test_install_enable_export_unregister(extension_zip, tmp_path):
    import zipfile
    names = zipfile.ZipFile(extension_zip).namelist()
    assert "scenes.blend" in names and "references/ggx_copper_50.exr" in names and "references/ggx_copper_50.json" in names
    assert not any(n.startswith(("tests/", "golden/", "benchmarks/", "scripts/")) for n in names)
    out = run_bpy(script(install(extension_zip), f"""
        enabled = {MODULE!r} in bpy.context.preferences.addons
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
        exported = bpy.ops.spectral_bench.export_json(filepath={str(tmp_path / "exported.json")!r})
        mitsuba = bpy.ops.spectral_bench.export_mitsuba(filepath={str(tmp_path / "mitsuba_export")!r})
        addon_utils.disable({MODULE!r}, default_set=True)
        gone = {{t: hasattr(getattr(bpy.types, t), "spectral_bench")
                 for t in ("Material", "Light", "World", "Camera", "Object", "Scene")}}
        gone_ops = [n for n in dir(bpy.types) if n.startswith("SPECTRAL_BENCH_")]
        print(json.dumps({{"install": list(installed), "enabled": enabled, "props": props, "ops": ops,
                          "exported": list(exported), "mitsuba": list(mitsuba), "gone": gone, "gone_ops": gone_ops}}))
    """), tmp_path / "user")
    assert out["install"] == ["FINISHED"] and out["enabled"]
    assert all(out["props"].values()) and out["ops"]
    assert out["exported"] == ["FINISHED"] and out["mitsuba"] == ["FINISHED"]
    scene = json.loads((tmp_path / "exported.json").read_text())
    assert scene["objects"][0]["bsdf"]["type"] == "diffuse"
    assert (tmp_path / "mitsuba_export" / "scene.xml").is_file()
    assert not any(out["gone"].values()) and out["gone_ops"] == []


@pytest.mark.slow
def test_installed_extension_opens_scenes_runs_one_against_a_shipped_reference_and_draws(extension_zip, tmp_path,
                                                                                          golden):
    out = run_bpy(script(install(extension_zip), f"""
        r_open = bpy.ops.spectral_bench.open_canonical_scenes()
        opened = sorted(sc.name for sc in bpy.data.scenes)
        s = bpy.context.window_manager.spectral_bench_run
        s.backends_off = ",".join(n for n in backends.BACKENDS if n != "mitsuba")
        s.scene_source, s.canonical_scene = "CANONICAL", "ggx_copper_50"
        s.spp, s.scale, s.passes, s.output_parent = 0, 0.125, 2, {str(tmp_path / "runs")!r}
        r_run = bpy.ops.spectral_bench.run_benchmark(wait=True)
        import importlib
        runs = importlib.import_module({MODULE!r} + ".batch.records").read(s.output_dir).resolved()["runs"]  # paths absolute
    """, draw_everything(), """
        results = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark_results, lr.Context())
        print(json.dumps({"open": list(r_open), "opened": opened, "blend": canonical.BLEND.as_posix(),
                          "filepath": bpy.data.filepath, "ext_dir": EXT_DIR, "run": list(r_run), "status": s.status,
                          "runs": runs, "drawn": drawn, "pref_labels": pref_labels,
                          "labels": [c[2].get("text") for c in results if c[1] == "label"]}))
    """), tmp_path / "user")
    ext = out["ext_dir"]
    assert out["blend"] == f"{ext}/scenes.blend" and out["open"] == ["FINISHED"]
    assert out["opened"] == sorted(golden) and not out["filepath"].startswith(ext)
    assert out["run"] == ["FINISHED"] and re.fullmatch(r"passed: 1/1 jobs \(1 (ok|known|fixed)\)", out["status"]), out["status"]
    (run,) = out["runs"]
    assert run["scene"] == "ggx_copper_50" and run["resolution"] == [64, 64] and run["status"] == "ok"
    assert run["test"]["pass"] and run["reference"]["path"] == f"{ext}/references/ggx_copper_50.exr"
    assert "no reference" not in run["reason"]
    assert all(n > 0 for n in out["drawn"].values()) and len(out["drawn"]) >= 9, out["drawn"]
    assert any(t.startswith("extension: ") and t.endswith(f"{ext}/references") for t in out["pref_labels"])
    assert any(t and t.startswith("reference (extension): mitsuba") for t in out["labels"]), out["labels"]


@pytest.mark.slow
def test_references_folder_preference_persists_and_each_reference_names_its_origin(extension_zip, tmp_path):
    """The folder chosen in the preferences is saved with Blender's preferences (read back in a new
    process); with "folder, then extension" a scene whose reference is in the folder is judged
    against it and another against the extension's, and each result says which."""
    folder = tmp_path / "my references"
    folder.mkdir()
    for suffix in (".exr", ".json"):
        shutil.copy(ROOT / "references" / f"ggx_copper_50{suffix}", folder)
    user = tmp_path / "user"
    first = run_bpy(script(install(extension_zip), f"""
        prefs = bpy.context.preferences.addons[{MODULE!r}].preferences
        prefs.references_dir, prefs.reference_source = {str(folder)!r}, "FOLDER"
        only_folder = [o for o, f in preferences.reference_folders()]
        prefs.reference_source = "BOTH"
        saved = bpy.ops.wm.save_userpref()
        print(json.dumps({{"saved": list(saved), "only_folder": only_folder}}))
    """), user)
    assert first["saved"] == ["FINISHED"] and first["only_folder"] == ["folder"]
    second = run_bpy(f"""
        import json, os, sys, bpy
        sys.path.insert(0, {TESTS!r})
        import layout_recorder as lr
        before = {MODULE!r} in bpy.context.preferences.addons
        bpy.ops.wm.read_userpref()  # Blender's own preferences, as Blender reads them at start-up
        addon = bpy.context.preferences.addons[{MODULE!r}]
        from {MODULE}.addon import preferences
        from {MODULE}.batch import backends
        bpy.ops.wm.read_homefile(use_empty=True)
        for name in ("ggx_copper_50", "ggx_copper_60"):
            bpy.ops.spectral_bench.append_canonical_scene(scene=name)
        bpy.data.scenes.remove(bpy.data.scenes["Scene"])
        s = bpy.context.window_manager.spectral_bench_run
        s.backends_off = ",".join(n for n in backends.BACKENDS if n != "mitsuba")
        s.scene_source, s.flip = "FILE", "OFF"
        s.spp, s.scale, s.passes, s.output_parent = 16, 0.125, 1, {str(tmp_path / "runs")!r}
        r = bpy.ops.spectral_bench.run_benchmark(wait=True)
        import importlib
        runs = importlib.import_module({MODULE!r} + ".batch.records").read(s.output_dir).resolved()["runs"]  # paths absolute
        results = lr.draw(bpy.types.SPECTRAL_BENCH_PT_benchmark_results, lr.Context())
        print(json.dumps({{"before": before, "dir": addon.preferences.references_dir,
                          "source": addon.preferences.reference_source,
                          "search": [[o, str(f)] for o, f in preferences.reference_folders()], "r": list(r),
                          "refs": {{run["scene"]: run.get("reference", {{}}).get("path") for run in runs}},
                          "status": {{run["scene"]: run["status"] for run in runs}},
                          "labels": [c[2].get("text") for c in results if c[1] == "label"]}}))
    """, user)
    assert not second["before"]  # the bpy module starts without the user's preferences ...
    assert second["dir"] == str(folder) and second["source"] == "BOTH"  # ... and reads them back
    assert [o for o, _ in second["search"]] == ["folder", "extension"]
    assert second["r"] == ["FINISHED"] and second["status"] == {"ggx_copper_50": "ok", "ggx_copper_60": "ok"}
    assert second["refs"]["ggx_copper_50"] == str(folder / "ggx_copper_50.exr")
    assert second["refs"]["ggx_copper_60"].endswith("/extensions/user_default/spectral_bench/references/ggx_copper_60.exr")
    assert any(t.startswith("reference (folder): mitsuba") for t in second["labels"] if t)
    assert any(t.startswith("reference (extension): mitsuba") for t in second["labels"] if t)


@pytest.mark.slow
def test_platform_zip_with_wheels_fits_the_platform_and_runs_on_its_wheels_alone(platform_zip, tmp_path):
    """The upload: within the size target; installed, Blender unpacks its wheels, and the installed
    batch runner judges a scene against a shipped reference in a Python that sees only the standard
    library, those wheels and numpy (which Blender ships)."""
    limit = _build_script().SIZE_TARGET_MB
    assert platform_zip.stat().st_size <= limit * 1e6, platform_zip.stat().st_size
    user = tmp_path / "user"
    out = run_bpy(script(install(platform_zip), """
        print(json.dumps({"install": list(installed), "ext_dir": EXT_DIR,
                          "site": [p for p in sys.path if p.endswith("site-packages") and "extensions" in p]}))
    """), user)
    site = user / SITE
    assert out["install"] == ["FINISHED"] and out["site"] == [str(site)]
    import numpy
    numpy_only = tmp_path / "numpy_only"
    numpy_only.mkdir()
    for part in ("numpy", "numpy.libs"):
        src = os.path.join(os.path.dirname(os.path.dirname(numpy.__file__)), part)
        if os.path.exists(src):
            os.symlink(src, numpy_only / part)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), str(numpy_only)]))
    env.pop("PYTHONHOME", None)
    python = [os.path.realpath(sys.executable), "-S"]  # -S: not even the test venv's site-packages
    isolated = subprocess.run(python + ["-c", "import scipy"], capture_output=True, text=True, timeout=60,
                              env=dict(env, PYTHONPATH=str(numpy_only)))
    assert isolated.returncode != 0 and "scipy" in isolated.stderr  # the isolation is real: only the wheels serve
    where = subprocess.run(python + ["-c", "import json, scipy, colour, mitsuba, drjit, OpenEXR, PIL, jsonschema, "
                                     "flip_evaluator, jinja2, filelock; print(json.dumps({m.__name__: m.__file__ for m in "
                                     "(scipy, colour, mitsuba, drjit, OpenEXR, PIL, jsonschema, flip_evaluator, jinja2, "
                                     "filelock)}))"],
                           capture_output=True, text=True, env=env, timeout=300)
    assert where.returncode == 0, where.stderr[-2000:]
    assert all(path.startswith(str(site)) for path in json.loads(where.stdout.strip().splitlines()[-1]).values())
    run = subprocess.run(python + [os.path.join(out["ext_dir"], "batch", "run.py"), "-i",
                                   str(ROOT / "golden" / "ir" / "ggx_copper_50.json"), "-r", "mitsuba", "--scale",
                                   "0.125", "--passes", "2", "--flip", "on", "-o", str(tmp_path / "o")],
                         capture_output=True, text=True, env=env, timeout=600)
    (entry,) = metrics(tmp_path / "o")["runs"]  # through the reader: paths absolute
    assert entry["status"] == "ok" and entry["test"]["pass"], run.stderr[-3000:]
    assert entry["reference"]["path"] == os.path.join(out["ext_dir"], "references", "ggx_copper_50.exr")
    assert entry["metrics"]["flip"] is not None  # flip-evaluator from its wheel, in its child process
