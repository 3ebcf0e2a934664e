import copy
import json
import logging
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# The tests are grouped by the part of the house they test (tests/<room>/test_*.py, issue 45 item 4);
# this folder holds what they share: this file's fixtures and helpers and the helper modules beside
# it (installed: ART, pbrt and Chromium and their skip markers; fake_renderer; noisy_runs;
# plant_renderer, scene_fuzz, run_fuzz, exr_craft, blend_builder, ...). Every room is on the path;
# a test module imports test modules of its own room only (tests/project/test_rooms.py).
ROOMS = sorted(p.name for p in Path(__file__).resolve().parent.iterdir()
               if p.is_dir() and any(p.glob("test_*.py")))
for _room in ROOMS:
    sys.path.insert(1, str(Path(__file__).resolve().parent / _room))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
GOLDEN = ROOT / "golden" / "ir"
REFLECTANCE = ["beckmann_glass", "ggx_copper_50", "ggx_copper_50_isolated", "ggx_copper_60", "ggx_copper_60_isolated",
               "ggx_copper_70", "ggx_copper_70_isolated", "ggx_copper_80", "ggx_copper_80_isolated", "ggx_copper_grazing", "ggx_glass"]
SPECTRAL_ACCURACY = ["macbeth_chart_D50", "macbeth_chart_D65"]
POLARIZATION = ["polarizing_plane_0", "polarizing_plane_90", "polarizing_spheres"]
IRIDESCENCE = ["iridescent_sphere_smooth", "iridescent_spheres_film", "iridescent_spheres_height",
               "iridescent_spheres_materials"]
DISPERSION = ["dispersion_fringes", "dispersion_prism"]
FLUORESCENCE = ["fluorescent_sphere_D50_red", "fluorescent_sphere_lone", "fluorescent_sphere_mono_invisible",
                "fluorescent_sphere_mono_red", "yellow_sphere_F8"]
FURNACE = ["furnace_colorchecker_yellow", "furnace_ggx_010", "furnace_ggx_030", "furnace_ggx_060", "furnace_ggx_100",
           "furnace_spiky"]
COATED = ["coated_sphere"]
ALL_SCENES = sorted(REFLECTANCE + SPECTRAL_ACCURACY + POLARIZATION + IRIDESCENCE + DISPERSION + FLUORESCENCE + FURNACE
                    + COATED)


