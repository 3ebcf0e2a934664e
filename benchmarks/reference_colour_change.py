"""What re-making the references in the scene format's own colour changed, per scene: the verdict
make_references recorded when it replaced each one (references/history/<scene>/*/replaced.json:
the new reference judged against the old on both their noises) and the mean ratio new / old per
channel with its standard error; both films named from the provenances.

    .venv/bin/python benchmarks/reference_colour_change.py [--history references/history] [--write]
    .venv/bin/python benchmarks/reference_colour_change.py --smoke DIR   (a tiny reference made with
        Mitsuba's film, then replaced through the CMF film, in DIR: the table of that replacement)

--write prepends the table to benchmarks/REFERENCE_COLOUR.md. The history folder itself is not
committed (git keeps the references' history); run this where the re-make ran.
"""
import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from record import machine, prepend  # noqa: E402

OUT = HERE / "REFERENCE_COLOUR.md"
HEAD = "# References in the scene format's colour\n\nRecorded by `benchmarks/reference_colour_change.py --write`; newest first.\n\n"


def film_of(prov):
    colour = (prov or {}).get("colour")
    if isinstance(colour, dict):
        return "CMF film (1 nm, IEC)" if colour.get("observer") == "cie1931" and "specfilm" in str(colour.get("film")) \
            else str(colour.get("film"))
    return f"Mitsuba film ({(prov or {}).get('mode')})"


def rows(history):
    out = []
    for replaced in sorted(Path(history).glob("*/*/replaced.json")):
        data = json.loads(replaced.read_text())
        why = data.get("why") or {}
        verdict = why.get("verdict") or {}
        prov_old, prov_new = data.get("old") or {}, data.get("new") or {}
        current = Path(history).parent / f"{replaced.parent.parent.name}.json"  # the reference that replaced it
        if "colour" not in prov_new and current.is_file():
            prov_new = json.loads(current.read_text())
        ratio = verdict.get("ratio") or {}
        test = verdict.get("test") or {}
        out.append({"scene": replaced.parent.parent.name, "old": film_of(prov_old), "new": film_of(prov_new),
                    "same": verdict.get("same"), "p_min": test.get("p_min"), "threshold": test.get("threshold"),
                    "ratio": ratio, "accepted": why.get("accepted_despite_verdict")})
    return out


def table(items):
    lines = ["| scene | old | new | new / old: R | G | B | verdict (p_min vs threshold) |", "|---|---|---|---|---|---|---|"]
    for r in items:
        cells = []
        for c in "RGB":
            v = r["ratio"].get(c)
            cells.append(f"{v[0]:.5f} +- {v[1]:.5f}" if v else "-")
        verdict = ("same within noise" if r["same"] else "differs beyond noise") + \
            (f" ({r['p_min']:.3g} vs {r['threshold']:.3g})" if r["p_min"] is not None else "")
        lines.append(f"| {r['scene']} | {r['old']} | {r['new']} | " + " | ".join(cells) + f" | {verdict} |")
    return "\n".join(lines)


def smoke(folder):
    """One tiny reference (fluorescent_sphere_lone at scale 0.25, 64 spp) made with Mitsuba's film,
    then replaced through the CMF film (--accept), in ``folder``; returns its history folder."""
    import subprocess
    make = [sys.executable, str(HERE.parent / "batch" / "make_references.py"), "-s", "fluorescent_sphere_lone",
            "--scale", "0.25", "--spp", "64", "--passes", "2", "--out", str(folder)]
    for extra in ([], ["--film", "cmf", "--seed", "3000", "--replace", "--accept"]):
        subprocess.run(make + extra, check=True, capture_output=True, text=True, cwd=HERE.parent)
    return folder / "history"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--history", default=str(HERE.parent / "references" / "history"))
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--smoke", metavar="DIR", help="make and replace one tiny reference in DIR first (seconds)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.history = str(smoke(Path(args.smoke)))
    items = rows(args.history)
    if not items:
        print(f"no replaced references under {args.history}", file=sys.stderr)
        return 1
    text = table(items)
    print(text)
    if args.write:
        import datetime as dt
        prepend(OUT, HEAD, f"## {dt.date.today().isoformat()}\n\nMachine: {machine()}.\n\n{text}\n\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
