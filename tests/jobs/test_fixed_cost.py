"""A job's fixed cost (issue 23): the warm FLIP child, and the verdict's shortcuts, which must give
the numbers the plain computations give, bit for bit (a run's metrics.json is the same before and
after: benchmarks/ENGINES.md).

- FLIP runs in one warm child per process (batch/verdict/flip_isolated.py): reused, its value is
  flip-evaluator's own, and a child that dies during a request fails that request alone; a FLIP
  left running after its verdict (the default engine collects it while the next verdict runs) is
  collected by the caller, also when the verdict breaks;
- the power bisection's Student t / normal cdfs (batch/verdict/stats.py ``power_curve``) are
  scipy.stats' values;
- a probe's colour table integrates its rows at once (exporters/colorimetry.py ``xyz_rows``);
- the prism probe clips the pixel boxes of many wavelengths in one call (probes/prism.py);
- the spectral tables are remembered per material and light (probes/common.py ``remembered``);
- the GGX quadrature's geometry is kept across a fit's trial materials (probes/ggx.py
  ``expected_images(cache=)``, the diagnosis's alpha, Beckmann and no-k fits);
- the Airy probe's sub-rays and film interfaces are kept across a fit's trial thicknesses
  (probes/thin_film.py ``expected_images(cache=)``, the diagnosis's film models);
- the default engine's verdict thread loads what the verdicts need while the first job renders.
"""
import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats as st

from spectral_bench.batch.verdict import flip_isolated, stats


def _images(seed, shape=(24, 32)):
    rng = np.random.default_rng(seed)
    a = rng.random(shape + (3,)).astype(np.float32) * 4
    return a, (a * rng.uniform(0.7, 1.3, a.shape)).astype(np.float32)


def _flip_in_a_fresh_process(tmp_path, ref, test):
    """flip-evaluator's own mean on the same arrays, computed in a fresh interpreter."""
    np.save(tmp_path / "r.npy", ref)
    np.save(tmp_path / "t.npy", test)
    code = ("import json, sys, numpy as np, flip_evaluator; r, t = np.load(sys.argv[1]), np.load(sys.argv[2]); "
            "print(json.dumps(float(flip_evaluator.evaluate(r, t, 'HDR', inputsRGB=False, applyMagma=False, "
            "computeMeanError=True)[1])))")
    proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "r.npy"), str(tmp_path / "t.npy")],
                          capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_flip_child_is_warm_and_gives_flip_evaluators_value(tmp_path):
    from spectral_bench.batch import exr
    ref, test = _images(1)
    first, err = flip_isolated.flip_images(ref, test, tmp_path / "f1.exr")
    assert err is None
    pid = flip_isolated._WORKER[0].proc.pid
    second, err = flip_isolated.flip_images(test, ref, tmp_path / "f2.exr")
    assert err is None and flip_isolated._WORKER[0].proc.pid == pid  # the same child served both
    assert first == _flip_in_a_fresh_process(tmp_path, ref, test)
    assert second == _flip_in_a_fresh_process(tmp_path, test, ref)
    fmap = exr.read(tmp_path / "f1.exr")
    # the map: one channel Y, half floats at 5 significant bits (batch/previews.py write_flip)
    assert set(fmap) == {"Y"} and fmap["Y"].shape == ref.shape[:2] and abs(float(np.mean(fmap["Y"])) - first) < 1e-2 * first + 1e-4


