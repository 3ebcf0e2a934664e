"""Without a usable libLLVM the runner says so (once) and falls back to the scalar variants."""
import json
import os
import subprocess
import sys
import textwrap

from conftest import GOLDEN, ROOT


def test_no_llvm_falls_back_to_scalar_and_says_why(tmp_path):
    code = textwrap.dedent(f"""
        import json, sys
        sys.path.insert(0, {str(ROOT)!r})
        import pkg_bootstrap; pkg_bootstrap.package()
        from spectral_bench.batch.backends.mitsuba import llvm
        from spectral_bench.batch import backends
        from spectral_bench.exporters import ir_json
        llvm.CANDIDATES = ()
        llvm.glob.glob = lambda pattern: []
        path, message = llvm.find()
        b = backends.get("mitsuba")
        mode, _ = b.mode_for(ir_json.load({str(GOLDEN / 'ggx_glass.json')!r}))
        print(json.dumps({{"path": path, "message": message, "mode": mode}}))
    """)
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=str(tmp_path / "libLLVM-missing.so"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["path"] is None
    assert "falling back to the scalar variants" in out["message"] and "libLLVM-missing" in out["message"]
    assert out["mode"] == "scalar_spectral"
