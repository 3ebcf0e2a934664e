"""Batch runner entry point.

    python batch/run.py [options]                              (bpy as a Python module)
    blender -b scenes.blend -P batch/run.py -- [options]       (inside Blender)

Both take the same options (see --help) and give the same jobs.
"""
import logging
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402


def setup_logging(log_file=None):
    logger = logging.getLogger("spectral_bench")
    logger.setLevel(logging.INFO)
    logger.handlers.clear()
    if sys.stderr.isatty():  # a progress bar is drawn: log lines go above it
        from spectral_bench.batch.jobs.progress import TqdmLogHandler
        console = TqdmLogHandler(logging.Formatter("%(message)s"))
    else:
        console = logging.StreamHandler(sys.stderr)
        console.setFormatter(logging.Formatter("%(message)s"))
    logger.addHandler(console)
    if log_file:
        fh = logging.FileHandler(log_file)
        fh.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
        logger.addHandler(fh)
    return logger


def list_jobs(runner, opts):
    """--list: each job as scene, case and backend; a scene that cannot be loaded is listed as
    ``ERROR`` with why (file, object and field) and makes the exit status 2; a scene with
    conversion warnings gets a note on stderr (their count)."""
    jobs, scenes = runner.plan(opts)
    errors = {name: str(sc) for name, sc in scenes if isinstance(sc, Exception)}
    for scene, case, backend in jobs:
        if scene not in errors:
            print(f"{scene}\t{case}\t{backend}")
    for scene, why in errors.items():
        print(f"{scene}\tERROR\t{' '.join(why.split())[:500]}")
    for scene, sc in scenes:  # a scene converted from Blender without annotations: how much it lost
        if isinstance(sc, dict) and sc.get("warnings"):
            print(f"note: {scene}: {len(sc['warnings'])} conversion warning(s) from its source (each in the run's "
                  "log, metrics.json and summary.md)", file=sys.stderr)
    if errors:
        print(f"error: {len(errors)} scene(s) could not be loaded (listed as ERROR)", file=sys.stderr)
    return 2 if errors else 0


def main(argv=None):
    pkg_bootstrap.package()
    from spectral_bench.batch import cli
    from spectral_bench.batch.jobs import engines, runner
    try:
        opts = cli.parse(cli.split_argv(sys.argv if argv is None else argv))
    except cli.UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        logger = setup_logging(opts["log"])
    except OSError as exc:
        print(f"error: --log {opts['log']}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    if opts["list"]:
        return list_jobs(runner, opts)
    try:
        code = runner.run(opts)  # sets opts["out"] to the folder it used
    except (runner.UsageError, engines.ClusterError, cli.UsageError) as exc:
        logger.error("error: %s", exc)
        return 2
    if opts["visualize"] and opts["out"]:
        import webbrowser
        webbrowser.open((Path(opts["out"]) / "report.html").resolve().as_uri())
    return code


if __name__ == "__main__":
    sys.exit(main())  # under Blender too, sys.exit is how a -P script sets the exit status
