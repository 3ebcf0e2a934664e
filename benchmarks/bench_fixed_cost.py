"""A job's fixed cost: where a run's wall time goes, per job and phase (issue 23, item 2).

    .venv/bin/python benchmarks/bench_fixed_cost.py                       # the tiny suite: --scale 0.125 --spp 4
    .venv/bin/python benchmarks/bench_fixed_cost.py --default [--write]   # the default suite (scenes' own settings)
    .venv/bin/python benchmarks/bench_fixed_cost.py --smoke               # seconds: one scene

Runs ``batch/run.py -r mitsuba`` in a child process exactly as a user does, with timestamps
around each phase (this script's child wraps the functions that the engine calls; nothing else
changes): *start* (interpreter, imports, reading the scenes, planning: until the first export),
per job *export* (the IR JSON and the backend's scene files), *render* (the pass loop: a warm
worker's scene load and passes, the render EXR; Mitsuba's own render seconds beside it),
*verdict* (reading the render, the noise test, probes, the previews; FLIP is sent to its warm
child), *flip* (waiting for FLIP's answer, while the next verdict runs), *record*
(metrics.json rewritten, the log line, the report's data files of the job), then *report* (summary.md, report.html with its data
files) and *exit* (closing the warm workers). Renders and verdicts overlap (the default engine
judges job k while job k+1 renders: batch/jobs/engines.py), so the phases add up to more than
the wall time; the wall time against the sum of the render phases is the figure of merit.

CPU (issue 31, decision 3): beside the wall times, the CPU seconds of judging against those of
rendering, per job and in all. Rendering: the render workers' processes during a job's render
call (every child process of the run but the FLIP child: psutil), plus the render thread's own
(``time.thread_time``) for the pass loop and the export. Judging: the verdict thread's CPU in the
job's verdict (noise test, probes, previews), the FLIP child's CPU between a job's request and its
answer, the main thread's in the job's record (metrics.json, log, the page's data) and in the
report (summary.md, report.html). The judging share is judging / rendering CPU; what neither
claims (start-up, imports, idle threads) is the rest of the run's CPU.

The tiny suite is issue 23's ``--scale 0.125 --spp 4``: the 620x420 charts, which 0.125 divides
into no integer fraction, render at 0.1 (62x42), the nearest scale their references judge
(docs/verdict.md, "Any resolution judged"; the run's log says so).

Prints Markdown tables; --write records them in benchmarks/ENGINES.md. Run it on a quiet machine
(``uptime`` load is printed with the result).
"""
import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

T0 = time.perf_counter()
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import machine  # noqa: E402

TINY = ["--scale", "0.125", "--spp", "4"]
SMOKE = ["--scale", "0.25", "--spp", "4", "-s", "ggx_copper_50"]
PHASES = ("export", "render", "verdict", "flip", "record")
CPU = ("render", "export", "verdict", "flip", "record")  # per-job CPU seconds (module doc)
JUDGING = ("verdict", "flip", "record")  # and the report's, once per run