# -- the suite's false-alarm budget (issue 45 item 7; benchmarks/TESTS.md) -------------------------
# A statistical test false-alarms between runs of the suite only when its outcome is random from run
# to run. Mitsuba (scalar and llvm variants) and Cycles render bit-identical images for one seed
# (measured: benchmarks/measure_determinism.py), and every pure-numpy Monte Carlo test seeds its
# generator, so a test on those has the same outcome in every run: it cannot cry wolf. LuxCore's
# renders differ from run to run with one seed (where its halt lands between polls, even on one
# thread), and ART's are the same for one seed and thread count but differ between thread counts
# (the backend runs artist -j <the machine's cores>): on a fleet of machines its outcome is random.
# Each of their judgements below is one family of tests with its own false-alarm rate. The suite's budget
# SUITE_ALPHA is split among them (Bonferroni): each at RANDOM_TEST_ALPHA, so that the whole suite
# false-alarms less than once in 1000 runs. A test added on a renderer whose renders are random must
# be counted here (and in benchmarks/TESTS.md) and judge at RANDOM_TEST_ALPHA.
SUITE_ALPHA = 1e-3
RANDOM_JUDGEMENTS = {  # test (file::function) -> how many families of tests its random renders are judged by
    # pbrt-v4's renders of the pbrt writer's exports (tests/exporters/test_pbrt_renders.py): the same image for
    # one seed whatever the thread count on one build, but a build per machine: one family each (the Lambert
    # probe; the plate's region test; the GGX probe)
    "exporters/test_pbrt_renders.py::test_white_plate_under_a_d65_environment_has_the_lambert_probes_radiance": 1,
    "exporters/test_pbrt_renders.py::test_white_plate_under_a_d65_area_light_has_lamberts_irradiance": 1,
    "exporters/test_pbrt_renders.py::test_ggx_copper_plate_under_an_area_light_matches_the_ggx_probe_with_pbrts_shadowing": 1,
    # LuxCore (tests/backends/test_rgb_backends.py, tests/backends/test_warm_rgb.py)
    "backends/test_rgb_backends.py::test_units_agree_with_the_closed_form_and_with_mitsuba": 2,  # closed form, against Mitsuba
    "backends/test_rgb_backends.py::test_render_is_judged_on_its_own_noise[luxcore]": 1,  # the block test
    "backends/test_rgb_backends.py::test_pixel_filter_is_a_one_pixel_box_and_the_image_is_upright[luxcore]": 1,  # half-covered edge
    "backends/test_rgb_backends.py::test_colorchecker_renders_the_rule_exactly_within_noise[luxcore]": 2,  # D65, D50 charts
    "backends/test_rgb_backends.py::test_colorchecker_d65_is_within_its_bound_and_d50_shows_the_rgb_error[luxcore]": 1,  # calibrated bound
    "backends/test_warm_rgb.py::test_one_warm_luxcore_worker_renders_scene_after_scene_as_fresh_children": 3,  # A, B, A again
    # ART (tests/backends/test_art.py): the module's four judged runs, shared by the tests that read them: each
    # run's noise test and its probe families (fluorescent_sphere_lone: fluorescence, bands;
    # polarizing_plane_0: Brewster, Stokes; macbeth_chart_D65: lambert, bands; polarizing_spheres:
    # Stokes), and the four Brewster renders (one probe family each)
    "backends/test_art.py::art_runs (test_art_renders_the_five_scenes_and_judges_them, test_art_chart_keeps_out_of_gamut_colour)": 11,
    "backends/test_art.py::test_art_brewster_and_polariser_convention": 4,
    # pbrt-v4 (tests/backends/test_pbrt.py): the same image for one seed whatever the thread count on one
    # build, but CI builds it for each machine (-march=native): across a fleet its outcome is a draw. The
    # shared run's two noise tests and its probe families (macbeth_chart_D65: lambert, bands;
    # ggx_copper_50_isolated: ggx), and the film test's two families (47 buckets, R G B)
    "backends/test_pbrt.py::pbrt_runs (test_pbrt_renders_the_scenes_and_judges_them)": 5,
    "backends/test_pbrt.py::test_film_buckets_are_box_means_once_their_empty_rate_is_divided_out": 2,
    # image textures and environment maps (issue 42): the pattern on LuxCore's and pbrt's renders,
    # the sky's patches and their radiance on theirs
    "exporters/test_textures.py::test_the_checkerboard_appears_in_a_luxcore_render_the_right_way_up": 1,
    "exporters/test_textures.py::test_the_checkerboard_appears_in_a_pbrt_render_the_right_way_up": 1,
    "exporters/test_envmap.py::test_cycles_and_luxcore_see_the_same_sky_in_each_direction": 1,
    "exporters/test_envmap.py::test_cycles_and_pbrt_see_the_same_sky_in_each_direction": 1,
}
N_RANDOM_TESTS = sum(RANDOM_JUDGEMENTS.values())
RANDOM_TEST_ALPHA = SUITE_ALPHA / N_RANDOM_TESTS  # each random family's false-alarm rate (Bonferroni)


def random_run_env():
    """The environment of a runner child whose renders are random (ART, LuxCore): its probes judge at
    RANDOM_TEST_ALPHA too (batch/verdict/stats.py PROBE_ALPHA_ENV); pass --alpha RANDOM_TEST_ALPHA
    for its noise test."""
    import os
    from spectral_bench.batch.verdict import stats
    return dict(os.environ, **{stats.PROBE_ALPHA_ENV: repr(RANDOM_TEST_ALPHA)})


@pytest.fixture(scope="session")
def golden():
    from spectral_bench.exporters import ir_json
    return {p.stem: ir_json.load(p) for p in sorted(GOLDEN.glob("*.json"))}


