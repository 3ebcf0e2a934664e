"""A stand-in renderer declared in TOML (batch/backends/command.py) and the pass loop driven with
it (batch/backends/passes.py): real child processes writing real EXR files, for the tests of the
loop (tests/backends/test_declared_renderer.py) and of hostile renderers (tests/hostile/).

``FAKE`` is the renderer script: it reads nothing but its arguments and writes a W x H EXR whose
value is chosen by MODE (its seed, a failure once, always a failure, NaN, the wrong size, a hang,
...); ``declaration(tmp_path, mode, **extra)`` declares it as ``fake_<mode>``; ``render(tmp_path,
mode, ...)`` renders the copper plate at 8 x 6 through the loop."""
import textwrap
from pathlib import Path

from spectral_bench.batch import backends
from spectral_bench.batch.backends import command
from spectral_bench.exporters import ir_json

ROOT = Path(__file__).resolve().parents[1]

# A renderer script: reads nothing but its arguments, writes a W x H EXR whose value is chosen by MODE
FAKE = textwrap.dedent('''
    import os, sys, time
    import numpy as np, OpenEXR
    mode, out, spp, seed, width, height = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6])
    value = float(seed)
    if mode == "fail_once":
        marker = os.path.join(os.environ["FAKE_STATE"], f"seed{seed}")
        if not os.path.exists(marker):
            open(marker, "w").close()
            print("fake: transient failure", file=sys.stderr)
            sys.exit(3)
    if mode == "fail":
        print("fake: out of memory while building the BVH", file=sys.stderr)
        sys.exit(7)
    if mode == "hang":
        time.sleep(600)
    if mode == "nan":
        value = float("nan")
    if mode == "size":
        width += 1
    if mode == "silent":
        sys.exit(0)
    img = np.full((height, width), value, dtype=np.float32)
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"R": img, "G": img * 2, "B": img * 3}) as f:
        f.write(out)
''')


def declaration(tmp_path, mode, **extra):
    script = tmp_path / "fake.py"
    script.write_text(FAKE)
    table = {"command": ["{python}", "{here}/fake.py", mode, "{output}", "{spp}", "{seed}", "{width}", "{height}", "{scene}"],
             "reads": "json", "writes": "rgb", "models": ["spectral"], "version": ["{python}", "--version"]}
    table.update(extra)
    return command.parse(f"fake_{mode}", table, str(tmp_path / "renderers.toml"), tmp_path)


def scene(tmp_path, name="ggx_copper_50", width=8, height=6):
    sc = ir_json.load(ROOT / "golden" / "ir" / f"{name}.json")
    sc["render"].update(width=width, height=height)
    return sc


def render(tmp_path, mode, passes_n=3, seed=0, timeout=120, declared=None):
    b = backends.get(f"fake_{mode}", declaration=declaration(tmp_path, mode, **(declared or {})))
    sc = scene(tmp_path)
    path = b.export(sc, tmp_path / "export")
    return b.render(path, b.mode_for(sc)[0], 12, tmp_path / "render.exr", passes=passes_n, seed=seed,
                    timeout=timeout, log_path=tmp_path / "render.log")