def _child(trace_path, argv):
    """In the child: wrap the engine's calls with timestamps, run batch/run.py, write the trace."""
    import threading
    sys.path.insert(0, str(ROOT))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch import run as entry
    from spectral_bench.batch.jobs import job as jobs, runner
    from spectral_bench.batch.report import html, summary
    events, lock = [], threading.Lock()

    import psutil
    from spectral_bench.batch.verdict import flip_isolated
    me, is_flip = psutil.Process(), {}

    def note(phase, label, t0, **extra):
        with lock:
            events.append(dict(phase=phase, job=label, t0=t0 - T0, t1=time.perf_counter() - T0, **extra))

    def process_cpu(p):
        t = p.cpu_times()
        return t.user + t.system

    def render_side_cpu():
        """CPU seconds so far of every child process of the run but the FLIP child."""
        total = 0.0
        for p in me.children(recursive=True):
            try:
                if p.pid not in is_flip:
                    is_flip[p.pid] = any("flip_isolated.py" in a for a in p.cmdline())
                if not is_flip[p.pid]:
                    total += process_cpu(p)
            except psutil.Error:  # gone meanwhile
                pass
        return total

    def timed(phase, fn, label_of=lambda *a, **k: None):
        def wrapper(*a, **k):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                note(phase, label_of(*a, **k), t0, cpu=time.thread_time() - c0)
        return wrapper

    backend_of = jobs.backend_of

    def timed_backend(job):
        backend = backend_of(job)
        render = backend.render

        def rendered(*a, **k):
            t0, c0, w0 = time.perf_counter(), time.thread_time(), render_side_cpu()
            info = render(*a, **k)
            thread = time.thread_time() - c0
            note("render", job["label"], t0, render_s=info.get("time_s"), cpu=render_side_cpu() - w0 + thread,
                 thread_cpu=thread)
            return info
        backend.render = rendered
        return backend

    send, receive = flip_isolated.FlipWorker.send, flip_isolated.FlipWorker.receive

    def flip_send(self, ref, test, map_path, *deadline):  # FlipWorker.send's own arguments, passed on as they are
        self.bench = (time.perf_counter(), process_cpu(psutil.Process(self.proc.pid)), Path(map_path))
        return send(self, ref, test, map_path, *deadline)

    def flip_receive(self, *deadline):
        t0, c0, map_path = self.bench
        try:
            c1 = process_cpu(psutil.Process(self.proc.pid))
        except psutil.Error:
            c1 = c0
        out = receive(self, *deadline)
        try:
            c1 = process_cpu(psutil.Process(self.proc.pid))
        except psutil.Error:  # died: what it had spent before
            pass
        # OUT/<scene>/results/<backend>/flip.exr: the job's default label "<scene> (<backend>)"
        note("flip_cpu", f"{map_path.parts[-4]} ({map_path.parts[-2]})", t0, cpu=c1 - c0)
        return out
    flip_isolated.FlipWorker.send, flip_isolated.FlipWorker.receive = flip_send, flip_receive
    jobs.backend_of = timed_backend
    jobs.execute = timed("execute", jobs.execute, lambda job: job["label"])
    jobs.judge = timed("verdict", jobs.judge, lambda job, *a, **k: job["label"])
    runner.Run.record = timed("record", runner.Run.record, lambda self, job, result: job["label"])
    from spectral_bench.batch.jobs import engines
    if hasattr(engines.LocalEngine, "_finish"):  # FLIP collected after the verdict, in a third thread
        engines.LocalEngine._finish = staticmethod(timed("flip", engines.LocalEngine._finish, lambda job, judged: job["label"]))
    summary.write = timed("report", summary.write)
    html.write = timed("report", html.write)
    try:
        code = entry.main(["run.py", *argv])
    finally:
        import resource
        me = resource.getrusage(resource.RUSAGE_SELF)
        note("exit", None, time.perf_counter(), cpu_s=me.ru_utime + me.ru_stime)
        Path(trace_path).write_text(json.dumps(events))
    return code


def measure(args_run, out):
    """Run the suite in a child; returns (wall s, CPU s, exit status, trace events, metrics runs)."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        trace = Path(f.name)
    try:
        t0, cpu0 = time.perf_counter(), _children_cpu()
        proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", str(trace), "--",
                               "-r", "mitsuba", "-o", str(out), *args_run],
                              capture_output=True, text=True, cwd=ROOT, stdin=subprocess.DEVNULL)
        wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
        if not trace.is_file() or not trace.read_text():
            raise SystemExit(f"the run left no trace (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
        events = json.loads(trace.read_text())
    finally:
        trace.unlink(missing_ok=True)
    sys.path.insert(0, str(ROOT))
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch import records  # through the reader: the per-block arrays put back
    runs = records.read(out)["runs"]
    size = (Path(out) / "metrics.json").stat().st_size
    beside = sum(p.stat().st_size for p in Path(out).rglob("probe_arrays-*.npz"))
    events.append({"phase": "metrics.json", "job": None, "t0": 0.0, "t1": 0.0, "bytes": size, "beside": beside})
    return wall, cpu, proc.returncode, events, runs


def _children_cpu():
    """User + system CPU seconds of the finished children (the run, its workers, FLIP): a figure
    that a busy machine disturbs less than the wall time."""
    import resource
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def breakdown(wall, events, runs):
    """Per job {phase: seconds} and the run's totals."""
    jobs = {}
    for e in events:
        if e["job"] is None:
            continue
        row = jobs.setdefault(e["job"], {"cpu": {}})
        if e["phase"] == "flip_cpu":
            row["cpu"]["flip"] = row["cpu"].get("flip", 0.0) + e["cpu"]
            continue
        row[e["phase"]] = row.get(e["phase"], 0.0) + e["t1"] - e["t0"]
        if e.get("cpu") is not None and e["phase"] in CPU + ("execute",):
            row["cpu"][e["phase"]] = row["cpu"].get(e["phase"], 0.0) + e["cpu"]
        if e["phase"] == "render":
            row["render_s"] = e.get("render_s") or 0.0
            row["render_thread_cpu"] = row.get("render_thread_cpu", 0.0) + e.get("thread_cpu", 0.0)
    for row in jobs.values():  # export: what execute spends before the pass loop
        row["export"] = max(0.0, row.get("execute", 0.0) - row.get("render", 0.0))
        row["cpu"]["export"] = max(0.0, row["cpu"].pop("execute", 0.0) - row.pop("render_thread_cpu", 0.0))
    first = min((e["t0"] for e in events if e["phase"] == "execute"), default=0.0)
    last_record = max((e["t1"] for e in events if e["phase"] == "record"), default=first)
    report = sum(e["t1"] - e["t0"] for e in events if e["phase"] == "report")
    exit_t = max((e["t1"] for e in events if e["phase"] == "exit"), default=last_record)
    totals = {p: sum(r.get(p, 0.0) for r in jobs.values()) for p in PHASES + ("render_s",)}
    totals["cpu"] = {p: sum(r["cpu"].get(p, 0.0) for r in jobs.values()) for p in CPU}
    totals["cpu"]["report"] = sum(e.get("cpu") or 0.0 for e in events if e["phase"] == "report")
    totals["metrics_bytes"] = next(((e["bytes"], e["beside"]) for e in events if e["phase"] == "metrics.json"), (0, 0))
    totals["main_cpu"] = max((e.get("cpu_s") or 0.0 for e in events if e["phase"] == "exit"), default=0.0)
    totals.update(start=first, jobs_span=last_record - first, report=report, wall=wall,
                  exit=max(0.0, wall - exit_t), tail=max(0.0, exit_t - last_record - report),
                  mitsuba_wall=sum(r.get("wall_s") or 0.0 for r in runs))
    return jobs, totals


