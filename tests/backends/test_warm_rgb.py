"""The warm Cycles and LuxCore workers (batch/backends/{cycles,luxcore}/worker.py ``serve``, kept
across jobs by batch/backends/warm.py; issue 23): one worker builds and renders scene after scene
as fresh child processes (the command lines a user re-runs) do - Cycles pixel for pixel, LuxCore
within its own noise - so no request sees another's data; a worker killed mid-render fails only that pass (retried on a fresh worker) or job, and the
next job renders on a fresh worker; a render past its time limit kills its worker. Every render
here is real (bpy, pyluxcore), 16x16 to 24x24 pixels."""
import json
import os
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

from conftest import RANDOM_TEST_ALPHA, camera_over_plane
from spectral_bench.batch import backends, exr
from spectral_bench.batch.backends import passes, warm
from spectral_bench.batch.backends.cycles import backend as cycles_backend
from spectral_bench.batch.backends.luxcore import backend as luxcore_backend
from spectral_bench.batch.verdict import stats
from spectral_bench.exporters import ir, rgb_scene

RGB = [n for n in ("cycles", "luxcore") if backends.get(n).availability()[0]]
pytestmark = pytest.mark.skipif(not RGB, reason="neither bpy nor pyluxcore is installed")
needs_cycles = pytest.mark.skipif("cycles" not in RGB, reason="bpy is not installed")
needs_luxcore = pytest.mark.skipif("luxcore" not in RGB, reason="pyluxcore is not installed")

HUGE_SPP = 1_000_000  # minutes per pass at 24x24: a render that is surely under way when it is killed


def _lamp_scene(albedo, lamp_x, size=16):
    """A diffuse plane lit by a small area light (direct-light sampling: every pixel is noisy, so a
    wrong seed or a stale scene shows in every pixel). Every variant has the same scene name and
    object names, so a worker that kept anything of the previous scene would render it."""
    cam = camera_over_plane()
    sc = {"format": ir.FORMAT, "version": ir.VERSION, "name": "warm", "case": "custom", "needs": [],
          "render": {"spp": 16, "width": size, "height": size, "max_depth": 4, "filter": "box", "integrator": "path"},
          "camera": {"to_world": cam.tolist(), "fov": 30.0, "fov_axis": "x"}, "environment": None,
          "objects": [{"name": "plane", "shape": {"type": "rectangle", "to_world": np.diag([3.0, 3.0, 1.0, 1.0]).tolist()},
                       "bsdf": {"type": "diffuse", "reflectance": {"type": "constant", "value": albedo}}, "emitter": None},
                      {"name": "lamp", "bsdf": None,
                       "shape": {"type": "rectangle", "to_world": [[0.3, 0, 0, lamp_x], [0, -0.3, 0, 0], [0, 0, -1, 1.0], [0, 0, 0, 1]]},
                       "emitter": {"type": "area", "radiance": {"type": "named", "name": "cie_d65", "scale": 4.0}}}]}
    sc["needs"] = ir.derived_needs(sc)
    return sc


def _rgb_json(scene, folder):
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "scene_rgb.json"
    path.write_text(json.dumps(rgb_scene.build(scene, backends.get("cycles").distributions)))
    return path


def _pixels(path):
    ch = exr.read(path)
    return np.stack([ch[c] for c in "RGB"], axis=-1)


