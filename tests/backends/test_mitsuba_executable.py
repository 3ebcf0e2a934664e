"""The mitsuba executable route (``-e mitsuba=PATH``) against the Python route: the same status on
every canonical scene it can render (camera polariser, monochrome variants, known deviations
matched through the version parsed from the executable's banner), --passes honoured; scenes
that need this project's Python plugins unsupported with the reason."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RUN = ROOT / "batch" / "run.py"
MITSUBA = Path(sys.executable).parent / "mitsuba"
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
from spectral_bench.batch.backends.mitsuba import backend as mitsuba_backend  # noqa: E402

pytestmark = pytest.mark.skipif(not MITSUBA.is_file(), reason=f"no mitsuba executable beside {sys.executable}")


def test_version_is_read_from_the_banner():
    assert mitsuba_backend.executable_version(str(MITSUBA)) == "3.9.1"  # requirements.txt pins mitsuba==3.9.1


# where the executable route used to differ (camera polariser, monochrome variant, known deviations of
# the charts), a plain spectral scene, and scenes of each Python plugin; every scene at default
# settings: benchmarks/EXECUTABLE.md
SCENES = ("polarizing_plane_0", "polarizing_plane_90", "polarizing_spheres", "macbeth_chart_D65", "macbeth_chart_D50",
          "ggx_copper_50", "iridescent_sphere_smooth", "dispersion_prism", "fluorescent_sphere_lone")


@pytest.mark.parametrize("name", ["polarizing_plane_0", "polarizing_spheres"])
def test_both_routes_give_the_same_pixels_for_the_same_seed(tmp_path, name):
    """One pass of the same samples and seed: the executable's film file and the Python route's
    array are the same numbers (polariser and monochrome conversion included), which needs the
    exported film to be float32 (hdrfilm's default float16 rounds by up to 2^-11: a light seen
    directly, with no variance, then failed the noise test at |z| ~ 5e4)."""
    import numpy as np
    from spectral_bench.batch import backends, exr
    from spectral_bench.batch.jobs import plan
    from spectral_bench.exporters import ir_json
    sc = plan.for_run(ir_json.load(ROOT / "golden" / "ir" / f"{name}.json"), {"scale": 0.125, "spp": 8})
    images = []
    for exe in (None, str(MITSUBA)):
        b = backends.get("mitsuba", executable=exe)
        out = tmp_path / ("exe" if exe else "py")
        b.render(b.export(sc, out / "export"), b.mode_for(sc)[0], 8, out / "r.exr", passes=1, seed=3)
        images.append(exr.read_image(out / "r.exr"))
    assert images[0][0] == images[1][0]
    assert np.array_equal(images[0][1], images[1][1])


def _run(out, *args):
    scenes = [a for s in SCENES for a in ("-s", s)]
    proc = subprocess.run([sys.executable, str(RUN), "-r", "mitsuba", "--scale", "0.25", "--passes", "3", *scenes, *args,
                           "-o", str(out)], capture_output=True, text=True, timeout=1800, cwd=ROOT)
    assert proc.returncode in (0, 1, 3), proc.stderr[-3000:]
    return {r["scene"]: r for r in json.loads((out / "metrics.json").read_text())["runs"]}


@pytest.mark.slow
def test_executable_route_reaches_the_python_routes_status(tmp_path):
    python = _run(tmp_path / "py")
    exe = _run(tmp_path / "exe", "-e", f"mitsuba={MITSUBA}")
    assert python.keys() == exe.keys()
    plugin_scenes = [s for s, r in exe.items() if r["status"] == "unsupported" and "Python plugins" in r["reason"]]
    assert sorted(plugin_scenes) == ["dispersion_prism", "fluorescent_sphere_lone", "iridescent_sphere_smooth"]
    for name, r in exe.items():
        if name in plugin_scenes:
            assert python[name]["status"] in ("ok", "known"), python[name]  # the Python route renders them
            continue
        assert r["status"] == python[name]["status"], (name, r["status"], r["reason"], python[name]["status"])
        assert r["passes"] == 3 and len(r["pass_times"]) == 3, r
        assert r["versions"]["mitsuba"] == "3.9.1" and r["versions"]["route"] == "executable"
    judged = [n for n in exe if n not in plugin_scenes]
    assert {"polarizing_plane_0", "polarizing_plane_90", "polarizing_spheres", "macbeth_chart_D65"} <= set(judged)
    assert all(exe[n]["status"] in ("ok", "known") for n in judged), {n: exe[n]["reason"] for n in judged}