def test_a_flip_child_that_dies_during_a_request_fails_that_request_alone(tmp_path, monkeypatch):
    import threading
    ref, test = _images(2, (8, 8))
    assert flip_isolated.flip_images(ref, test, tmp_path / "f.exr")[1] is None
    worker = flip_isolated._WORKER[0]
    os.kill(worker.proc.pid, signal.SIGSTOP)  # it cannot answer: the request below waits in its pipe
    sent = threading.Event()  # set once the request is in the stopped child (requests queue first)
    real_send = flip_isolated.FlipWorker.send

    def send_and_tell(self, *args):
        error = real_send(self, *args)
        sent.set()
        return error
    monkeypatch.setattr(flip_isolated.FlipWorker, "send", send_and_tell)
    pending = flip_isolated.start(ref, test, tmp_path / "f.exr")
    assert sent.wait(120)
    os.kill(worker.proc.pid, signal.SIGKILL)  # the child dies with the request in it
    value, err = pending.result()
    assert value is None and "FLIP failed (exit -9)" in err, err
    again, err = flip_isolated.flip_images(ref, test, tmp_path / "g.exr")  # the next request: a fresh child
    assert err is None and again == _flip_in_a_fresh_process(tmp_path, ref, test)
    assert flip_isolated._WORKER[0] is not worker


def test_flip_refuses_what_it_cannot_judge_without_a_child():
    ref, test = _images(3)
    bad = test.copy()
    bad[0, 0, 0] = np.inf
    assert "NaN or Inf" in flip_isolated.flip_images(ref, bad, "unused.exr")[1]
    assert "shapes differ" in flip_isolated.flip_images(ref, test[:4], "unused.exr")[1]


def _scipy_stats_power(shift, threshold, dof):
    """The power as scipy.stats computes it (the formula of stats.shifted_power before issue 23)."""
    shift = np.asarray(shift, dtype=np.float64)
    d = np.broadcast_to(np.asarray(np.inf if dof is None else dof, dtype=np.float64), shift.shape)
    small = np.isfinite(d) & (d < 1e7)
    dd = np.where(small, np.maximum(d, 1.0), 1e7)
    tcrit = np.where(small, st.t.isf(threshold / 2.0, dd), st.norm.isf(threshold / 2.0))
    cdf = lambda x: np.where(small, st.t.cdf(x, dd), st.norm.cdf(x))
    return 1.0 - cdf(tcrit - shift) + cdf(-tcrit - shift)


def test_power_curve_is_scipy_stats_bit_for_bit():
    rng = np.random.default_rng(5)
    for trial in range(300):
        n = int(rng.integers(1, 40))
        shift = rng.normal(0, 4, (n, 3)) * rng.choice([1e-3, 1.0, 30.0])
        dof = [None, np.inf, 2.0, np.where(rng.random((n, 3)) < 0.3, np.inf, rng.uniform(0.5, 1e8, (n, 3)))][trial % 4]
        threshold = float(rng.choice([1e-7, 1e-3, 0.05, 0.6]))
        expected = _scipy_stats_power(shift, threshold, dof)
        assert np.array_equal(stats.shifted_power(shift, threshold, dof), expected)
        assert np.array_equal(stats.power_curve(threshold, dof, shift.shape)(shift), expected)


def test_xyz_rows_is_xyz_per_row_bit_for_bit():
    from spectral_bench.exporters import colorimetry
    rng = np.random.default_rng(6)
    for obs in colorimetry.OBSERVERS:
        wl = colorimetry.observer(obs)[0]
        rows = rng.random((257, wl.size)) * 3
        assert np.array_equal(colorimetry.xyz_rows(rows, obs), np.stack([colorimetry.xyz(r, obs) for r in rows]))


def test_prism_boxes_clipped_together_as_each_wavelength_alone(golden):
    from spectral_bench.batch.verdict.probes import prism
    scene = golden["dispersion_prism"]
    w, h = 64, 32
    wl = np.arange(380.0, 781.0, 2.0)
    tr = prism.trace_beam(scene, wl, [(-1, -1), (1, -1), (1, 1), (-1, 1), (0, 0)])
    quads = prism.project(scene["camera"], w, h, tr["point"][:, :4])
    lit = np.flatnonzero(tr["T"][:, 4] > 0)
    together = prism._beam_coverage(quads, lit, w, h)
    assert len(together) > 10
    for k, y0, y1, x0, x1, cov in together:
        gx, gy = np.meshgrid(np.arange(x0, x1), np.arange(y0, y1))
        alone = prism._clip_boxes(gx.ravel(), gy.ravel(), quads[k]).reshape(gy.shape)
        assert np.array_equal(cov, alone)


