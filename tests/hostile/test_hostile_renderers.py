"""Declared renderers that misbehave (issue 30): real shell-script renderers whose children outlive
them, hold their output pipe, hang, flood their output or write a corrupt EXR. Nothing a pass
started is left in the process table afterwards (every process carrying the test's marker in its
environment, which a renderer's children inherit, is gone or a zombie); a renderer is judged by its
own exit; its output is kept head and tail in bounded memory; a corrupt EXR fails the pass, named.

Synchronisation is by files the processes write (pid files), never by sleeping: the only clock is
the pass time-out, which one test is about.
"""
import json
import os
import subprocess
import sys
import textwrap
import uuid

import psutil
import pytest

from fake_renderer import FAKE, ROOT, declaration, render  # noqa: F401 - the stand-in renderer script and the loop driver
from spectral_bench.batch.backends import passes

# A wrapper, as real renderers are often started: a shell script that runs the renderer behind it.
# $1: what to do; then the output, spp, seed, width, height of the pass. The fake renderer (FAKE,
# written beside it as fake.py) writes the EXR; a background child, whose pid is written to
# $PIDS/child.<seed> by itself, keeps the wrapper's stdout and stderr open.
WRAPPER = textwrap.dedent('''\
    #!/bin/sh
    what=$1; out=$2; spp=$3; seed=$4; w=$5; h=$6
    here=$(dirname "$0")
    child() { sh -c 'echo $$ > "$0.tmp" && mv "$0.tmp" "$0" && exec sleep 3600' "$PIDS/child.$seed" & }
    case $what in
      orphan)   "$PYTHON" "$here/fake.py" seed "$out" "$spp" "$seed" "$w" "$h" && child; exit 0 ;;
      hang)     child; wait ;;
      flood)    "$PYTHON" -c 'import sys
    o = sys.stdout.buffer
    o.write(b"HEAD-MARK\\n")
    for _ in range(100): o.write(b"x" * 1048575 + b"\\n")
    o.write(b"TAIL-MARK\\n")' && "$PYTHON" "$here/fake.py" seed "$out" "$spp" "$seed" "$w" "$h" ;;
      corrupt)  echo "not an EXR" > "$out"; exit 0 ;;
      truncated) "$PYTHON" "$here/fake.py" seed "$out" "$spp" "$seed" "$w" "$h" && "$PYTHON" -c 'import os, sys
    p = sys.argv[1]; os.truncate(p, os.path.getsize(p) // 2)' "$out" ;;
    esac
    ''')


@pytest.fixture
def wrapper(tmp_path, monkeypatch):
    """(declared options for ``render``, the marker, the pid folder) of the wrapper renderer."""
    (tmp_path / "fake.py").write_text(FAKE)
    (tmp_path / "wrapper.sh").write_text(WRAPPER)
    pids = tmp_path / "pids"
    pids.mkdir()
    mark = uuid.uuid4().hex
    env = {"PIDS": str(pids), "PYTHON": sys.executable, "HOSTILE_RENDERER_MARK": mark}
    return env, mark, pids


def declared(env, what, **extra):
    return dict({"command": ["/bin/sh", "{here}/wrapper.sh", what, "{output}", "{spp}", "{seed}", "{width}", "{height}",
                             "{scene}"], "env": env}, **extra)


def leftovers(mark):
    """Processes (not zombies) whose environment carries ``mark``: what the renderer started."""
    found = []
    for p in psutil.process_iter(["pid", "status"]):
        try:
            if p.info["status"] != psutil.STATUS_ZOMBIE and p.environ().get("HOSTILE_RENDERER_MARK") == mark:
                found.append(p.pid)
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            pass
    return found


def gone(pid):
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


@pytest.fixture(params=["select", "threads"])
def collect(request, monkeypatch):
    """Both ways a pass's output is read: selecting on its pipes (POSIX) and reader threads (the
    Windows route, run here on Linux)."""
    if request.param == "threads":
        monkeypatch.setattr(passes, "COLLECT", passes._collect_threads)
    return request.param


