"""Property-based fuzzing of load -> validate -> every writer (tests/scene_fuzz.py): each scene
ends in a validation error naming scene, object and field, or in exports that parse and stay in
their folder. A bounded number of scenes here; benchmarks/fuzz_scenes.py makes the long run
(benchmarks/FUZZ.md). Ordinary .blend files too (scene_fuzz.blend_scenes, tests/blend_builder.py):
batch/run.py --export-only on each, every scene exported or failed alone naming scene, object and
field (3 files of 4 scenes here, 20 of 6: both slow; each test's files built by one bpy child
and exported by one batch/run.py)."""
import tempfile

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import scene_fuzz



def fuzz(examples):
    """Derandomised (the same scenes on every run: CI is reproducible), no example database."""
    return settings(max_examples=examples, deadline=None, database=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])


def _one(scene):
    with tempfile.TemporaryDirectory() as d:
        return scene_fuzz.check(scene_fuzz.scene_text(scene), d)


@pytest.mark.slow
@fuzz(150)
@given(scene_fuzz.mutated_scenes())
def test_mutated_golden_scenes_fail_by_name_or_export_safely(scene):
    assert _one(scene) in ("invalid", "exported")


@pytest.mark.slow
@fuzz(10)
@given(scene_fuzz.schema_scenes())
def test_scenes_the_schema_admits_fail_by_name_or_export_safely(scene):
    assert _one(scene) in ("invalid", "exported")


@pytest.mark.slow
@fuzz(300)
@given(st.one_of(st.text(), st.sampled_from(scene_fuzz.HOSTILE_TEXT)))
def test_comment_text_cannot_end_or_escape_a_comment(text):
    from spectral_bench.exporters import names
    out = names.comment_text(text)
    assert "\n" not in out and "\r" not in out and "--" not in out and "*/" not in out and "\\" not in out
    assert all(" " <= c <= "~" for c in out)


@fuzz(300)
@given(st.lists(st.one_of(st.text(max_size=80), st.sampled_from(scene_fuzz.HOSTILE_TEXT)), min_size=1, max_size=6))
def test_safe_ids_are_valid_and_unique_ignoring_case(texts):
    from spectral_bench.exporters import names
    taken = []
    for text in texts:
        name = names.safe_id(text, taken)
        assert names.object_problem(name) is None and names.scene_problem(name) is None, (text, name)
        assert name.lower() not in {t.lower() for t in taken}
        taken.append(name)


def test_the_checker_sees_what_it_must_refuse(tmp_path):
    """The fuzz checks can fail: an export with an injected element, a comment outside the
    writer's grammar and a file outside the folder are each caught."""
    import json
    import xml.etree.ElementTree as ET
    scene = scene_fuzz.golden_scenes()["ggx_copper_50"]
    from spectral_bench.exporters import art_writer, mitsuba_writer
    path = mitsuba_writer.write(scene, tmp_path / "m")
    tree = ET.parse(path)
    ET.SubElement(tree.getroot(), "emitter", type="point")
    tree.write(path)
    with pytest.raises(AssertionError, match="emitters"):
        scene_fuzz.check_mitsuba(path, scene)
    arm, _ = art_writer.write(scene, tmp_path / "a")
    arm.write_text(arm.read_text().replace("// floor", "// floor\n__attribute__((constructor)) static void f(void) { abort(); }"))
    with pytest.raises(AssertionError, match="grammar"):
        scene_fuzz.check_art(arm, scene_fuzz.art_vocabulary())
    from spectral_bench.exporters import pbrt_writer
    pbrt = pbrt_writer.write(scene, tmp_path / "p")
    scene_fuzz.check_pbrt(pbrt, scene)
    pbrt.write_text(pbrt.read_text().replace("# floor\n", "# floor\nShape \"sphere\"\n", 1))  # the object's comment, not its backing's
    with pytest.raises(AssertionError, match="shape was injected"):
        scene_fuzz.check_pbrt(pbrt, scene)
    pbrt.write_text(pbrt.read_text().replace("WorldBegin", "WorldBegin\nInclude \"/etc/passwd\""))
    with pytest.raises(AssertionError, match="unexpected directive"):
        scene_fuzz.check_pbrt(pbrt, scene)
    (tmp_path / "outside").mkdir()
    before = scene_fuzz.snapshot(tmp_path)
    (tmp_path / "outside" / "x").write_text(json.dumps({}))
    assert scene_fuzz.snapshot(tmp_path) != before


def _blend_files(strategy, examples, tmp_path):
    """The ``examples`` .blend files Hypothesis draws from ``strategy`` (derandomised, as ``fuzz``),
    built by one bpy child and exported by one batch/run.py (scene_fuzz.check_blends: two child
    start-ups in all instead of two per file); every file's scenes exported or failed by name."""
    files = []

    @fuzz(examples)
    @given(strategy)
    def draw(specs):
        files.append(specs)

    draw()
    assert len(files) == examples, len(files)
    for statuses in scene_fuzz.check_blends(files, tmp_path):
        assert set(statuses.values()) <= {"exported", "failed"}


@pytest.mark.slow  # renders (or builds .blend files) through the real entry point: the full suite, not the fast subset
def test_ordinary_blend_files_export_scene_by_scene_or_fail_by_name(tmp_path):
    """Hypothesis-made .blend files (3 files of 4 scenes, built by one bpy child) through
    batch/run.py --export-only: each scene exported or failed alone naming scene, object and field."""
    _blend_files(scene_fuzz.blend_scenes(), 3, tmp_path)


@pytest.mark.slow
def test_ordinary_blend_files_many(tmp_path):
    _blend_files(scene_fuzz.blend_scenes(n=6), 20, tmp_path)