def test_spectral_tables_are_remembered_and_read_only(golden):
    from spectral_bench.batch.verdict.probes import ggx
    plate = next(o for o in golden["ggx_copper_50"]["objects"] if (o.get("bsdf") or {}).get("type") == "conductor")
    light = next(o for o in golden["ggx_copper_50"]["objects"] if o.get("emitter"))
    first = ggx.fresnel_colour_table(plate["bsdf"], light["emitter"]["radiance"])
    again = ggx.fresnel_colour_table(json.loads(json.dumps(plate["bsdf"])), light["emitter"]["radiance"])
    assert again is first  # equal arguments (not the same objects) find the table
    fresh = ggx.fresnel_colour_table.__wrapped__(plate["bsdf"], light["emitter"]["radiance"])
    assert all(np.array_equal(a, b) for a, b in zip(first, fresh))
    with pytest.raises(ValueError):
        first[1][0, 0] = 0.0  # shared by every caller: never written


@pytest.mark.slow
def test_ggx_geometry_kept_across_trial_materials_gives_the_plain_images(golden):
    """The diagnosis's fits reuse the GGX quadrature's geometry between trials (only D, G and the
    Fresnel table change): every trial's image must be the plain computation's, to rounding, in an
    order that goes back to a material already seen, changes the distribution and drops k (a new
    Fresnel table: its colours must not be the cached ones)."""
    import copy

    from spectral_bench.batch.verdict.diagnosis import materials
    from spectral_bench.batch.verdict.probes import ggx
    scene = golden["ggx_copper_50"]
    plates, lights = materials._ggx_plates(scene)  # the plate and its light, the floor aside
    plate = plates[0]
    changes = [("alpha", 0.3), ("alpha", 0.05), ("alpha", None), ("distribution", "beckmann"), ("k", 0.0),
               ("alpha", 0.3)]
    cache = {}
    for what, value in changes:
        sc = copy.deepcopy(scene)
        bsdf = sc["objects"][plate]["bsdf"]
        if what == "distribution":
            bsdf["roughness"]["distribution"] = value
        elif what == "k":
            eta, _ = ggx._eta_k(bsdf)
            bsdf.pop("material", None)
            bsdf["eta"], bsdf["k"] = eta, {"type": "constant", "value": value}
        elif value is not None:
            bsdf["roughness"]["alpha"] = value
        mask, images = ggx.expected_images(sc, plate, lights, 48, 36, cache=cache)
        plain_mask, plain = ggx.expected_images(sc, plate, lights, 48, 36)
        assert mask.any() and np.array_equal(mask, plain_mask)
        got, want = images["cie1931"], plain["cie1931"]
        assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want)), (what, value)
    again = ggx.expected_images(scene, plate, lights, 48, 36, cache=cache)[1]["cie1931"]
    assert np.array_equal(again, ggx.expected_images(scene, plate, lights, 48, 36, cache=cache)[1]["cie1931"])
    assert len(cache) == 1  # one geometry for all of them


@pytest.mark.slow
def test_film_geometry_kept_across_trial_thicknesses_gives_the_plain_images(golden):
    """The diagnosis's thickness fit reuses the Airy probe's sub-rays and the film's interfaces
    between trials (only the Airy sum's phase changes): every trial's image and mask must be the
    plain computation's, for thicknesses that go back to one already seen and to no film (0)."""
    import copy

    from spectral_bench.batch.verdict.probes import thin_film
    scene = golden["iridescent_sphere_smooth"]
    i = next(k for k, o in enumerate(scene["objects"]) if thin_film.applies(o))
    declared = scene["objects"][i]["bsdf"]["thin_film"]["thickness"]
    cache = {}
    for nm in (declared * 1.05, 0.0, declared * 1.05):
        sc = copy.deepcopy(scene)
        sc["objects"][i]["bsdf"]["thin_film"]["thickness"] = nm
        got, mask = thin_film.expected_image(sc, i, 24, 20, cache=cache)
        want, plain_mask = thin_film.expected_image(sc, i, 24, 20)
        assert mask.any() and np.array_equal(mask, plain_mask)
        assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want)), nm
    assert len(cache) == 2  # one geometry, one set of interfaces


