"""The long fuzzing run of issue 18: hostile scenes (tests/scene_fuzz.py) through load ->
validate -> every writer, in worker processes, each chunk with its own Hypothesis seed. Prints
and (with --write) records in benchmarks/FUZZ.md how many scenes ended how, what validation
refused most often, and every failure with its message.

    .venv/bin/python benchmarks/fuzz_scenes.py --count 100000 --schema-count 1000 --write
"""
import argparse
import collections
import datetime as dt
import multiprocessing as mp
import re
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
import pkg_bootstrap  # noqa: E402

from record import machine, replace_section  # noqa: E402

FUZZ_MD = Path(__file__).resolve().parent / "FUZZ.md"


def _field_kind(obj, field):
    """A refused field without its object names and indices: 'objects[*].name', 'render.spp'."""
    where = "scene" if obj in ("scene", "render", "camera", "environment") else "object"
    return f"{where}:{obj if where == 'scene' else '*'}.{re.sub(r'[0-9]+', '*', field)}"


def run_chunk(task):
    kind, seed, count = task
    pkg_bootstrap.package()
    import warnings
    warnings.simplefilter("ignore")
    import scene_fuzz
    from hypothesis import HealthCheck, Phase, given, settings, seed as hseed
    outcomes, fields, failures = collections.Counter(), collections.Counter(), []
    strategy = scene_fuzz.mutated_scenes() if kind == "mutated" else scene_fuzz.schema_scenes()

    @hseed(seed)
    @settings(max_examples=count, deadline=None, database=None, phases=[Phase.generate, Phase.shrink],
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def one(scene):
        with tempfile.TemporaryDirectory() as d:
            outcome, refused = scene_fuzz.check_detailed(scene_fuzz.scene_text(scene), d)
        outcomes[outcome] += 1
        fields.update({_field_kind(o, f) for o, f in refused})

    t0 = time.perf_counter()
    try:
        one()
    except Exception as exc:  # noqa: BLE001 - a finding: recorded with its shrunk example's message
        failures.append(f"{kind} seed {seed}: {type(exc).__name__}: {str(exc)[:400]}")
    return kind, outcomes, fields, failures, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=100000, help="mutated golden scenes")
    ap.add_argument("--schema-count", type=int, default=1000, help="scenes generated from the schema (slow to generate)")
    ap.add_argument("--chunk", type=int, default=2000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--write", action="store_true", help=f"record the table in {FUZZ_MD.name}")
    args = ap.parse_args()
    tasks = []
    for kind, total, chunk in (("mutated", args.count, args.chunk), ("schema", args.schema_count, max(1, args.chunk // 20))):
        for k, start in enumerate(range(0, total, chunk)):
            tasks.append((kind, args.seed * 100003 + len(tasks), min(chunk, total - start)))
    t0 = time.perf_counter()
    totals = {"mutated": collections.Counter(), "schema": collections.Counter()}
    fields, failures, cpu = collections.Counter(), [], collections.Counter()
    with mp.get_context("spawn").Pool(args.workers) as pool:
        for kind, outcomes, f, fails, seconds in pool.imap_unordered(run_chunk, tasks):
            totals[kind].update(outcomes)
            fields.update(f)
            failures += fails
            cpu[kind] += seconds
            for f_ in fails:
                print("FAILURE", f_, flush=True)
            done = sum(sum(c.values()) for c in totals.values())
            print(f"{done} scenes, {len(failures)} failures, {time.perf_counter() - t0:.0f} s", flush=True)
    wall = time.perf_counter() - t0
    lines = [f"Run {dt.date.today().isoformat()} on {machine()}, {args.workers} worker processes: "
             f"{wall:.0f} s wall, `benchmarks/fuzz_scenes.py --count {args.count} --schema-count {args.schema_count}`.",
             "", "| source | scenes | refused by validation | exported (every check passed) | failures | CPU s per scene |",
             "|---|---|---|---|---|---|"]
    for kind, c in totals.items():
        n = sum(c.values())
        lines.append(f"| {kind} | {n} | {c['invalid']} | {c['exported']} | "
                     f"{sum(1 for x in failures if x.startswith(kind))} | {cpu[kind] / max(n, 1):.3f} |")
    lines += ["", "Fields validation refused most often (scenes refused for each; a scene counts once per field):", ""]
    lines += [f"- `{k}`: {v}" for k, v in fields.most_common(20)]
    lines += ["", "Failures (an exception other than a named SceneError, an export that did not parse, a file "
              "outside OUT):", ""] + ([f"- {f}" for f in failures] or ["- none"])
    text = "\n".join(lines)
    print(text)
    if args.write:
        replace_section(FUZZ_MD, f"Long run {dt.date.today().isoformat()}", text)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