def _fresh(scene_json, folder, spp, seed):
    """The scene built and rendered by fresh child processes (the subcommands a user re-runs)."""
    worker = str(cycles_backend.WORKER)
    blend, out = folder / "fresh.blend", folder / "fresh.exr"
    for cmd in (["build", "--scene", scene_json, "--blend", blend],
                ["render", "--blend", blend, "--spp", spp, "--seed", seed, "--out", out, "--result", folder / "fresh.json"]):
        proc = subprocess.run([sys.executable, worker, *map(str, cmd)], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
    return _pixels(out)


def _warm(scene_json, blend, folder, spp, seed, tag):
    """The same through the warm worker's requests (batch/backends/cycles/backend.py ``ask``)."""
    log = folder / "warm.log"
    if scene_json is not None:
        cycles_backend.ask({"build": {"scene": str(scene_json), "blend": str(blend)}}, 300, log, "build")
    out = folder / f"warm_{tag}.exr"
    cycles_backend.ask({"render": {"blend": str(blend), "mode": "rgb", "spp": spp, "passes": 1, "seed": seed,
                                   "out": str(out), "result": str(folder / f"warm_{tag}.json")}}, 300, log, "render")
    return _pixels(out)


@pytest.mark.slow
@needs_cycles
def test_one_warm_worker_renders_scene_after_scene_as_fresh_children(tmp_path):
    """A, then B (same scene and object names, another albedo and lamp position), then A's .blend
    again, all on one warm worker: each image equals, pixel for pixel, the fresh children's
    render with the same seed (Cycles on the CPU is deterministic for a seed), and A differs
    from B (the comparison can see a stale scene)."""
    a, b = tmp_path / "a", tmp_path / "b"
    ja, jb = _rgb_json(_lamp_scene(0.5, 0.0), a), _rgb_json(_lamp_scene(0.2, 0.4), b)
    fresh_a, fresh_b = _fresh(ja, a, 8, 3), _fresh(jb, b, 8, 3)
    assert np.abs(fresh_a - fresh_b).max() > 0.05  # the two scenes render visibly differently
    warm_a = _warm(ja, a / "warm.blend", a, 8, 3, "first")
    pid = warm.idle("cycles").pid
    warm_b = _warm(jb, b / "warm.blend", b, 8, 3, "first")
    warm_a2 = _warm(None, a / "warm.blend", a, 8, 3, "again")
    assert warm.idle("cycles").pid == pid  # one worker served all of them
    np.testing.assert_array_equal(warm_a, fresh_a)
    np.testing.assert_array_equal(warm_b, fresh_b)
    np.testing.assert_array_equal(warm_a2, fresh_a)
    other_seed = _warm(None, a / "warm.blend", a, 8, 4, "seed4")
    assert np.abs(other_seed - fresh_a).max() > 0  # the seed reaches the render (equality above means something)


@pytest.mark.slow
@needs_luxcore
def test_one_warm_luxcore_worker_renders_scene_after_scene_as_fresh_children(tmp_path):
    """LuxCore stops between polls, so two renders of one seed differ in their last samples: A,
    then B, then A again on one warm worker each agree with a fresh child's render of that scene
    in the mean over pixels, within the renders' own pixel-to-pixel noise (stats.region_mean_test
    on the pixel differences: pixels are independent, one-pixel box and RANDOM sampler), and A's
    render is told apart from B's by the same test. Each of the three agreements is random from
    run to run: it judges at its share of the suite's false-alarm budget (RANDOM_TEST_ALPHA), and
    so does the telling apart."""
    b = backends.get("luxcore")
    scenes = {"a": _lamp_scene(0.5, 0.0), "b": _lamp_scene(0.45, 0.1)}
    cfgs = {k: b.export(sc, tmp_path / k) for k, sc in scenes.items()}

    def one(key, fresh, tag):
        out, res = tmp_path / f"{key}_{tag}.npy", tmp_path / f"{key}_{tag}.json"
        args = {"cfg": str(cfgs[key]), "mode": "rgb", "spp": 64, "passes": 1, "seed": 5, "timeout": 300,
                "out": str(out), "result": str(res)}
        if fresh:
            cmd = [sys.executable, str(luxcore_backend.WORKER)] + [f"--{k}={v}" for k, v in args.items()]
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
            assert proc.returncode == 0, proc.stderr[-2000:]
        else:
            warm.call("luxcore", luxcore_backend.SERVE, "LuxCore", {"render": args, "log": str(tmp_path / "warm.log")},
                      300, "render")
        return np.load(out)[0]

    fresh = {k: one(k, True, "fresh") for k in scenes}
    warm_a = one("a", False, "first")
    pid = warm.idle("luxcore").pid
    warm_renders = {"a": warm_a, "b": one("b", False, "first"), "a2": one("a", False, "again")}
    assert warm.idle("luxcore").pid == pid  # one worker served all of them

    def agree(x, y):
        return stats.region_mean_test((x - y).reshape(-1, 3), alpha=RANDOM_TEST_ALPHA, tests=3)["pass"]

    for key, img in warm_renders.items():
        assert agree(img, fresh[key[0]]), key
    assert not agree(warm_renders["a2"], fresh["b"])  # the test can tell the two scenes apart


def _job(scene, folder, name="cycles"):
    """The scene exported for ``name`` (Cycles: on the warm worker): (path, mode, backend)."""
    b = backends.get(name)
    mode, why = b.mode_for(scene)
    assert mode, why
    blend = b.export(scene, folder / "export")
    return blend, mode, b


def _kill_renders(count, killed, stop):
    """Kill (SIGKILL) the next ``count`` warm workers seen rendering, one after the other."""
    while len(killed) < count and not stop.is_set():
        for w in warm.busy():
            pid = w.pid
            if (w.asking or "").startswith("rendering") and pid is not None and pid not in killed:
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
        stop.wait(0.01)


@pytest.mark.slow
@pytest.mark.parametrize("name", RGB)
def test_a_worker_killed_mid_render_fails_only_that_job(tmp_path, name):
    """SIGKILL of the worker under a pass: the pass is retried on a fresh worker (another pid);
    killed again, the job fails naming the pass; the next job renders on a fresh worker."""
    blend, mode, b = _job(_lamp_scene(0.5, 0.0, size=24), tmp_path / "killed", name)
    killed, stop = [], threading.Event()
    killer = threading.Thread(target=_kill_renders, args=(2, killed, stop), daemon=True)
    killer.start()
    try:
        with pytest.raises(passes.BackendFailure) as err:
            b.render(blend, mode, HUGE_SPP, tmp_path / "killed" / "render.exr", passes=1, timeout=120,
                     log_path=tmp_path / "killed" / "render.log")
    finally:
        stop.set()
        killer.join()
    assert len(set(killed)) == 2, killed  # the retry ran on a fresh worker
    assert "failed twice" in str(err.value) and "exited with -9" in str(err.value), str(err.value)
    assert "timed out" not in str(err.value)
    blend2, mode2, _ = _job(_lamp_scene(0.2, 0.4), tmp_path / "next", name)
    info = b.render(blend2, mode2, 8, tmp_path / "next" / "render.exr", passes=2, log_path=tmp_path / "next" / "render.log")
    assert info["passes"] == 2 and "retried" not in info
    assert warm.idle(name).pid not in killed and warm.idle(name).alive()


@pytest.mark.slow
@pytest.mark.parametrize("name", RGB)
def test_a_render_past_its_time_limit_kills_the_worker_and_the_next_job_renders(tmp_path, name):
    """A pass that overruns its limit (a hang, as far as the backend can tell) fails its job
    without a retry, its worker killed and not kept; the next job renders on a fresh worker."""
    blend, mode, b = _job(_lamp_scene(0.5, 0.0, size=24), tmp_path / "slow", name)
    with pytest.raises(passes.BackendFailure, match="timed out"):
        b.render(blend, mode, HUGE_SPP, tmp_path / "slow" / "render.exr", passes=1, timeout=5,
                 log_path=tmp_path / "slow" / "render.log")
    assert not warm.busy() and warm.idle(name) is None  # the overrunning worker was killed, not kept
    blend2, mode2, _ = _job(_lamp_scene(0.2, 0.4), tmp_path / "next", name)
    info = b.render(blend2, mode2, 8, tmp_path / "next" / "render.exr", passes=2, log_path=tmp_path / "next" / "render.log")
    assert info["passes"] == 2 and warm.idle(name).alive()