def test_prestart_does_not_wait_for_a_flip_in_flight(tmp_path):
    """The next verdict's prestart must not hold it behind the previous job's FLIP (the child
    serves one request: the lock is held until its result is collected)."""
    import threading
    ref, test = _images(3, (8, 8))
    pending = flip_isolated.start(ref, test, tmp_path / "f.exr")  # held until result()
    t = threading.Thread(target=flip_isolated.prestart, daemon=True)
    t.start()
    t.join(60)  # the old prestart waited for the lock, i.e. for ever here: nobody reads the result
    still_waiting = t.is_alive()
    value, err = pending.result()
    assert not still_waiting and err is None and value > 0


def test_the_verdict_thread_is_warmed_with_the_flip_child():
    from spectral_bench.batch.jobs import job as jobs
    flip_isolated.close()
    jobs.warm([{"kind": "render", "verdict": {"flip": False}}])
    assert not flip_isolated._WORKER  # --no-flip: no child
    jobs.warm([{"kind": "render", "verdict": {"flip": True}}])
    assert flip_isolated._WORKER and flip_isolated._WORKER[0].alive()


def test_a_deferred_flip_is_collected_by_the_caller_in_order(tmp_path):
    ref, test = _images(7, (8, 8))
    assert not flip_isolated.defer(lambda: None)  # outside a deferred block: the caller finishes at once
    got = []
    with flip_isolated.deferred() as pending:
        first = flip_isolated.start(ref, test, tmp_path / "a.exr")
        assert flip_isolated.defer(lambda: got.append(first.result()))
    assert len(pending) == 1 and not got  # nothing waited for inside the verdict
    pending[0]()
    assert got[0][1] is None and got[0][0] == _flip_in_a_fresh_process(tmp_path, ref, test)
    second, err = flip_isolated.flip_images(test, ref, tmp_path / "b.exr")  # the child is free again
    assert err is None and second > 0


def test_judge_deferring_collects_flip_when_the_verdict_breaks(tmp_path):
    """A verdict that raises after sending its FLIP still collects it: the next FLIP is not left
    waiting for a request nobody reads."""
    from spectral_bench.batch.jobs import job as jobs
    ref, test = _images(8, (8, 8))
    kind = jobs.KINDS_TABLE["render"]

    def breaking(job, record, deviations):
        pending = flip_isolated.start(ref, test, tmp_path / "c.exr")
        assert flip_isolated.defer(pending.result)
        raise RuntimeError("a verdict that breaks after sending FLIP")
    jobs.KINDS_TABLE["render"] = jobs.Kind(breaking)
    try:
        with pytest.raises(RuntimeError):
            jobs.judge_deferring({"kind": "render"}, {"status": "rendered"})
    finally:
        jobs.KINDS_TABLE["render"] = kind
    assert not flip_isolated._LOCK.locked()  # collected: the next request does not wait for ever
    assert flip_isolated.flip_images(ref, test, tmp_path / "d.exr")[1] is None


def _makespan(order, est):
    """When the last verdict ends: renders one after another, verdicts in the same order, each
    after its render and after the verdict before it (the default engine's two threads)."""
    rendered = judged = 0.0
    for j in order:
        r, v = est[j["scene_name"]]
        rendered += r
        judged = max(judged, rendered) + v
    return judged


