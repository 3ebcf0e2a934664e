"""Hostile run folders for property-based tests of batch/compare_runs.py (tests/hostile/test_fuzz_runs.py).

``mutations()`` draws a few changes to a copy of a real run folder (its metrics.json and its
files): fields set to wrong types, huge or non-finite numbers, path walks and absolute paths,
fields removed, metrics.json truncated or not an object, renders truncated, replaced by garbage,
by a decompression bomb (tests/exr_craft.py), by an image of another size or without its noise
channels, removed, or made symbolic links to a file outside the run, and a NEW/compare that is a
link out of the run.

``check(old, new, root, out)`` compares the two folders with compare_runs' main() and returns its
exit status after asserting the contract: 0 (every job judged ``same``), 1 (something listed as
changed, new or missing), 2 (an ``error:`` line naming a folder, file or field; nothing
written), 3 (each job it could not judge named on stderr, none of them called ``same``); never
an exception; nothing outside the output folder changed (``snapshot`` of ``root`` before and
after: every path, its type, its content or link target).
"""
import contextlib
import hashlib
import io
import json
import os
import shutil
import stat
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

import exr_craft

IMAGE = "ggx_copper_50/results/mitsuba/render.exr"
FIELDS = ("image", "resolution", "pass_times", "probes", "passes", "spp", "status", "scene", "backend", "mode",
          "metrics", "test", "reason", "baseline")
HOSTILE = (None, "", 0, -1, True, 1e308, -1e308, 5e-324, [], {}, "../../secret.exr", "/etc/hostname", "a" * 5000,
           [1e308, 1e-308], [0.0, 0.0], [-1.0, 2.0], ["x"], [[[]]], {"name": "x"}, [64], [64, 64, 64], [20000, 20000],
           [{"name": "p", "pass": True, "stat": {"measured": [1e308], "expected": [-1e308], "se": [0.0]}}],
           "ggx_copper_50/results/mitsuba", "ggx_copper_50/results/mitsuba/render.log", "<script>|\n\x1b[31m")


def _field():
    return st.tuples(st.just("field"), st.sampled_from(("old", "new")), st.sampled_from(FIELDS),
                     st.sampled_from(HOSTILE))


def _file():
    return st.tuples(st.just("file"), st.sampled_from(("old", "new")),
                     st.sampled_from(("truncate", "garbage", "bomb", "other_size", "one_pass", "remove", "link_out",
                                      "metrics_truncate", "metrics_not_object", "metrics_link_out", "compare_link_out",
                                      "drop_field", "duplicate_job")),
                     st.integers(0, 100))


def mutations():
    """One to four changes to the pair of folders."""
    return st.lists(st.one_of(_field(), _file()), min_size=1, max_size=4)


def _metrics(folder):
    return json.loads((folder / "metrics.json").read_text())


def _put_metrics(folder, data):
    path = folder / "metrics.json"
    if path.is_symlink():
        path.unlink()
    path.write_text(json.dumps(data, allow_nan=True))


