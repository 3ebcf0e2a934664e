"""Cross-checked references (issue 44): ``batch/make_references.py --crosscheck NAME`` judges a
reference against another renderer's render on both noises and records the outcome in the
reference's provenance; verdicts against it say who cross-checked it.

The renders run at reduced settings (macbeth_chart_D65 at a tenth of its resolution) and each
asserts its own power (the recorded ``detectable``) below the 1 % it claims to see. The second
renderer is the example renderer declared in examples/your_renderer/toy.toml (``toy_spectral``:
a renderer by another name, with its own spectral film, which exists wherever the tests run) and,
where it is built, pbrt-v4 (an independent renderer): the same checks run with each.
"""
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, metrics, run_batch
from spectral_bench.batch import exr
from spectral_bench.batch.backends.pbrt import backend as pbrt_backend
from spectral_bench.batch.report import results
from spectral_bench.batch.verdict import crosscheck as cc, references

MAKE = ROOT / "batch" / "make_references.py"
TOY = ROOT / "examples" / "your_renderer" / "toy.toml"
SCENE = "macbeth_chart_D65"
IR = ROOT / "golden" / "ir" / f"{SCENE}.json"


def make_refs(*args, timeout=900):
    proc = subprocess.run([sys.executable, str(MAKE), *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          cwd=ROOT)
    return proc.returncode, proc.stdout + proc.stderr


# -- the record: what counts, what a verdict says ----------------------------------------------------
def provenance(sha="a" * 64, fp="f" * 64, **item):
    entry = {"renderer": "pbrt", "version": "4 (built Dec  4 2026)", "mode": "spectral47", "spp": 64, "passes": 2,
             "detectable": 0.0012, "agrees": True, "date": "2026-12-05T08:00:00+00:00",
             "reference_sha256": sha, "fingerprint": fp}
    entry.update(item)
    return {"backend": "mitsuba", "mode": "llvm_ad_spectral", "spp": 4096, "exr_sha256": "a" * 64,
            "fingerprint": "f" * 64, "crosschecks": [entry]}


def run_entry(prov, probes=()):
    counted, stale = cc.counting(prov)
    ref = {"path": "r.exr", "backend": "mitsuba", "mode": "llvm_ad_spectral", "spp": 4096, "date": "2026-12-02"}
    if counted:
        ref["crosschecks"] = [cc.summary(c) for c in counted]
    return {"status": "ok", "backend": "mitsuba", "reference": ref, "probes": list(probes)}, stale


def test_a_current_agreeing_crosscheck_names_the_renderer_and_its_power():
    run, stale = run_entry(provenance())
    assert not stale
    assert results.judged_by(run) == ("no probe; reference by mitsuba llvm_ad_spectral, 4096 spp, 2026-12-02; "
                                      "reference cross-checked by pbrt-v4 (detects 0.12 %)")
    assert not results.checked_against_itself(run)
    assert results.crosscheck_note(run) == "reference cross-checked by pbrt-v4 (detects 0.12 %)"


def test_a_stale_crosscheck_does_not_count():
    """A cross-check made against another image of the reference (its sha256 differs: re-made since)
    or another version of the scene does not count: the verdict is checked against itself again."""
    for prov in (provenance(sha="b" * 64), provenance(fp="e" * 64)):
        run, stale = run_entry(prov)
        assert "crosschecks" not in run["reference"]
        assert len(stale) == 1 and ("sha256 differs" in stale[0][1] or "fingerprint differs" in stale[0][1])
        assert results.checked_against_itself(run)
        assert results.judged_by(run).endswith(f"({results.SELF_CHECK})")
    no_hash = provenance()
    del no_hash["exr_sha256"]
    assert cc.counting(no_hash)[0] == []


def test_a_disagreeing_crosscheck_is_said_and_does_not_vouch():
    run, _ = run_entry(provenance(agrees=False))
    assert "reference DIFFERS from pbrt-v4 beyond noise (cross-check of 2026-12-05)" in results.judged_by(run)
    assert results.checked_against_itself(run)


def _deviation(**kw):
    from spectral_bench.batch.verdict import known
    d = dict(id="pbrt-dev", backend="pbrt", checks=["noise test"], evidence="e", explanation="x", date="2026-12-05",
             scale=1.0047, scale_se=0.0008)
    d.update(kw)
    return known.Deviation(**d)


def test_a_crosscheck_that_agreed_under_a_deviation_names_it_and_counts_while_it_is_recorded():
    """An entry that agreed only under a recorded deviation says so in the verdict ("up to ID");
    it counts while the deviation file records that id with the model it was judged under, and not
    once the deviation is gone or re-measured (its scale changed)."""
    prov = provenance(agrees_under="pbrt-dev", deviation={"id": "pbrt-dev", "scale": 1.0047, "scale_se": 0.0008},
                      detectable=0.0028)
    counted, stale = cc.counting(prov, [_deviation()])
    assert len(counted) == 1 and not stale
    run = {"status": "ok", "backend": "mitsuba", "probes": [],
           "reference": {"backend": "mitsuba", "crosschecks": [cc.summary(c) for c in counted]}}
    assert results.crosscheck_note(run) == "reference cross-checked by pbrt-v4 up to pbrt-dev (detects 0.28 %)"
    assert not results.checked_against_itself(run)
    for devs in ([], [_deviation(scale=1.003)], [_deviation(scale_se=0.002)], [_deviation(id="other")]):
        counted, stale = cc.counting(prov, devs)
        assert counted == [] and "no longer record" in stale[0][1], devs
    assert len(cc.counting(prov)[0]) == 1  # deviations not given: not checked (the record alone)


def test_only_scale_models_of_the_noise_test_for_that_renderer_explain_a_crosscheck():
    job = {"scene": "ggx_glass", "backend": "pbrt", "mode": "spectral47", "versions": {"pbrt": "4 (built)"}, "film": ""}
    good = _deviation(scenes=["ggx_glass"], versions=["*pbrt 4 *"])
    others = [_deviation(id="probe", checks=["ggx *"]), _deviation(id="art", backend="art"),
              _deviation(id="scene", scenes=["ggx_copper_80"]), _deviation(id="obs", observer="mitsuba3"),
              _deviation(id="g2", shadowing="height-correlated", scale=1.0, scale_se=0.0)]
    assert [d.id for d in cc.explaining([*others, good], job)] == ["pbrt-dev"]
    assert cc.explaining([], job) == []
    # the model as the test applies it: to the reference where the cross-check is the tested image,
    # inverted where the reference is (finer than the cross-check)
    assert cc.model_for_test(good, True) == (1.0047, 0.0008)
    s, se = cc.model_for_test(good, False)
    assert s == pytest.approx(1 / 1.0047) and se == pytest.approx(0.0008 / 1.0047**2)


def test_hostile_crosscheck_records_are_shown_as_text_never_raise():
    for bad in (None, 3, "x", [1, "a"], {"crosschecks": "no"}):
        prov = {"exr_sha256": "a" * 64, "fingerprint": "f" * 64, "crosschecks": bad}
        assert cc.counting(prov)[0] == []
    run = {"status": "ok", "backend": "b", "reference": {"backend": "a", "crosschecks": [
        {"label": "<b>" * 100, "agrees": True, "detectable": float("nan")}, 7, None]}}
    text = results.judged_by(run)
    assert text.count("<b>") <= 20 and "detects" not in text


def test_record_changes_only_the_crosschecks_atomically(tmp_path):
    """record() rewrites the reference's record with its crosschecks (the newer entry of a renderer
    and mode replacing the older), every other field as it was; the image untouched; refused when
    the image on disk is not the one judged."""
    src = ROOT / "references"
    shutil.copy(src / f"{SCENE}.json", tmp_path)
    shutil.copy(src / f"{SCENE}.exr", tmp_path)
    before = json.loads((tmp_path / f"{SCENE}.json").read_text())
    image = (tmp_path / f"{SCENE}.exr").read_bytes()
    item = dict(provenance()["crosschecks"][0], reference_sha256=before["exr_sha256"], fingerprint=before["fingerprint"])
    cc.record(tmp_path, SCENE, item)
    cc.record(tmp_path, SCENE, dict(item, detectable=0.001))
    after = json.loads((tmp_path / f"{SCENE}.json").read_text())
    assert after.pop("crosschecks") == [dict(item, detectable=0.001)]
    assert after == {k: v for k, v in before.items() if k != "crosschecks"}
    assert (tmp_path / f"{SCENE}.exr").read_bytes() == image
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    with pytest.raises(ValueError, match="changed while it was cross-checked"):
        cc.record(tmp_path, SCENE, dict(item, reference_sha256="0" * 64))


# -- usage errors: exit 2, naming the option or scene, nothing rendered -------------------------------
@pytest.mark.parametrize("args, said", [
    (["--crosscheck", "nosuch"], "--crosscheck nosuch: unknown backend"),
    (["--crosscheck", "pbrt", "--replace"], "--replace: not with --crosscheck pbrt"),
    (["--crosscheck", "pbrt", "--scale", "0.5"], "--scale: not with --crosscheck pbrt"),
    (["--crosscheck", "pbrt", "--out", "x"], "--out: not with --crosscheck pbrt"),
    (["--crosscheck", "pbrt", "-r", "art"], "-r: not with --crosscheck pbrt"),
    (["--crosscheck", "pbrt", "--references", "/nonexistent/refs"], "--references /nonexistent/refs: no such folder"),
    (["--references", "references"], "--references: only with --crosscheck NAME"),
    (["--no-record"], "--no-record: only with --crosscheck NAME"),
    (["--known", "k.toml"], "--known: only with --crosscheck NAME"),
    (["--crosscheck", "pbrt", "--known", "/nonexistent/k.toml"], "--known /nonexistent/k.toml: no such file"),
    (["--crosscheck", "pbrt", "--known", str(ROOT / "README.md")], "--known " + str(ROOT / "README.md") + ": "),
])
def test_usage_errors_name_the_option(args, said, capsys):
    from spectral_bench.batch import make_references
    assert make_references.main(args) == 2
    assert said in capsys.readouterr().err


def test_help_prints_the_crosscheck_options():
    """--help once raised (a help string %-formatted twice: '90 %% power' became '90 % power',
    which argparse read as a format)."""
    from spectral_bench.batch import make_references
    text = make_references.parser().format_help()
    assert "--crosscheck NAME" in text and "90 % power (default 0.005)" in " ".join(text.split())


def test_rgb_transport_is_exact_only_where_every_bsdf_is_wavelength_independent():
    """The rule an RGB renderer's cross-check rests on (docs/backends.md, RGB renderers as
    cross-checks), read from the IR: colourless constant-IOR glass is exact; a measured
    conductor, a named reflectance, a dispersive IOR, a thin film and an unknown BSDF are not."""
    from spectral_bench.exporters import rgb_scene

    def ir(name):
        return json.loads((ROOT / "golden" / "ir" / f"{name}.json").read_text())
    assert rgb_scene.wavelength_dependent(ir("ggx_glass")) == []
    assert rgb_scene.wavelength_dependent(ir("beckmann_glass")) == []
    assert rgb_scene.wavelength_dependent(ir("ggx_copper_50"))[0][:2] == ("copper_plate_50", "bsdf.eta")
    assert ("patch_cyan", "bsdf.reflectance") in [w[:2] for w in rgb_scene.wavelength_dependent(ir("macbeth_chart_D65"))]
    assert rgb_scene.wavelength_dependent(ir("dispersion_fringes"))[0][:2] == ("sf11_sphere", "bsdf.int_ior")
    assert ("smooth_film_sphere", "bsdf.thin_film") in [
        w[:2] for w in rgb_scene.wavelength_dependent(ir("iridescent_sphere_smooth"))]
    glass = ir("ggx_glass")
    next(o for o in glass["objects"] if o["name"] == "glass_sphere")["bsdf"]["type"] = "velvet"
    assert rgb_scene.wavelength_dependent(glass)[0][:2] == ("glass_sphere", "bsdf.type")


def test_an_rgb_renderer_cross_checks_no_wavelength_dependent_scene(capsys):
    """Cycles on the copper plate: refused before anything renders, naming object and field (exit 1)."""
    from spectral_bench.batch import make_references
    rc = make_references.main(["--crosscheck", "cycles", "-i", str(ROOT / "golden" / "ir" / "ggx_copper_50.json"),
                               "-s", "ggx_copper_50", "--no-record"])
    out = capsys.readouterr().out
    assert rc == 1
    assert "ggx_copper_50: NOT cross-checked: cycles renders in RGB" in out
    assert "copper_plate_50.bsdf.eta" in out and "pass 1/" not in out


def test_a_history_folder_is_refused_as_references(tmp_path, capsys):
    from spectral_bench.batch import make_references
    (tmp_path / "file").write_text("")
    assert make_references.main(["--crosscheck", "pbrt", "--references", str(tmp_path / "file")]) == 2
    assert f"--references {tmp_path / 'file'}: not a folder" in capsys.readouterr().err
    (tmp_path / references.HISTORY_RECORD).write_text("{}")
    assert make_references.main(["--crosscheck", "pbrt", "--references", str(tmp_path)]) == 2
    assert "a history folder" in capsys.readouterr().err


def test_an_unknown_scene_and_the_references_own_renderer_are_usage_errors(capsys):
    """In this process (``main(argv)``, as the module's other usage errors): two children of
    make_references.py cost 3.2-3.6 s of CPU, over the fast subset's 1 s rule."""
    from spectral_bench.batch import make_references

    def make_refs_here(*args):
        rc = make_references.main([str(a) for a in args])
        said = capsys.readouterr()
        return rc, said.out + said.err
    rc, out = make_refs_here("--crosscheck", "mitsuba", "-i", IR, "-s", "no_such_scene", "--references", ROOT / "references")
    assert rc == 2 and "-s no_such_scene: no such scene" in out
    rc, out = make_refs_here("--crosscheck", "mitsuba", "-i", IR, "--references", ROOT / "references")
    assert rc == 2 and f"scene {SCENE}'s reference" in out and "made by mitsuba" in out and "independent" in out


# -- real cross-checks at reduced settings --------------------------------------------------------
RENDERERS = [
    pytest.param(("toy_spectral", ["--renderers", TOY]), id="toy_spectral"),
    pytest.param(("pbrt", []), id="pbrt", marks=pytest.mark.skipif(
        not pbrt_backend.find_pbrt(), reason=f"no pbrt-v4 ({pbrt_backend.ENV_FILE}; scripts/build_pbrt.sh builds it)")),
]


def scaled_copy(src, dst, factor, keep_crosschecks):
    """The reference of SCENE in ``src`` copied to ``dst`` with its image (mean and noise) times
    ``factor``, its record's sha256 that of the new image (as a re-made reference's would be);
    ``keep_crosschecks``: the old record's cross-checks stay in it (made against the old image)."""
    dst.mkdir(exist_ok=True)
    ref, bad = references.examine(src, SCENE)
    assert bad is None
    meta = json.loads((src / f"{SCENE}.json").read_text())
    extra = {f"stderr.{n}": (ref.stderr[..., i] * factor).astype(np.float32) for i, n in enumerate(ref.names)}
    exr.write_image(dst / f"{SCENE}.exr", ref.names, (ref.mean * factor).astype(np.float32), extra)
    meta["exr_sha256"] = references.sha256_of(dst / f"{SCENE}.exr")
    if not keep_crosschecks:
        meta.pop("crosschecks", None)
    (dst / f"{SCENE}.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")


@pytest.fixture(scope="module", params=RENDERERS)
def checked(request, tmp_path_factory):
    """A reference made by Mitsuba (CMF film, a tenth of the resolution), cross-checked by the
    renderer; then a copy 1 % too bright (its record keeping the first cross-check, now stale),
    cross-checked too."""
    name, extra = request.param
    base = tmp_path_factory.mktemp(f"crosscheck-{name}")
    refs = base / "refs"
    rc, out = make_refs("-s", SCENE, "--scale", "0.1", "--spp", "2048", "--passes", "4", "--film", "cmf", "--out", refs)
    assert rc == 0, out
    rc, out = make_refs("--crosscheck", name, *extra, "-s", SCENE, "--references", refs, "--spp", "1024")
    bright, stale = base / "bright", base / "stale"
    scaled_copy(refs, bright, 1.01, keep_crosschecks=False)
    scaled_copy(refs, stale, 1.01, keep_crosschecks=True)  # not cross-checked again: its record's one is stale
    rc_b, out_b = make_refs("--crosscheck", name, *extra, "-s", SCENE, "--references", bright, "--spp", "1024")
    return dict(name=name, base=base, refs=refs, bright=bright, stale=stale, rc=rc, out=out, rc_b=rc_b, out_b=out_b)


@pytest.mark.slow
def test_the_reference_agrees_with_the_other_renderer_at_its_stated_power(checked):
    assert checked["rc"] == 0, checked["out"]
    assert f"{SCENE}: agrees with" in checked["out"]
    meta = json.loads((checked["refs"] / f"{SCENE}.json").read_text())
    (item,) = meta["crosschecks"]
    # its power: a uniform 1 % error of the reference is detected (90 % power at `detectable`)
    assert item["detectable"] < 0.01, item
    assert item["detectable"] <= cc.DEFAULT_DETECT  # the stated power the command enforces
    assert item["agrees"] is True and item["renderer"] == checked["name"] and item["spp"] == 1024
    assert item["reference_sha256"] == meta["exr_sha256"] == references.sha256_of(checked["refs"] / f"{SCENE}.exr")
    for key in ("version", "mode", "passes", "p", "date"):
        assert item.get(key) is not None, key


@pytest.mark.slow
def test_a_reference_one_percent_too_bright_fails_its_crosscheck(checked):
    out = checked["out_b"]
    assert checked["rc_b"] == 1, out
    assert f"{SCENE}: DIFFERS from" in out and f"do not: {SCENE}" in out
    # channel, size and z of the difference, and the diagnosis
    assert "channel G: the cross-check is" in out and "darker than the reference" in out and "z = -" in out
    assert "diagnosis" in out
    meta = json.loads((checked["bright"] / f"{SCENE}.json").read_text())
    now = [c for c in meta["crosschecks"] if c["reference_sha256"] == meta["exr_sha256"]]
    assert len(now) == 1 and now[0]["agrees"] is False and now[0]["difference"]


@pytest.mark.slow
def test_verdicts_say_who_crosschecked_the_reference_and_a_stale_one_does_not_count(checked):
    """A Mitsuba run judged against the cross-checked reference carries the label in metrics.json,
    the summary, the report and JUnit; against the copy 1 % too bright, the disagreement is said;
    against the copy whose record holds only the first cross-check (made against the other image),
    that one does not count: checked against itself."""
    who = cc.renderer_label(checked["name"], json.loads((checked["refs"] / f"{SCENE}.json").read_text())
                            ["crosschecks"][0]["version"])
    label = f"reference cross-checked by {who} (detects"
    for refs in (checked["refs"], checked["bright"], checked["stale"]):
        out = checked["base"] / f"run-{refs.name}"
        junit = checked["base"] / f"junit-{refs.name}.xml"
        proc = run_batch("-r", "mitsuba", "-s", SCENE, "--scale", "0.1", "--film", "cmf", "--references", refs,
                         "-o", out, "--junit", junit, "--flip", "off")
        assert (out / "metrics.json").is_file(), proc.stdout + proc.stderr
        (run,) = metrics(out)["runs"]
        if refs is checked["refs"]:
            assert label in run["judged_by"] and run["reference"]["crosschecks"][0]["agrees"] is True
            for page in ("summary.md", "report.html"):
                assert label in (out / page).read_text(), page
            assert label in junit.read_text()
        elif refs is checked["bright"]:
            assert label not in run["judged_by"] and f"reference DIFFERS from {who}" in run["judged_by"]
        else:
            assert who not in run["judged_by"] and "crosschecks" not in run["reference"]
            assert any("sha256 differs" in s for s in run["reference"]["crosschecks_not_counted"])


@pytest.mark.slow
def test_the_truth_table_in_the_docs_is_the_registries():
    """docs/verdict.md's scene -> truth table is what scripts/truth_table.py makes from the probe
    registry and the references' cross-checks (run --write after a cross-check or a new probe)."""
    proc = subprocess.run([sys.executable, str(ROOT / "scripts" / "truth_table.py"), "--check"], capture_output=True,
                          text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr


# -- agreement up to a recorded deviation (a scale model of the cross-checking renderer) ---------------
DEVIATION = """
[[deviation]]
id = "toy-two-percent"
backend = "toy_spectral"
scenes = ["{scene}"]
checks = ["noise test"]
scale = {scale}
scale_se = 0.0005
evidence = "planted by the test: the reference divided by 1.02"
explanation = "test"
date = "2026-12-05"
"""


@pytest.fixture(scope="module")
def deviating(tmp_path_factory):
    """One cross-check render by the toy renderer (a tenth of the resolution, 1024 spp) judged,
    from its kept passes, against a reference made 2 % too dark (so the renderer reads 1.02 times
    it: what a recorded deviation of scale 1.02 predicts): without the deviation, with a model that
    does not fit (1.05), with the right one against the reference 1 % too bright besides (planted),
    and with the right one against the 2 % reference. Returns each (exit status, output) and the folders."""
    base = tmp_path_factory.mktemp("crosscheck-known")
    refs, dev = base / "refs", base / "dev"
    rc, out = make_refs("-s", SCENE, "--scale", "0.1", "--spp", "2048", "--passes", "4", "--film", "cmf", "--out", refs)
    assert rc == 0, out
    files = {}
    for key, scale in (("none", None), ("wrong", 1.05), ("right", 1.02)):
        files[key] = base / f"{key}.toml"
        files[key].write_text("" if scale is None else DEVIATION.format(scene=SCENE, scale=scale))
    args = ("--crosscheck", "toy_spectral", "--renderers", TOY, "-s", SCENE, "--references", dev, "--spp", "1024")
    got = {}
    scaled_copy(refs, dev, 1 / 1.02, keep_crosschecks=False)
    got["none"] = make_refs(*args, "--known", files["none"], "--no-record")
    got["wrong"] = make_refs(*args, "--known", files["wrong"], "--no-record")
    scaled_copy(refs, dev, 1.01 / 1.02, keep_crosschecks=False)  # 1 % planted on the reference
    got["planted"] = make_refs(*args, "--known", files["right"])
    scaled_copy(refs, dev, 1 / 1.02, keep_crosschecks=False)
    got["right"] = make_refs(*args, "--known", files["right"])
    return dict(got=got, dev=dev, files=files)


@pytest.mark.slow
def test_a_crosscheck_agrees_up_to_a_deviation_only_where_its_model_fits(deviating):
    from spectral_bench.batch.verdict import known
    got = deviating["got"]
    rc, out = got["none"]
    assert rc == 1 and f"{SCENE}: DIFFERS from" in out, out
    assert "passes kept" in out
    rc, out = got["wrong"]  # judged again from the kept passes: no new render
    assert rc == 1 and "resuming, 2 of 2 passes already rendered" in out, out
    assert "the known deviation toy-two-percent (scale 1.05 +- 0.0005) does not fit" in out
    rc, out = got["planted"]  # the reference 1 % too bright besides: fails even under the deviation
    assert rc == 1 and f"{SCENE}: DIFFERS from" in out and "does not fit" in out, out
    rc, out = got["right"]
    assert rc == 0 and f"{SCENE}: agrees with" in out and "up to the known deviation toy-two-percent" in out, out
    meta = json.loads((deviating["dev"] / f"{SCENE}.json").read_text())
    (item,) = [c for c in meta["crosschecks"] if c["reference_sha256"] == meta["exr_sha256"]]
    assert item["agrees"] is True and item["agrees_under"] == "toy-two-percent"
    assert item["deviation"] == {"id": "toy-two-percent", "scale": 1.02, "scale_se": 0.0005}
    # its power under the model: the planted 1 % is above what it detects (and the stated 0.5 %)
    assert item["detectable"] <= cc.DEFAULT_DETECT < 0.01, item
    assert item["detectable"] >= item["detectable_plain"] * 0.99  # the model's uncertainty costs power
    assert item["difference"]  # the plain difference stays in the record
    counted, _ = cc.counting(meta, known.load(deviating["files"]["right"]))
    assert cc.label([cc.summary(c) for c in counted]).startswith("reference cross-checked by toy_spectral")
    assert "up to toy-two-percent (detects" in cc.label([cc.summary(c) for c in counted])
    assert cc.counting(meta, known.load(deviating["files"]["wrong"]))[0] == []  # another model: does not count


@pytest.mark.slow
def test_a_run_against_a_reference_crosschecked_up_to_a_deviation_says_so(deviating):
    """A Mitsuba run judged against that reference (with the run's --known file) carries "up to
    ID" in judged_by, metrics.json and the summary; with a deviation file whose model differs, the
    cross-check does not count (metrics.json says why) and the verdict names no cross-check."""
    assert deviating["got"]["right"][0] == 0
    base = deviating["dev"].parent
    for key in ("right", "wrong"):
        out = base / f"run-{key}"
        proc = run_batch("-r", "mitsuba", "-s", SCENE, "--scale", "0.1", "--film", "cmf", "--references",
                         deviating["dev"], "--known", deviating["files"][key], "-o", out, "--flip", "off")
        assert (out / "metrics.json").is_file(), proc.stdout + proc.stderr
        (run,) = metrics(out)["runs"]
        if key == "right":
            assert "reference cross-checked by toy_spectral" in run["judged_by"], run["judged_by"]
            assert "up to toy-two-percent (detects" in run["judged_by"]
            assert run["reference"]["crosschecks"][0]["agrees_under"] == "toy-two-percent"
            assert "up to toy-two-percent" in (out / "summary.md").read_text()
        else:
            # (macbeth's probes still judge it: not "checked against itself", but no cross-check is named)
            assert "crosschecks" not in run["reference"] and "cross-checked" not in run["judged_by"]
            assert any("no longer record" in w for w in run["reference"]["crosschecks_not_counted"])