def test_overlap_order_is_johnsons_rule_and_ignores_a_bad_record(golden, tmp_path):
    """plan.overlap_order: the order with the soonest last verdict (Johnson 1954) for the
    estimates it is given, checked against every permutation of six jobs of different kinds; a
    reference record whose time is not a number falls back to the default cost, naming nothing."""
    import itertools
    from spectral_bench.batch.jobs import job as jobs, plan
    names = ["fluorescent_sphere_lone", "ggx_glass", "ggx_copper_50_isolated", "dispersion_prism",
             "iridescent_spheres_film", "macbeth_chart_D65"]
    js = [jobs.make("render", n, golden[n], "mitsuba", "m", golden[n]["render"]["spp"], tmp_path, n,
                    verdict={"flip": True}) for n in names]
    est = {j["scene_name"]: plan.estimated_seconds(j) for j in js}
    assert len({round(r / v, 9) for r, v in est.values()}) == len(names)  # no ties: one best order
    assert est["ggx_glass"][0] > est["ggx_glass"][1] and est["fluorescent_sphere_lone"][0] < est["fluorescent_sphere_lone"][1]
    best = min(_makespan(p, est) for p in itertools.permutations(js))
    ordered = plan.overlap_order(js)
    assert sorted(j["scene_name"] for j in ordered) == sorted(names)
    assert _makespan(ordered, est) == pytest.approx(best, rel=1e-12)
    assert _makespan(js, est) > best  # the planned (alphabetical) order is not already the best
    # a record whose time is not a number: the default cost per sample, no error
    refs = tmp_path / "refs"
    refs.mkdir()
    (refs / "ggx_glass.json").write_text(json.dumps({"fingerprint": "x", "spp": 4, "resolution": [2, 2],
                                                     "time_s": "soon"}))
    bad = jobs.make("render", "ggx_glass", golden["ggx_glass"], "mitsuba", "m", 16, tmp_path, "g",
                    verdict={"flip": True, "references": [str(refs)]})
    r = golden["ggx_glass"]["render"]
    assert plan.estimated_seconds(bad)[0] == pytest.approx(plan.RENDER_S_PER_SAMPLE * r["width"] * r["height"] * 16)


def test_prestarted_mitsuba_workers_serve_the_jobs_that_come_later(golden, tmp_path):
    """job.prestart_workers starts the warm workers of a run's variants in the background; the
    jobs then take those very workers (no second start), alive when their job comes: a child
    started with PR_SET_PDEATHSIG dies with the thread that started it, so they must be started
    by a thread that lives on (batch/backends/mitsuba/backend.py ``prestart``)."""
    import copy
    from spectral_bench.batch import backends
    from spectral_bench.batch.backends.mitsuba import backend as mb
    from spectral_bench.batch.jobs import job as jobs
    variant = "scalar_rgb"  # a variant no other test of this module keeps warm, with no kernels to JIT-compile (llvm_ad_rgb: +0.6 s CPU)
    mb.close_pool()
    sc = copy.deepcopy(golden["ggx_copper_50"])
    sc["render"].update(width=16, height=16, spp=1)
    jobs.prestart_workers([jobs.make("render", "ggx_copper_50", sc, "mitsuba", variant, 1, tmp_path, "a")])
    started = mb._STARTING.get(variant)
    if started is not None:
        assert started.wait(300)
    pid = mb._POOL[variant].proc.pid
    b = backends.get("mitsuba")
    xml = b.export(sc, tmp_path / "export")
    record = b.render(xml, variant, 1, tmp_path / "render.exr", passes=2, seed=3, timeout=300)
    assert record["passes"] == 2 and (tmp_path / "render.exr").is_file()
    assert mb._POOL[variant].alive() and mb._POOL[variant].proc.pid == pid  # the prestarted one rendered both passes