def apply(mutation, folders, outside):
    """Apply one mutation to ``folders`` {"old": Path, "new": Path}; ``outside`` holds the files a
    hostile run points at (secret.exr, a folder of the user's)."""
    kind, which, what, arg = mutation
    folder = folders[which]
    try:
        data = _metrics(folder)
    except (OSError, ValueError):
        data = None
    runs = data.get("runs") if isinstance(data, dict) else None
    entry = runs[0] if isinstance(runs, list) and runs and isinstance(runs[0], dict) else None
    render = folder / IMAGE
    if kind == "field":
        if entry is not None:
            entry[what] = arg
            _put_metrics(folder, data)
        return
    if what == "truncate" and render.is_file():
        raw = render.read_bytes()
        render.write_bytes(raw[:len(raw) * arg // 100])
    elif what == "garbage":
        render.unlink(missing_ok=True)
        render.parent.mkdir(parents=True, exist_ok=True)
        render.write_bytes(b"v/1\x01" + os.urandom(arg * 10))
    elif what == "bomb":
        render.unlink(missing_ok=True)
        render.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(outside / "bomb.exr", render)
    elif what == "other_size":
        from spectral_bench.batch import exr
        render.unlink(missing_ok=True)
        size = 1 + arg % 70
        exr.write_image(render, ["R", "G", "B"], np.ones((size, size, 3), np.float32),
                        {f"stderr.{c}": np.full((size, size), 0.1, np.float32) for c in "RGB"})
    elif what == "one_pass" and render.is_file():
        from spectral_bench.batch import exr
        try:
            names, img = exr.read_image(render)
        except Exception:  # noqa: BLE001 - already broken by an earlier mutation
            return
        render.unlink()
        exr.write_image(render, names, img)
    elif what == "remove":
        render.unlink(missing_ok=True)
    elif what == "link_out":
        render.unlink(missing_ok=True)
        render.parent.mkdir(parents=True, exist_ok=True)
        render.symlink_to(outside / "secret.exr")
    elif what == "metrics_truncate" and (folder / "metrics.json").is_file():
        raw = (folder / "metrics.json").read_bytes()
        (folder / "metrics.json").write_bytes(raw[:len(raw) * arg // 100])
    elif what == "metrics_not_object":
        _put_metrics(folder, [data] if arg % 2 else arg)
    elif what == "metrics_link_out":
        (folder / "metrics.json").unlink(missing_ok=True)
        (folder / "metrics.json").symlink_to(outside / "user.json")
    elif what == "compare_link_out" and not (folder / "compare").exists():
        (folder / "compare").symlink_to(outside / "user_dir", target_is_directory=True)
    elif what == "drop_field" and entry is not None:
        entry.pop(FIELDS[arg % len(FIELDS)], None)
        _put_metrics(folder, data)
    elif what == "duplicate_job" and entry is not None:
        runs.append(dict(entry, mode=None if arg % 2 else entry.get("mode")))
        _put_metrics(folder, data)


def snapshot(root):
    """{relative path: (type, sha256 of its content or link target)} of everything under ``root``."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        for name in dirnames + filenames:
            path = Path(dirpath) / name
            st_ = os.lstat(path)
            if stat.S_ISLNK(st_.st_mode):
                out[str(path.relative_to(root))] = ("link", os.readlink(path))
            elif stat.S_ISDIR(st_.st_mode):
                out[str(path.relative_to(root))] = ("dir", None)
            else:
                out[str(path.relative_to(root))] = ("file", hashlib.sha256(path.read_bytes()).hexdigest(),
                                                    stat.S_IMODE(st_.st_mode))
    return out


def check(old, new, root, out=None):
    """compare_runs' main() on OLD and NEW (into ``out``, or its default NEW/compare[-N]); returns
    (exit status, stderr) after asserting the contract in this module's docstring."""
    from spectral_bench.batch import compare_runs
    before = snapshot(root)
    err, std = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
        code = compare_runs.main([str(old), str(new)] + (["-o", str(out)] if out else []))
    text = err.getvalue()
    after = snapshot(root)
    assert "Traceback" not in text, text
    written = [p for p in after if before.get(p) != after[p]]
    gone = [p for p in before if p not in after]
    assert not gone, (gone, text)
    if code == 2:
        assert text.startswith("error: ") and not written, (text, written)
        return code, text
    folder = Path(text.strip().splitlines()[-1].removeprefix("written to "))
    inside = [p for p in written if not (Path(root) / p).is_relative_to(folder)
              and not (Path(root) / p) == folder]
    assert not inside, (inside, folder)
    result = json.loads((folder / "compare.json").read_text())
    unjudged = [j for j in result["jobs"] if j["unjudged"]]
    if code == 0:
        assert not result["changed"] and not unjudged and all(j["baseline"]["status"] == "same" for j in result["jobs"]), result
    elif code == 1:
        assert result["changed"] and (any(j["changes"] for j in result["jobs"]) or result["new_jobs"] or result["missing_jobs"])
    else:
        assert code == 3 and unjudged and not result["changed"], (code, text)
        assert all("not judged" in text and compare_runs._printable(j["scene"])[:20] in text for j in unjudged)
        lines = (folder / "compare.md").read_text().splitlines()
        assert sum(l.startswith("| UNJUDGED |") for l in lines) == len(unjudged), lines
    return code, text