def test_a_renderer_that_exits_0_leaving_a_child_on_its_stdout_is_judged_by_its_exit(tmp_path, wrapper, collect):
    """Its child keeps the pipe open for an hour: the pass is the renderer's (exit 0, a good EXR),
    not a time-out, and the child is ended with the pass."""
    env, mark, pids = wrapper
    info = render(tmp_path, "seed", passes_n=2, timeout=30, declared=declared(env, "orphan"))
    assert info["passes"] == 2, info
    children = sorted(pids.glob("child.*[0-9]"))
    assert len(children) == 2  # each pass started one
    assert all(gone(int(p.read_text())) for p in children)
    assert leftovers(mark) == []


def test_a_time_out_ends_the_real_renderer_behind_a_shell_wrapper(tmp_path, wrapper, collect):
    """The wrapper waits on its child: the pass times out, and both the wrapper and the renderer
    behind it are gone afterwards (only the direct child used to be killed)."""
    env, mark, pids = wrapper
    with pytest.raises(passes.BackendFailure, match="timed out"):
        render(tmp_path, "seed", passes_n=1, declared=declared(env, "hang", timeout=3))
    child = pids / "child.0"
    assert child.is_file(), "the renderer behind the wrapper had not started within the 3 s time-out"
    assert gone(int(child.read_text()))
    assert leftovers(mark) == []


@pytest.mark.slow  # over about 1 s of CPU (1.2-2.6 s measured with ART and pbrt built, 2026-12-06: benchmarks/TESTS.md)
def test_a_renderer_flooding_its_output_is_kept_head_and_tail_in_bounded_memory(tmp_path, wrapper):
    """100 MB on stdout: render.log keeps its first and last 64 kB and says how much was dropped;
    the process running the pass grows by far less than the output (measured in a child: its peak
    resident memory before and after the render)."""
    env, mark, _pids = wrapper
    script = textwrap.dedent(f'''
        import json, resource, sys
        from pathlib import Path
        sys.path.insert(0, {str(ROOT)!r})
        sys.path.insert(0, {str(ROOT / "tests")!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        import fake_renderer as t
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        t.render(Path({str(tmp_path)!r}), "seed", passes_n=1, declared={declared(env, "flood")!r})
        print(json.dumps([before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss]))
        ''')
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    before_kb, after_kb = json.loads(proc.stdout.strip().splitlines()[-1])
    assert (after_kb - before_kb) * 1024 < 30e6, (before_kb, after_kb)  # the output alone is 100 MB
    log = (tmp_path / "render.log").read_text()
    assert len(log) < 300_000 and "HEAD-MARK" in log and "TAIL-MARK" in log
    assert f"[... {100 * 2 ** 20 + 20 - 2 * passes.OUTPUT_HEAD} bytes of output dropped" in log
    assert leftovers(mark) == []


@pytest.mark.parametrize("what", ["corrupt", "truncated"])
def test_a_corrupt_exr_fails_the_pass_naming_the_file_and_is_retried(tmp_path, wrapper, what):
    env, _mark, _pids = wrapper
    with pytest.raises(passes.BackendFailure) as err:
        render(tmp_path, "seed", passes_n=1, declared=declared(env, what))
    text = str(err.value)
    assert "pass 1/1 (seed 0) failed twice" in text and "pass0.exr" in text and "cannot be read" in text, text
    assert "internal error" not in text
    assert "failed (attempt 1)" in (tmp_path / "render.log").read_text()


def test_capped_output_keeps_head_and_tail():
    out = passes.CappedOutput(head=4, tail=3)
    for chunk in (b"ab", b"cdefg", b"hij", b"", b"k"):
        out.add(chunk)
    assert (bytes(out.head), bytes(out.tail), out.dropped) == (b"abcd", b"ijk", 4)
    assert out.text().startswith("abcd\n[... 4 bytes of output dropped") and out.text().endswith("...]\nijk")
    small = passes.CappedOutput(head=4, tail=3)
    small.add(b"abcdef")
    assert small.text() == "abcdef"


