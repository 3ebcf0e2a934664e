"""Without a usable libLLVM the runner says so (once) and falls back to the scalar variants; the
probe's answer is handed down to children only for the same inputs."""
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


def test_a_handed_down_answer_is_taken_only_for_the_same_inputs(monkeypatch):
    """The LLVM answer is handed down through the environment (llvm.INHERITED): the same
    interpreter and candidate libraries take the parent's answer (here a planted one, which no
    probe could give); other candidates, or a malformed value, probe for real."""
    import pkg_bootstrap
    pkg_bootstrap.package()
    from spectral_bench.batch.backends.mitsuba import llvm
    key = [sys.executable, llvm.candidates()]
    planted = json.dumps({"llvm": [key, [None, "handed down by the test"]]})
    try:
        monkeypatch.setenv(llvm.INHERITED, planted)
        llvm.find.cache_clear()
        assert llvm.find() == (None, "handed down by the test")
        for bad in ("{not json", "[1, 2]", json.dumps({"llvm": [key, [3, 4]]}), json.dumps({"llvm": [key]})):
            monkeypatch.setenv(llvm.INHERITED, bad)
            assert llvm.inherited("llvm", key) is None, bad
        monkeypatch.setenv(llvm.INHERITED, planted)
        monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/nonexistent/libLLVM-test.so")  # another first candidate
        llvm.find.cache_clear()
        path, message = llvm.find()  # probed for real: the missing library is named in it or skipped for a good one
        assert message != "handed down by the test"
        assert json.loads(os.environ[llvm.INHERITED])["llvm"][0] == [sys.executable, llvm.candidates()]  # handed on
    finally:
        llvm.find.cache_clear()
