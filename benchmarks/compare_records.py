"""Two runs' metrics.json, job by job: every field of every run record (statuses, noise tests'
p, z and detectable, probes' numbers, FLIP), per-block arrays read back, but what differs between
any two runs of the same code (timings, versions, dates, the reference's path, the diagnosis'
"slowest" seconds). Prints a line per job and each difference; exit 1 when any.

    .venv/bin/python benchmarks/compare_records.py BEFORE_RUN_FOLDER AFTER_RUN_FOLDER
    .venv/bin/python benchmarks/compare_records.py --smoke   # one tiny run, compared with itself

Used for issue 45 item 1 (benchmarks/ENGINES.md, 2026-12-04, "judging's share"): the default
suite before and after a change, both at the default seed (bench_fixed_cost.py --keep DIR).
"""
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
from spectral_bench.batch import records  # noqa: E402

VOLATILE = {"time_s", "wall_s", "pass_times", "versions", "path", "date", "tool", "started", "slowest"}


def differences(x, y, path, out):
    if isinstance(x, dict) and isinstance(y, dict):
        for k in sorted(set(x) | set(y), key=str):
            if k in VOLATILE:
                continue
            if k not in x or k not in y:
                out.append((f"{path}/{k}", "only in " + ("after" if k not in x else "before")))
            else:
                differences(x[k], y[k], f"{path}/{k}", out)
    elif isinstance(x, list) and isinstance(y, list):
        if len(x) != len(y):
            out.append((path, f"length {len(x)} -> {len(y)}"))
            return
        for i, (u, v) in enumerate(zip(x, y)):
            differences(u, v, f"{path}[{i}]", out)
    elif isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y):
        return
    elif type(x) is not type(y) or x != y:
        out.append((path, f"{x!r:.80} -> {y!r:.80}"))


def smoke():
    """One tiny run of the runner (as a user runs it), compared with itself: the script works."""
    import subprocess
    import tempfile
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        subprocess.run([sys.executable, str(root / "batch" / "run.py"), "-r", "mitsuba", "--scale", "0.25", "--spp", "4",
                        "-s", "ggx_copper_50", "-o", str(out)], cwd=root, check=True, stdin=subprocess.DEVNULL,
                       stdout=subprocess.DEVNULL)
        return main([__file__, str(out), str(out)])


def main(argv):
    if argv[1:] == ["--smoke"]:
        return smoke()
    if len(argv) != 3:
        sys.exit(__doc__)
    a, b = (records.read(p) for p in argv[1:3])
    ra = {f"{r['scene']}/{r['backend']}": r for r in a["runs"]}
    rb = {f"{r['scene']}/{r['backend']}": r for r in b["runs"]}
    found = [(k, "only in " + ("before" if k in ra else "after")) for k in sorted(set(ra) ^ set(rb))]
    for k in sorted(set(ra) & set(rb)):
        n = len(found)
        differences(ra[k], rb[k], k, found)
        flips = [(r.get("metrics") or {}).get("flip") for r in (ra[k], rb[k])]
        print(f"{k:45s} {ra[k].get('status')} -> {rb[k].get('status')}; FLIP {flips[0]!r} -> {flips[1]!r}; "
              f"{len(ra[k].get('probes') or [])} probes; {len(found) - n} differences")
    for path, what in found:
        print("  DIFF", path, what)
    print(f"{len(set(ra) & set(rb))} jobs compared, {len(found)} differences")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
