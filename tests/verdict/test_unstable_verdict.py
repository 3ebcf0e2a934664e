"""Issue 45 item 6 in the fast subset: a probe's verdict that flips within noise is "unstable", not
a change, and one that moved beyond noise is CHANGED. The run folders are
tests/verdict/test_verdict_cells.py's ``_probe_run`` (real EXRs, hand-made records), and
compare_runs' ``main(argv)`` is called in this process (two ``batch/compare_runs.py`` children cost
2 s of CPU, well under 1 s here; the child's exit status is tested there on rendered runs)."""
import contextlib
import io
import json
import re
import types

import pytest

from conftest import ROOT
from test_verdict_cells import _probe_run


def compare_runs(*args):
    """compare_runs' main() in this process: its exit status and what it printed."""
    from spectral_bench.batch import compare_runs as cr
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), contextlib.chdir(ROOT):
        code = cr.main([str(a) for a in args])
    return types.SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


def test_a_probe_that_flips_within_noise_is_unstable_here_and_one_that_moved_is_changed(tmp_path):
    """A probe 2.5 standard errors off passes at alpha 0.01, 2.8 off fails: the same render with
    other noise flips its status while the images and the probe's residuals agree within noise;
    compare_runs names it unstable with the probe's deviation against what it detects, exit 0. The
    probe 10 standard errors off (moved beyond both runs' noise) is CHANGED, exit 1."""
    old, new, moved = tmp_path / "old", tmp_path / "new", tmp_path / "moved"
    ro, rn = _probe_run(old, 1, 1.025), _probe_run(new, 2, 1.028)
    assert (ro["status"], rn["status"]) == ("ok", "failed")  # the premise: the probe's verdict flips
    cmp = compare_runs(old, new)
    assert cmp.returncode == 0, cmp.stdout[-3000:] + cmp.stderr[-2000:]
    (j,) = json.loads((new / "compare" / "compare.json").read_text())["jobs"]
    det = rn["detectable"]["probes"]["p"]
    m = re.fullmatch(r"verdict unstable: probe p's deviation ([0-9.]+) % is at its detectable ([0-9.]+) % "
                     r"\(status ok -> failed, probe p pass -> FAIL; the images agree within noise\)", j["unstable"])
    assert m and j["changed"] is False, j
    assert float(m.group(2)) == pytest.approx(100 * det, rel=0.05)
    assert float(m.group(1)) == pytest.approx(100 * (1.025 + 1.028) / 2 - 100, rel=0.05)  # both runs' own, pooled
    assert "| unstable | s |" in cmp.stdout

    _probe_run(moved, 3, 1.10)
    cmp = compare_runs(old, moved)
    assert cmp.returncode == 1, cmp.stdout[-3000:] + cmp.stderr[-2000:]
    (j,) = json.loads((moved / "compare" / "compare.json").read_text())["jobs"]
    assert j["changed"] and j["unstable"] is None and any(c.startswith("probe p moved beyond noise") for c in j["changes"]), j
    assert "| CHANGED | s |" in cmp.stdout


def test_the_baseline_summary_and_the_report_say_unstable_as_compare_runs_does():
    """A ``same`` baseline record whose verdicts flipped within noise (``unstable``) is shown as
    unstable in summary.md's baseline section (its row and its count), the report's baseline line
    and the panel's (baseline.shown_status), as compare_runs lists it; its status stays ``same``."""
    from spectral_bench.batch.report import html
    from spectral_bench.batch.verdict import baseline
    flipped = "verdict unstable: the deviation 0.10 % is at the test's detectable 0.11 % (status ok -> failed)"
    recs = {"a": {"run": "old", "status": "same", "unstable": flipped, "reason": flipped},
            "b": {"run": "old", "status": "same", "unstable": None, "reason": ""},
            "c": {"run": "old", "status": "changed", "reason": "image differs beyond noise"}}
    assert [baseline.shown_status(r) for r in recs.values()] == ["unstable", "same", "changed"]
    runs = [{"scene": s, "backend": "mitsuba", "mode": "m", "baseline": r} for s, r in recs.items()]
    text = baseline.summary_section(runs)
    assert "Baseline: old. 1 changed, 1 unstable, 1 same." in text, text
    rows = [line for line in text.splitlines() if line.startswith("| ") and "mitsuba" in line]
    assert [r.split(" | ")[0] for r in rows] == ["| changed", "| unstable", "| same"], rows
    assert recs["a"]["status"] == "same"
    line = html._baseline(None, {"baseline": recs["a"]})
    assert line["text"].startswith("against baseline old: unstable"), line