def tables(title, argv, wall, cpu, code, jobs, totals, load):
    n = max(len(jobs), 1)
    lines = [f"### {title}", "", f"`batch/run.py -r mitsuba {' '.join(argv)}`: {len(jobs)} jobs, exit {code}; "
             f"machine {machine()}; Python {platform.python_version()}; load before {load[0]}, after {load[1]}.", "",
             "| phase | where | total s | per job s |", "|---|---|---|---|",
             f"| start | main: interpreter, imports, scenes, plan | {totals['start']:.2f} | |"]
    where = {"export": "render thread: IR JSON, scene files", "render": "render thread + warm worker: load, passes, EXR",
             "verdict": "verdict thread: noise test, probes, previews; FLIP sent to its child",
             "flip": "finishing thread: waiting for the FLIP child's answer",
             "record": "main: metrics.json, log, progress, the page's data files (view.js)"}
    for p in PHASES:
        lines.append(f"| {p} | {where[p]} | {totals[p]:.2f} | {totals[p] / n:.3f} |")
    lines += [f"| (Mitsuba's render calls) | worker | {totals['render_s']:.2f} | {totals['render_s'] / n:.3f} |",
              f"| jobs, first export to last record | overlapped | {totals['jobs_span']:.2f} | {totals['jobs_span'] / n:.3f} |",
              f"| report | main: summary.md, report.html | {totals['report']:.2f} | |",
              f"| exit | closing workers, interpreter | {totals['exit'] + totals['tail']:.2f} | |",
              f"| **wall** | | **{wall:.2f}** | |",
              f"| CPU (run, workers, FLIP: user + system) | | {cpu:.2f} | {cpu / n:.3f} |",
              f"| of which the runner's process (all its threads) | | {totals['main_cpu']:.2f} | {totals['main_cpu'] / n:.3f} |", "",
              f"Wall / sum of render phases: {wall / max(totals['render'], 1e-9):.2f}x "
              f"(render phases {totals['render']:.1f} s; metrics.json wall_s sum {totals['mitsuba_wall']:.1f} s: "
              f"{wall / max(totals['mitsuba_wall'], 1e-9):.2f}x).", "",
              f"metrics.json {totals['metrics_bytes'][0] / 1e3:.1f} kB; the per-block arrays beside the images "
              f"(probe_arrays-*.npz) {totals['metrics_bytes'][1] / 1e3:.1f} kB.", ""]
    lines += ["| job | export s | render s | Mitsuba s | verdict s | FLIP wait s | record s |", "|---|---|---|---|---|---|---|"]
    for label, r in jobs.items():
        lines.append(f"| {label} | {r.get('export', 0):.3f} | {r.get('render', 0):.3f} | {r.get('render_s', 0):.3f} | "
                     f"{r.get('verdict', 0):.3f} | {r.get('flip', 0):.3f} | {r.get('record', 0):.3f} |")
    return "\n".join(lines + [""] + cpu_table(jobs, totals, cpu))