def run_batch(*args, timeout=900, env=None):
    """The real command line, in a child process, as a user runs it (``env``: its environment, default
    this process's)."""
    proc = subprocess.run([sys.executable, str(ROOT / "batch" / "run.py"), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT, env=env)
    return proc


def metrics(out):
    """OUT/metrics.json through the reader (batch/records.py): upgraded to the current version,
    every path field absolute (a test opens the files it names)."""
    from spectral_bench.batch import records
    return records.read(Path(out) / "metrics.json").resolved()


HAND_MADE = ".hand-made-metrics"  # beside a metrics.json a test wrote itself, off the contract on purpose


def write_hand_made_metrics(out, data):
    """Write OUT/metrics.json as a test makes it (hostile, broken, of another shape: not the
    runner's), marked so that the session's schema check (validate_every_metrics_json) leaves it out."""
    out = Path(out)
    (out / HAND_MADE).write_text("written by a test, not by the runner\n")
    (out / "metrics.json").write_text(data if isinstance(data, str) else json.dumps(data))


def runner_metrics_files(root):
    """([metrics.json the runner wrote under root], [those left out]): a file the runner wrote
    carries schema_version (tests/report/test_records.py checks that it always does); a file without it
    is a version-1 or hand-made input that a test wrote itself, and one marked HAND_MADE is
    hand-made on purpose."""
    found, left_out = [], []
    for path in sorted(Path(root).rglob("metrics.json")):
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError):
            left_out.append(path)  # a broken file a test made (the runner writes atomically)
            continue
        if (path.parent / HAND_MADE).exists() or not isinstance(data, dict) or "schema_version" not in data:
            left_out.append(path)
        else:
            found.append(path)
    return found, left_out


@pytest.fixture(scope="session", autouse=True)
def validate_every_metrics_json(tmp_path_factory):
    """After the session (each xdist worker: its own temporary folders), every metrics.json the
    runner wrote under the tests' temporary folders must validate against
    schemas/metrics.schema.json; the first files that do not are named with their fields."""
    yield
    from spectral_bench.batch import records
    found, _left_out = runner_metrics_files(tmp_path_factory.getbasetemp())
    bad = []
    for path in found:
        problems = records.validate(json.loads(path.read_text(encoding="utf-8")))
        if problems:
            bad.append(f"{path}:\n  " + "\n  ".join(problems[:8]))
    if bad:
        pytest.fail(f"{len(bad)} of {len(found)} metrics.json written by the runner break "
                    f"schemas/metrics.schema.json:\n" + "\n".join(bad[:10]), pytrace=False)


def write_scene(tmp_path, scene, name=None):
    from spectral_bench.exporters import ir_json
    sc = copy.deepcopy(scene)
    if name:
        sc["name"] = name
    return ir_json.write(sc, tmp_path / f"{sc['name']}.json")


def render_with_noise(scene, tmp_path, spp, size=None, passes=2, seed=0, backend="mitsuba"):
    """Render an IR scene (Mitsuba by default) in independent passes; returns (the scene as
    rendered, channel names, image, per-pixel standard error or None with one pass)."""
    from spectral_bench.batch import backends, exr
    from spectral_bench.exporters import ir
    sc = copy.deepcopy(scene)
    if size:
        sc["render"]["width"], sc["render"]["height"] = size
    sc["render"]["spp"] = spp
    sc["needs"] = ir.derived_needs({k: v for k, v in sc.items() if k != "needs"})
    b = backends.get(backend)
    path = b.export(sc, Path(tmp_path) / backend)
    b.render(path, b.mode_for(sc)[0], spp, Path(tmp_path) / "render.exr", passes=passes, seed=seed)
    return (sc, *exr.read_image_and_stderr(Path(tmp_path) / "render.exr"))


def render(scene, tmp_path, spp, size=None):
    """Render an IR scene with the Mitsuba backend in one pass; returns (scene, names, image)."""
    return render_with_noise(scene, tmp_path, spp, size, passes=1)[:3]


def noise_test(reference_name, image, stderr, spp, passes=2):
    """The noise test of a render (with its own noise) against a committed reference (with its
    observer layers, for ``rejudge(..., observer=)``)."""
    from spectral_bench.batch.verdict import compare, observer_layers, references
    ref = references.load(reference_name)
    at = compare.reference_at(ref.mean, ref.stderr, ref.spp, image.shape, ref.provenance.get("passes", 8),
                              observer_layers.offsets(ref, image.shape[-1]))
    own = None if stderr is None else stderr.astype("float64") ** 2
    return compare.z_test(image, at, spp, own_var_of_mean=own, own_passes=passes)


def assert_sees(run, effect, what):
    """A test at reduced settings keeps its power (issue 31): ``run``'s own ``detectable`` scale
    (metrics.json: the smallest uniform error its checks find with 90 % power) is below
    ``effect``, the size of what the test claims to see (``what``, for the message), so a render
    too small to see it fails here instead of passing by luck."""
    det = (run.get("detectable") or {}).get("scale")
    assert isinstance(det, (int, float)) and det < effect, (
        f"{run.get('scene')}: this run detects {det} (90 % power), not below the {effect:g} of {what}")