# -- --flip on|off|auto (issue 31, decision 2: FLIP keeps its meaning, lazy for runs that ask) ------
def test_flip_option_values_from_the_command_line_and_a_settings_file(tmp_path):
    from spectral_bench.batch import cli
    assert cli.parse([])["flip"] == "auto"  # issue 45: FLIP where a verdict is not ok, by default
    assert cli.parse(["--flip", "auto"])["flip"] == "auto"
    assert cli.parse(["--flip", "off"])["flip"] is False and cli.parse(["--no-flip"])["flip"] is False
    assert cli.parse(["--flip", "on"])["flip"] is True
    for value, want in (('"auto"', "auto"), ("false", False), ("true", True)):
        (tmp_path / "s.toml").write_text(f"flip = {value}\n")
        assert cli.parse(["--settings", str(tmp_path / "s.toml")])["flip"] == want
    (tmp_path / "s.toml").write_text('flip = "sometimes"\n')
    with pytest.raises(cli.UsageError, match="flip"):
        cli.parse(["--settings", str(tmp_path / "s.toml")])
    assert cli.check_option("flip", "auto") == "auto" and cli.check_option("flip", False) is False  # --resume
    with pytest.raises(SystemExit):  # argparse: exit 2 naming --flip
        cli.parse(["--flip", "sometimes"])


@pytest.mark.slow
def test_flip_auto_judges_only_the_renders_that_are_not_ok(tmp_path):
    """--flip auto: the Brewster plane that passes gets no FLIP (metrics.flip null, no flip.exr; its
    reference is Mitsuba's film's, as the render, so it passes but for the test's alpha: a CMF
    reference would leave it ok or known by the noise);
    the D65 chart, "known" at 16 spp (Mitsuba's 0.1 % film scale), gets NVIDIA's HDR-FLIP mean:
    the value flip-evaluator gives for the same pair (the reference at the render's size, the
    render), computed here as --flip on computes it (from the files: the stored reference is
    rounded below its noise, so to 1e-4; measured 2e-6)."""
    from conftest import metrics, run_batch
    from spectral_bench.batch import exr
    out = tmp_path / "out"
    proc = run_batch("-r", "mitsuba", "-s", "macbeth_chart_D65", "-s", "polarizing_plane_0", "--spp", "16",
                     "--junit", tmp_path / "j.xml", "-o", out)  # --flip auto: the default (issue 45)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    runs = {r["scene"]: r for r in metrics(out)["runs"]}
    ok, known = runs["polarizing_plane_0"], runs["macbeth_chart_D65"]
    assert ok["status"] == "ok" and ok["metrics"]["flip"] is None, ok
    # never a blank or a 0 where FLIP stands: the record says why, and so do the summary, the report and JUnit
    assert ok["flip_not_computed"] == "verdict ok; --flip on computes it" and "flip_not_computed" not in known
    said = "not computed (verdict ok; --flip on computes it)"
    row = next(l for l in (out / "summary.md").read_text().splitlines() if "| polarizing_plane_0 |" in l)
    assert said in row and f"{known['metrics']['flip']:.4g}" in (out / "summary.md").read_text()
    assert said in (out / "report.html").read_text() and f'value="{said}"' in (tmp_path / "j.xml").read_text()
    assert not (out / "polarizing_plane_0" / "results" / "mitsuba" / "flip.exr").exists()
    assert known["status"] == "known" and isinstance(known["metrics"]["flip"], float), known
    folder = out / "macbeth_chart_D65" / "results"
    assert (folder / "mitsuba" / "flip.exr").is_file()
    ref = exr.read_rgb(next(folder.glob("reference_*.exr")))
    test = exr.read_rgb(folder / "mitsuba" / "render.exr")
    mean, err = flip_isolated.flip_images(ref, test, tmp_path / "f.exr")
    assert err is None and known["metrics"]["flip"] == pytest.approx(mean, rel=1e-4)