def judging_share(c):
    """(rendering CPU s, judging CPU s, judging / rendering) of a {part: CPU s} dict."""
    rendering = c.get("render", 0.0) + c.get("export", 0.0)
    judging = sum(c.get(p, 0.0) for p in JUDGING + ("report",))
    return rendering, judging, judging / rendering if rendering > 0 else float("nan")


def cpu_table(jobs, totals, cpu):
    """Issue 31: CPU seconds of judging beside rendering's, per job and in all (module doc)."""
    c = totals["cpu"]
    rendering, judging, share = judging_share(c)
    lines = ["CPU seconds: judging (verdict: noise test, probes, previews; FLIP's child; record; report) "
             "beside rendering (the render workers' processes and the render thread; export).", "",
             "| job | render CPU s | export CPU s | verdict CPU s | FLIP CPU s | record CPU s | judging / rendering |",
             "|---|---|---|---|---|---|---|"]
    for label, r in jobs.items():
        rj = r["cpu"]
        lines.append(f"| {label} | {rj.get('render', 0):.3f} | {rj.get('export', 0):.3f} | {rj.get('verdict', 0):.3f} | "
                     f"{rj.get('flip', 0):.3f} | {rj.get('record', 0):.3f} | {judging_share(rj)[2]:.0%} |")
    lines += [f"| **all jobs** (+ report {c['report']:.2f}) | {c['render']:.2f} | {c['export']:.2f} | {c['verdict']:.2f} | "
              f"{c['flip']:.2f} | {c['record']:.2f} | **{share:.0%}** |", "",
              f"Judging {judging:.2f} s of CPU against rendering's {rendering:.2f} s: **{share:.0%}** "
              f"(verdicts {c['verdict']:.2f}, FLIP {c['flip']:.2f}, record {c['record']:.2f}, report {c['report']:.2f}); "
              f"the run's CPU {cpu:.2f} s, of which {max(cpu - rendering - judging, 0.0):.2f} s neither "
              "(start-up, imports, idle threads).", ""]
    return lines


def main():
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        sep = sys.argv.index("--")
        return _child(sys.argv[2], sys.argv[sep + 1:])
    ap = argparse.ArgumentParser()
    ap.add_argument("--default", action="store_true", help="the default suite (every scene at its own settings)")
    ap.add_argument("--smoke", action="store_true", help="one scene, tiny settings (checks the script runs)")
    ap.add_argument("--write", action="store_true", help="record the tables in benchmarks/ENGINES.md")
    ap.add_argument("--flip", choices=("on", "off", "auto"), help="the run's --flip (default: the runner's, auto)")
    ap.add_argument("--keep", metavar="DIR", help="run into DIR (new) and keep it, e.g. to compare metrics.json "
                    "before and after a change (default: a temporary folder)")
    args = ap.parse_args()
    argv, title = (([], "default suite") if args.default else (SMOKE, "smoke") if args.smoke
                   else (TINY, "tiny suite"))
    if args.flip:
        argv, title = [*argv, "--flip", args.flip], f"{title}, --flip {args.flip}"
    load0 = os.getloadavg()[0]
    if args.keep:
        if Path(args.keep).exists():
            raise SystemExit(f"--keep {args.keep}: exists; give a new folder")
        wall, cpu, code, events, runs = measure(argv, Path(args.keep).resolve())
    else:
        with tempfile.TemporaryDirectory() as tmp:
            wall, cpu, code, events, runs = measure(argv, Path(tmp) / "out")
    load1 = os.getloadavg()[0]
    void = [f"{r.get('scene')} ({r.get('backend')}): {r['flip_error']}" for r in runs if r.get("flip_error")]
    if void:  # FLIP failed (its CPU then counts nothing): the judging share would be void, not small
        raise SystemExit(f"FLIP failed in {len(void)} job(s), so judging's CPU is not measured: " + "; ".join(void[:3]))
    jobs, totals = breakdown(wall, events, runs)
    text = tables(title, argv, wall, cpu, code, jobs, totals, (f"{load0:.2f}", f"{load1:.2f}"))
    print(text)
    if args.write and not args.smoke:
        from record import prepend
        prepend(ROOT / "benchmarks" / "ENGINES.md", "# Engines: wall time against render time\n\n",
                f"## {dt.date.today().isoformat()}: fixed cost per job\n\n`benchmarks/bench_fixed_cost.py"
                f"{' --default' if args.default else ''}`\n\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