def turned_about_view_axis(scene, degrees):
    """A copy of a polarizing_plane scene's IR with the plane and light turned about the camera's
    view axis (world +y there): the s direction of the reflection then sits at ``degrees``
    counter-clockwise from image right (the Stokes frame tests of probes/ and backends/)."""
    import numpy as np
    sc = copy.deepcopy(scene)
    a = np.radians(-degrees)  # a right-handed turn about +y by -d moves image right towards image up by d
    rot = np.array([[np.cos(a), 0, np.sin(a), 0], [0, 1, 0, 0], [-np.sin(a), 0, np.cos(a), 0], [0, 0, 0, 1]])
    for obj in sc["objects"]:
        obj["shape"]["to_world"] = (rot @ np.asarray(obj["shape"]["to_world"])).tolist()
    return sc


def bpy_script(body, timeout=300):
    """Run ``body`` in a child Python with bpy and scenes.blend read by the runner's reader
    (batch/blend_input.py: ``results`` holds its scenes' IR or the error of each), the extractor's
    modules imported, the extension not registered; returns the JSON its last printed line holds."""
    import textwrap
    code = textwrap.dedent(f"""
        import json, sys
        sys.path.insert(0, {str(ROOT)!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        import bpy
        from spectral_bench.batch import blend_input
        from spectral_bench.exporters import extract_blender, ir_json, validate
        results = dict(blend_input.load_blend({str(ROOT / 'scenes.blend')!r}))
    """) + textwrap.dedent(body)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


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
        blend_input.load_blend({str(ROOT / 'scenes.blend')!r})  # registers the annotation properties only
        import spectral_bench; spectral_bench.register()  # the whole extension: operators, panels, preferences
    """) + textwrap.dedent(body)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                          env=dict(os.environ, **(env or {})))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


# The fast subset (`pytest -m "not slow"`) is the tests that cost under about 1 s of CPU each: the
# test's own process plus the child processes it waits for (batch/run.py, bpy, Mitsuba, Chromium, a
# renderer; kept render workers' share), a module- or session-scoped fixture's cost counted to every
# test that uses it. Every test above that is marked slow (`pytestmark = pytest.mark.slow` where a
# whole module is); each room (tests/<room>/) keeps fast in-process tests of its code
# (tests/project/test_fast_subset.py; docs/developing.md, benchmarks/TESTS.md: how it is measured).
def pytest_configure(config):
    config.addinivalue_line("markers", "slow: costs over about 1 s of CPU with its children and shared fixtures (renders, "
                                       "bpy, batch runs, studies); `pytest -m 'not slow'` is the fast subset")
    if not hasattr(config, "workerinput"):  # the session's first process: before the workers start
        hand_down_mitsuba_probes()


def hand_down_mitsuba_probes():
    """Mitsuba's LLVM and CUDA probes (batch/backends/mitsuba/llvm.py, cuda.py), run for real once
    here; their answers reach every worker and child through the environment, so each batch/run.py
    child does not probe again (about 0.7 s of CPU each). Tests of the probes change its inputs
    (DRJIT_LIBLLVM_PATH, the candidates, the CUDA test hook) and so probe anew."""
    from spectral_bench.batch.backends.mitsuba import cuda
    cuda.find()  # asks llvm.find first; both hand their answers down


# pytest.ini runs the suite on pytest-xdist workers with `--dist loadscope`, which this file's
# scheduler (below) refines: a module that defines a fixture wider than one test (a batch run, a
# render, a built zip, found by SHARED_FIXTURE in its text) is one unit of work, so it runs on one
# worker and the fixture runs once; every other test is a unit of its own, so the long ones (the
# benchmark smoke runs, the example renderers end to end) spread over the workers. (xdist's own
# `loadgroup` marks do not reach its scheduler under pytest 9: it rewrites item._nodeid, which
# pytest 9 no longer reads.)
SHARED_FIXTURE = re.compile(r"@pytest\.fixture\(\s*scope\s*=\s*[\"'](module|package|session)[\"']")


def shares_a_fixture(module_path):
    """True when the test module at module_path defines a module-, package- or session-scoped fixture."""
    try:
        return bool(SHARED_FIXTURE.search(Path(module_path).read_text(encoding="utf-8")))
    except OSError:
        return True  # unreadable here: keep it whole, as loadscope would


try:
    from xdist.scheduler import LoadScopeScheduling
except ImportError:  # pytest-xdist not installed: the suite runs in one process (pytest.ini's -n needs it)
    LoadScopeScheduling = None

if LoadScopeScheduling is not None:
    class ModuleOrTestScheduling(LoadScopeScheduling):
        """loadscope whose unit is the module where the module shares a fixture and the test elsewhere,
        the modules handed out before the single tests; a worker gets its next unit when it has one
        test left (loadscope: two), so at most one test waits queued on a busy worker while the
        other may fall idle."""

        def __init__(self, config, log=None):
            super().__init__(config, log)
            self._whole = {}  # module path -> shares a fixture (read once)
            self._root = Path(str(config.rootpath))
            self._ordered = False  # the work queue put in order (_assign_work_unit), once

        def _split_scope(self, nodeid):
            module = nodeid.split("::", 1)[0]
            if module not in self._whole:
                self._whole[module] = shares_a_fixture(self._root / module)
            return module if self._whole[module] else nodeid

        def _assign_work_unit(self, node):
            """loadscope's, with the whole-module units first (in loadscope's order: most tests
            first), then the single tests: a module's shared fixture (a batch run, a render) is
            the longest work there is, and one started last keeps the other workers idle at the end."""
            if not self._ordered:
                self._ordered = True
                units = sorted(self.workqueue.items(), key=lambda unit: "::" in unit[0])  # stable: False (modules) first
                self.workqueue.clear()
                self.workqueue.update(units)
            super()._assign_work_unit(node)

        def _reschedule(self, node):
            """loadscope's, with one test waiting behind the running one instead of two (a worker
            starts a test once it holds the next one or is told to stop)."""
            if node.shutting_down:
                return
            if not self.workqueue:
                node.shutdown()
                return
            if self._pending_of(self.assigned_work[node]) > 1:
                return
            self._assign_work_unit(node)


@pytest.hookimpl(optionalhook=True)  # a pytest-xdist hook: absent without it
def pytest_xdist_make_scheduler(config, log):
    if LoadScopeScheduling is not None and config.getvalue("dist") == "loadscope":
        return ModuleOrTestScheduling(config, log)
    return None


# -- the command line in this process ----------------------------------------------------------------
@pytest.fixture
def run_batch_here(monkeypatch, capsys):
    """batch/run.py's ``main(argv)`` called in this process, as run_batch starts it in a child
    (working directory ROOT): returns a subprocess.CompletedProcess with its exit status (returned,
    or argparse's SystemExit) and what it wrote to standard output and error (argparse's messages
    and the logged errors: setup_logging's handler writes to sys.stderr, here capsys's).

    A child costs a Python start and the runner's imports (0.3-0.4 s of CPU) each time; where a
    test is about what the runner decides and writes, not the process boundary, this checks the
    same exit status, messages and files. Each module that uses it keeps a real child for the
    same kind of run. The "spectral_bench" logger that main() sets up is put back afterwards."""
    from spectral_bench.batch import run
    logger = logging.getLogger("spectral_bench")
    saved = logger.level, list(logger.handlers), logger.propagate
    monkeypatch.chdir(ROOT)

    def call(*args):
        argv = ["batch/run.py", *map(str, args)]
        capsys.readouterr()
        try:
            code = run.main(argv)
        except SystemExit as exc:
            code = exc.code
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(argv, code, out, err)

    yield call
    for handler in logger.handlers:
        if handler not in saved[1]:
            handler.close()  # -l FILE's file handler
    logger.setLevel(saved[0])
    logger.handlers[:] = saved[1]
    logger.propagate = saved[2]


def camera_over_plane():
    """The to_world (4x4 array) of the camera at (0, -2, 2) whose frame's z axis runs from the
    origin to it and x along world x: the small plane scenes of the RGB and warm-worker tests."""
    import numpy as np
    cam = np.eye(4)
    pos = np.array([0.0, -2.0, 2.0])
    z = pos / np.linalg.norm(pos)
    x = np.array([1.0, 0.0, 0.0])
    cam[:3, 0], cam[:3, 1], cam[:3, 2], cam[:3, 3] = x, np.cross(z, x), z, pos
    return cam