def test_an_interrupted_run_ends_the_passes_under_way(tmp_path, wrapper):
    """Ctrl-C reaches the runner, not a pass in its own session: the engine's stop_all kills the
    groups of the passes under way, so the render thread ends (the pass stopped, not retried) and
    nothing is left.
    The pass is known to be under way from the pid file its renderer writes."""
    import concurrent.futures as cf
    import time
    env, mark, pids = wrapper
    with cf.ThreadPoolExecutor(1) as pool:
        fut = pool.submit(render, tmp_path, "seed", 1, 0, 600, declared(env, "hang"))
        deadline = time.monotonic() + 120
        while not (pids / "child.0").is_file() and not fut.done() and time.monotonic() < deadline:
            time.sleep(0.05)  # waiting for the marker, not for a duration: the pass is under way once it exists
        assert (pids / "child.0").is_file(), fut.exception() if fut.done() else "no pid file in 120 s"
        passes.stop_all()
        with pytest.raises(passes.PassStopped, match="the run was interrupted"):
            fut.result(timeout=60)
    assert gone(int((pids / "child.0").read_text())) and leftovers(mark) == []


@pytest.mark.slow
def test_nothing_a_run_started_is_left_when_it_ends(tmp_path, wrapper):
    """batch/run.py end to end with the wrapper renderer whose every pass leaves a child holding its
    output: the run finishes its passes (judged by the renderer's exit) and, once it has exited, no
    process carrying the renderer's marker is left in the process table."""
    from conftest import GOLDEN, metrics, run_batch
    env, mark, pids = wrapper
    decl = tmp_path / "wrapped.toml"
    decl.write_text(textwrap.dedent(f'''
        [renderers.wrapped]
        command = ["/bin/sh", "{{here}}/wrapper.sh", "orphan", "{{output}}", "{{spp}}", "{{seed}}", "{{width}}", "{{height}}", "{{scene}}"]
        reads = "json"
        models = ["spectral"]
        timeout = 300
        env = {{ {", ".join(f"{k} = {json.dumps(v)}" for k, v in env.items())} }}
        '''))
    out = tmp_path / "out"
    proc = run_batch("-i", GOLDEN / "ggx_copper_50_isolated.json", "--renderers", decl, "-r", "wrapped",
                     "--scale", 0.0625, "--spp", 4, "--passes", 2, "--no-flip", "-o", out, timeout=600)
    assert proc.returncode in (0, 1, 3), proc.stderr[-3000:]
    run = metrics(out)["runs"][0]
    assert run["passes"] == 2 and "timed out" not in run["reason"], run
    assert len(list(pids.glob("child.*[0-9]"))) == 2  # each pass left a child behind
    assert leftovers(mark) == []


def test_a_version_command_leaving_a_child_on_its_stdout_is_read_and_its_child_ended(tmp_path, wrapper):
    """The declared ``version`` command runs like a pass: its first line is read once it exits
    (its child holding the pipe used to make it wait for the 60 s limit and record "unknown"),
    and the child is ended with it."""
    from spectral_bench.batch import backends
    env, mark, pids = wrapper
    version = ["/bin/sh", "-c", 'echo "wrapped 1.2"; sleep 3600 & echo $! > "$PIDS/version.pid"; exit 0']
    b = backends.get("fake_seed", declaration=declaration(tmp_path, "seed", version=version, env=env))
    assert b.version() == "wrapped 1.2"
    assert gone(int((pids / "version.pid").read_text())) and leftovers(mark) == []


@pytest.mark.slow
def test_closing_a_local_cluster_ends_the_passes_in_its_workers(tmp_path, wrapper):
    """A pass under way in a Dask worker (its own session: the worker's death alone would leave the
    renderer behind a wrapper running) is ended with its group when the cluster closes (the
    preload's teardown). Known to be under way from the pid file it writes."""
    import time
    from spectral_bench.batch.jobs import engines
    env, mark, pids = wrapper
    pid_file = pids / "child.cluster"
    cmd = ["/bin/sh", "-c", 'sleep 3600 & echo $! > "$0.tmp" && mv "$0.tmp" "$0"; wait', str(pid_file)]
    engine = engines.make("local:1", timeout=60)
    try:
        fut = engine.client.submit(passes.run_captured, cmd, 600, dict(os.environ, **env), pure=False)
        deadline = time.monotonic() + 120
        while not pid_file.is_file() and not fut.done() and time.monotonic() < deadline:
            time.sleep(0.05)  # waiting for the marker, not for a duration
        assert pid_file.is_file(), fut.exception() if fut.done() else "no pid file in 120 s"
    finally:
        engine.close()
    assert gone(int(pid_file.read_text())) and leftovers(mark) == []
