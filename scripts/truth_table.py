"""The table "scene -> truth" of docs/verdict.md (issue 44), made from the code's registries: for
each canonical scene, the analytic probes that measure it (batch/verdict/probes PROBES, each run on
the scene's committed reference image at its resolution: a probe that applies and has pixels enough
to measure counts, with its number of checks) and the cross-checks of its reference that count
(batch/verdict/crosscheck.py ``counting``: the renderer, what it detects, agreed or not, and the
recorded deviation it agreed up to, if any).

    .venv/bin/python scripts/truth_table.py            # print the table
    .venv/bin/python scripts/truth_table.py --write    # put it into docs/verdict.md between its markers
    .venv/bin/python scripts/truth_table.py --check    # exit 1 when docs/verdict.md's table is not this one

The band checks (batch/verdict/probes/bands.py) judge a spectral render's bands and are not listed
(a reference has no bands). A scene with neither probe nor agreeing cross-check is judged only
against a reference of the renderer that made it: "checked against itself" for that renderer.
"""
import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

DOC = ROOT / "docs" / "verdict.md"
BEGIN, END = "<!-- truth-table -->", "<!-- /truth-table -->"


def probe_names(scene, ref):
    """["module.function (N checks)"] of the probes that measure ``scene`` on its reference image."""
    from spectral_bench.batch.verdict import probes
    if scene.get("lights"):  # probes.evaluate: no closed form assumes delta lights
        return []
    m = probes.Measurement(scene, list(ref.names), ref.mean.astype("float64"), ref.stderr.astype("float64"), None,
                           ref.provenance.get("passes", 8), (), None)
    out = []
    for fn in probes.PROBES:
        if fn in probes.bands.PROBES:
            continue
        measured = [r for r in fn(m) if r.get("pass") is not None]
        if measured:
            out.append(f"`{fn.__module__.rsplit('.', 1)[1]}.{fn.__name__}` ({len(measured)})")
    return out


def rows():
    from spectral_bench.batch import scene_sources
    from spectral_bench.batch.verdict import crosscheck, known, references
    deviations = known.load()  # a cross-check that agreed under a deviation counts while it is recorded
    out = []
    # the canonical scenes as golden/ir holds them (scripts/update_golden.py: scenes.blend's extraction)
    for name, scene in scene_sources.load([str(p) for p in sorted((ROOT / "golden" / "ir").glob("*.json"))]):
        if isinstance(scene, Exception):
            raise SystemExit(f"{name}: {scene}")
        ref = references.search(name, scene=scene).ref
        names = probe_names(scene, ref) if ref is not None else []
        counted, _stale = crosscheck.counting(ref.provenance, deviations) if ref is not None else ([], [])
        checks = [f"{crosscheck.renderer_label(c.get('renderer'), c.get('version'))}: "
                  + ((f"agrees up to `{c['agrees_under']}`" if c.get("agrees_under") else "agrees")
                     + f", detects {crosscheck.percent(c['detectable'])}" if c.get("agrees") else "DIFFERS")
                  + f" ({str(c.get('date'))[:10]})" for c in counted]
        maker = ref.provenance.get("backend") if ref is not None else None
        if names or any(c.get("agrees") for c in counted):
            truth = " + ".join(p for p in ("probes" if names else "", "cross-check" if any(c.get("agrees") for c in counted)
                                           else "") if p)
        else:
            truth = f"checked against itself ({maker})" if maker else "none"
        out.append((name, ", ".join(names) or "-", "; ".join(checks) or "-", truth))
    return out


def table():
    lines = ["| scene | probes (checks measured on the reference) | reference cross-checked by | truth |",
             "|---|---|---|---|"]
    lines += [f"| {s} | {p} | {c} | {t} |" for s, p, c, t in rows()]
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="scripts/truth_table.py", description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help=f"write it into {DOC.relative_to(ROOT)} between its markers")
    ap.add_argument("--check", action="store_true", help=f"exit 1 when {DOC.relative_to(ROOT)}'s table differs")
    args = ap.parse_args(argv)
    pkg_bootstrap.package()
    text = table()
    if not (args.write or args.check):
        print(text)
        return 0
    doc = DOC.read_text(encoding="utf-8")
    if BEGIN not in doc or END not in doc:
        print(f"{DOC}: no {BEGIN} ... {END} markers", file=sys.stderr)
        return 2
    head, rest = doc.split(BEGIN, 1)
    _old, tail = rest.split(END, 1)
    new = f"{head}{BEGIN}\n{text}\n{END}{tail}"
    if args.check:
        if new != doc:
            print(f"{DOC}: the scene -> truth table is not current: run scripts/truth_table.py --write", file=sys.stderr)
            return 1
        return 0
    DOC.write_text(new, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