def test_a_flip_child_that_stops_reading_is_killed_and_the_queue_behind_it_served(tmp_path):
    """Issue 40: the time limit covers writing the request too. A child that stops reading
    (SIGSTOP) used to block a request above the pipe's 64 kB for ever, and every request queued
    behind it; now the whole exchange is bounded, the stuck child is killed and the next request
    is served by a fresh one."""
    import threading
    import time
    ref, test = _images(9, (128, 128))  # 2 x 192 kB: three times a Linux pipe's 64 kB buffer
    assert ref.nbytes > 2 * 65536
    assert flip_isolated.flip_images(ref, test, tmp_path / "warm.exr")[1] is None  # a warm child
    worker = flip_isolated._WORKER[0]
    pid = worker.proc.pid
    os.kill(pid, signal.SIGSTOP)
    limit = 3.0
    got, behind = [], []
    try:
        first = flip_isolated.start(ref, test, tmp_path / "stuck.exr", timeout=limit)
        queued = flip_isolated.start(test, ref, tmp_path / "behind.exr")  # waits behind the stuck one
        threads = [threading.Thread(target=lambda: got.append(first.result()), daemon=True),
                   threading.Thread(target=lambda: behind.append(queued.result()), daemon=True)]
        t0 = time.monotonic()
        for t in threads:
            t.start()
        threads[0].join(limit + 60)  # generous for a busy machine; the old code never returned
        took = time.monotonic() - t0
        assert got, f"the request to a stopped child still hangs after {took:.0f} s (time limit {limit} s)"
        threads[1].join(120)
        assert behind, "the request queued behind the stopped child still waits"
    finally:
        try:
            os.kill(pid, signal.SIGKILL)  # unblocks the old code's write, so the session goes on
        except ProcessLookupError:
            pass
    value, err = got[0]
    assert value is None and "timed out after 3 s" in err and "stopped reading" in err, err
    with pytest.raises(ProcessLookupError):  # killed and reaped, not left stopped
        os.kill(pid, 0)
    value, err = behind[0]
    assert err is None and value == _flip_in_a_fresh_process(tmp_path, test, ref)
    assert flip_isolated._WORKER[0] is not worker and flip_isolated._WORKER[0].alive()


def test_the_fresnel_probes_geometry_is_shared_by_polariser_angles(golden):
    """polarizing_plane_0 and _90 differ only in their polariser: the Fresnel probe's footprint
    geometry (probes/fresnel.py ``_footprints``) is computed once for both (issue 45 item 1), and
    each angle's expected image is the plain computation's, bit for bit."""
    from spectral_bench.batch.verdict.probes import fresnel
    w, h = 48, 32
    kept = []
    for name in ("polarizing_plane_0", "polarizing_plane_90"):
        scene = golden[name]
        objs = scene["objects"]
        di = next(i for i, o in enumerate(objs) if (o.get("bsdf") or {}).get("type") == "dielectric")
        li = next(i for i, o in enumerate(objs) if o.get("emitter") and o["shape"]["type"] == "rectangle")
        pol = scene["camera"]["polarizer"]
        mask, acc, eta, cos_c = fresnel._expected(scene, di, li, w, h, pol)
        up = np.asarray(scene["camera"]["to_world"], dtype=np.float64)[:3, 1]
        up = up / np.linalg.norm(up)
        plain_mask, plain = None, None
        for offset, weight in fresnel.raycast.footprint_offsets(fresnel.FOOTPRINT):  # the computation without sharing
            valid, cos_i, e, s, dirs = fresnel._reflection(scene, di, li, w, h, offset)
            rs, rp = fresnel.fresnel_dielectric(cos_i, e)
            phi = fresnel._stokes_chi(s, dirs, up) - np.radians(pol["angle"])
            values = np.stack([(rs * np.cos(phi) ** 2 + rp * np.sin(phi) ** 2) / 2], axis=-1)
            plain_mask = valid if plain_mask is None else plain_mask & valid
            plain = weight * values if plain is None else plain + weight * values
        corners = fresnel._reflection(scene, di, li, w, h, "corners")[0]
        plain_mask &= corners[:-1, :-1] & corners[1:, :-1] & corners[:-1, 1:] & corners[1:, 1:]
        assert plain_mask.sum() > 100 and np.array_equal(mask, plain_mask) and np.array_equal(acc, plain)
        assert np.array_equal(cos_c, fresnel._reflection(scene, di, li, w, h, "centers")[1]) and eta == e
        kept.append(next(reversed(fresnel._footprints.cache.values())))
    assert kept[1] is kept[0]  # the second scene found the first's geometry
