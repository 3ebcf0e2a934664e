"""Options and bounds, claiming the output folder, resuming, clusters (issue 18): every option and
every settings-file value is checked at parse (exit 2 naming the option); an output folder is
claimed exclusively; --resume restores what a job id depends on or refuses; a cluster that cannot
be used fails within a timeout; a run where nothing ran exits 4."""
import json
import os
import subprocess
import sys

import filelock
import pytest

from conftest import GOLDEN, ROOT, metrics, run_batch
from spectral_bench.batch import cli
from spectral_bench.batch.jobs import runner

GOOD = GOLDEN / "ggx_copper_50_isolated.json"
TINY = ("--scale", 0.0625, "--spp", 4, "--passes", 2, "--no-flip")

BAD_OPTIONS = [
    (["--min-samples", "0"], "--min-samples"), (["--alpha", "2"], "--alpha"), (["--alpha", "nan"], "--alpha"),
    (["--alpha", "0"], "--alpha"), (["--passes", "0"], "--passes"), (["--spp", "-5"], "--spp"),
    (["--spp", "1000000000000"], "--spp"), (["--scale", "-1"], "--scale"), (["--scale", "nan"], "--scale"),
    (["--scale", "0"], "--scale"), (["--scale", "inf"], "--scale"), (["--timeout", "0"], "--timeout"),
    (["--timeout", "nan"], "--timeout"), (["--cluster", "local:abc"], "--cluster"), (["--cluster", "local:0"], "--cluster"),
    (["--cluster", "tcp://host:99999"], "--cluster"), (["--cluster", "not an address"], "--cluster"),
    (["--ladder", "4,0,16"], "--ladder"), (["--ladder", "-4"], "--ladder"), (["--min-samples", "-3"], "--min-samples"),
    (["--block", "0"], "--block"), (["--seed", "-1"], "--seed"), (["-e", "=/opt/mitsuba"], "--exec"),
    (["-e", "nosuch=/opt/x"], "--exec"), (["-e", "mitsuba="], "--exec"), (["-r", "nosuch"], "--renderer"),
    (["--sweep-modes", "a,,b"], "--sweep-modes"), (["--timeout", "inf"], "--timeout"),
]


@pytest.mark.parametrize("args,option", BAD_OPTIONS, ids=[" ".join(a) for a, _ in BAD_OPTIONS])
def test_a_bad_option_is_a_usage_error_naming_it(args, option, capsys):
    with pytest.raises(SystemExit) as info:
        cli.parse(args)
    assert info.value.code == 2
    assert option in capsys.readouterr().err


def test_a_bare_executable_needs_one_backend():
    with pytest.raises(cli.UsageError, match="-e"):
        cli.parse(["-e", "/opt/mitsuba/mitsuba"])  # default backends: mitsuba and art
    assert cli.parse(["-e", "/opt/mitsuba/mitsuba", "-r", "mitsuba"])["exec"] == {"*": "/opt/mitsuba/mitsuba"}
    assert cli.parse(["-e", "mitsuba=/opt/a=b/mitsuba"])["exec"] == {"mitsuba": "/opt/a=b/mitsuba"}


BAD_SETTINGS = [
    ('spp = "4"\n', "spp"), ("spp = 0\n", "spp"), ("alpha = 2.0\n", "alpha"), ("passes = 0\n", "passes"),
    ("scale = -1.0\n", "scale"), ("scale = nan\n", "scale"), ('renderer = ["mitsuba", 3]\n', "renderer"),
    ('renderer = ["nosuch"]\n', "renderer"), ("ladder = [4, 0]\n", "ladder"), ('ladder = ["4"]\n', "ladder"),
    ('flip = "no"\n', "flip"), ("export_only = 1\n", "export_only"), ('cluster = "local:0"\n', "cluster"),
    ("timeout = true\n", "timeout"), ('exec = ["=x"]\n', "exec"), ('format = ["pdf"]\n', "format"),
    ('settings = "other.toml"\n', "settings"),
]


@pytest.mark.parametrize("text,key", BAD_SETTINGS, ids=[t.strip() for t, _ in BAD_SETTINGS])
def test_a_bad_settings_value_goes_through_the_options_own_type(tmp_path, text, key):
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(cli.SettingsError) as info:
        cli.parse(["--settings", str(path)])
    assert key in str(info.value) and str(path) in str(info.value)


def test_a_settings_file_that_is_not_a_table_is_named(tmp_path):
    path = tmp_path / "s.json"
    path.write_text("[1, 2]")
    with pytest.raises(cli.SettingsError, match="s.json"):
        cli.parse(["--settings", str(path)])


def test_settings_files_accumulate_later_wins(tmp_path):
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.write_text('scene = ["ggx_glass"]\nspp = 4\n')
    b.write_text("spp = 8\nalpha = 0.05\n")
    opts = cli.parse(["--settings", str(a), "--settings", str(b)])
    assert opts["scene"] == ["ggx_glass"] and opts["spp"] == 8 and opts["alpha"] == 0.05


@pytest.mark.slow
def test_bad_options_exit_2_through_the_real_command_line(tmp_path):
    bad = tmp_path / "s.toml"
    bad.write_text('spp = "4"\n')
    for args, needle in ((["--scale", "nan"], "--scale"), (["--settings", bad], "spp")):
        proc = run_batch(*args, "--export-only", "-o", tmp_path / "o")
        assert proc.returncode == 2 and needle in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert not (tmp_path / "o").exists()


def test_a_bad_known_file_is_named(tmp_path, run_batch_here):
    """In this process (the real child of a usage error: test_bad_options_exit_2_through_the_real_command_line)."""
    broken = tmp_path / "known.toml"
    broken.write_text("[[deviation]\nid = ")
    for path in (broken, tmp_path / "no_such_known.toml"):
        proc = run_batch_here("-i", GOOD, "--export-only", "--format", "json", "--known", path, "-o", tmp_path / "o")
        assert proc.returncode == 2 and str(path) in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]


KNOWN_ENTRY = {"id": '"dim"', "backend": '"mitsuba"', "checks": '["noise test"]', "evidence": '"measured"',
               "explanation": '"explained"', "date": '"2026-12-04"', "scale": "0.99", "scale_se": "0.001"}


@pytest.mark.parametrize("field, value", [
    ("scale", "nan"), ("scale", "0"), ("scale", "-1.0"), ("scale", "inf"), ("scale", "true"), ("scale", '"1.0"'),
    ("scale_se", "-0.01"), ("scale_se", "nan"), ("scale_se", "1.5"), ("observer", '"nosuch"'),
    ("checks", '"noise test"'), ("checks", "[]"), ("scenes", "[1]"), ("backend", '""'), ("shadowing", '"smooth"'),
])
def test_a_known_deviation_with_an_implausible_parameter_is_named(tmp_path, run_batch_here, field, value):
    """--known FILE whose one entry has a parameter no renderer's deviation can have (a factor that
    is not finite or not positive, an uncertainty not below it, a pattern that is not a list of
    strings): exit 2 naming the file, the entry and the field, before anything runs."""
    path = tmp_path / "known.toml"
    path.write_text("[[deviation]]\n" + "".join(f"{k} = {v}\n" for k, v in KNOWN_ENTRY.items()))  # TOML values as written
    proc = run_batch_here("-i", GOOD, "--export-only", "--format", "json", "--known", path, "-o", tmp_path / "plausible")
    assert proc.returncode == 0, proc.stderr[-2000:]  # the entry as it should be is taken: the field is the problem
    entry = dict(KNOWN_ENTRY, **{field: value})
    path.write_text("[[deviation]]\n" + "".join(f"{k} = {v}\n" for k, v in entry.items()))
    proc = run_batch_here("-i", GOOD, "--export-only", "--format", "json", "--known", path, "-o", tmp_path / "o")
    assert proc.returncode == 2, (path.read_text(), proc.stderr[-2000:])
    assert f"{path}: deviation 'dim', field {field}:" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert not (tmp_path / "o").exists()


def test_an_output_folder_that_cannot_be_written_is_named(tmp_path, run_batch_here):
    """In this process, as the test above."""
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    for out in (blocker, blocker / "out"):
        proc = run_batch_here("-i", GOOD, "--export-only", "--format", "json", "-o", out)
        assert proc.returncode == 2 and str(blocker) in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]


def test_a_run_where_nothing_ran_exits_4(tmp_path):
    out = tmp_path / "o"
    proc = run_batch("-i", GOOD, "-r", "art", "-e", f"art={tmp_path / 'no_artist_here'}", *TINY, "-o", out)
    assert proc.returncode == 4, proc.stderr[-2000:]
    assert [r["status"] for r in metrics(out)["runs"]] == ["skipped"]
    assert (out / "summary.md").is_file()


# -- claiming the output folder -------------------------------------------------------------------
@pytest.mark.slow
def test_a_folder_in_use_by_another_run_is_refused(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    with filelock.FileLock(str(out / ".lock"), timeout=0):  # another run holds it
        proc = run_batch("-i", GOOD, "--export-only", "--format", "json", "-o", out)
        assert proc.returncode == 2 and "in use by another run" in proc.stderr and str(out) in proc.stderr, proc.stderr
        assert not (out / "metrics.json").exists()
        (out / "metrics.json").write_text(json.dumps({"options": {}, "runs": []}))
        proc = run_batch("--resume", out)
        assert proc.returncode == 2 and "in use by another run" in proc.stderr, proc.stderr
    proc = run_batch("-i", GOOD, "--export-only", "--format", "json", "-o", tmp_path / "o2")
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_default_folders_never_collide(tmp_path, monkeypatch):
    """Two runs started in the same second get two folders: every per-second name of the next
    minute is taken already (with results), and a new run still gets a folder of its own."""
    import datetime as dt
    monkeypatch.chdir(tmp_path)
    now = dt.datetime.now()
    taken = set()
    for s in range(-1, 60):
        d = tmp_path / (now + dt.timedelta(seconds=s)).strftime("outputs-%Y%m%d-%H%M%S")
        d.mkdir(exist_ok=True)
        (d / "metrics.json").write_text("{}")
        taken.add(d.name)
    out, lock = runner.claim({"out": None, "resume": None})
    try:
        assert out.name not in taken and out.is_dir() and not (out / "metrics.json").exists()
        out2, lock2 = runner.claim({"out": None, "resume": None})
        lock2.release()
        assert out2 != out
    finally:
        lock.release()


# -- resume -----------------------------------------------------------------------------------------
@pytest.mark.slow
def test_resume_with_a_corrupt_metrics_file_is_named(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    for text in ("{ not json", "[1, 2]", json.dumps({"options": {"spp": "many"}, "runs": []})):
        (out / "metrics.json").write_text(text)
        proc = run_batch("--resume", out)
        assert proc.returncode == 2 and str(out / "metrics.json") in proc.stderr, proc.stderr[-2000:]
        assert "Traceback" not in proc.stderr, proc.stderr[-2000:]


@pytest.mark.slow
def test_resume_needs_exec_again_and_keeps_finished_renders(tmp_path):
    """-e is part of a job's id: a resumed run without -e used to plan other jobs and render the
    finished ones again, over their files. An executable recorded in a run folder is never run
    (issue 30: the folder is data): the resume without -e is refused saying to give it again; with
    the same -e it keeps what finished, and refuses an option that differs."""
    exe = ROOT / ".venv" / "bin" / "mitsuba"
    if not exe.is_file():
        exe = os.path.join(os.path.dirname(sys.executable), "mitsuba")
    out = tmp_path / "o"
    proc = run_batch("-i", GOOD, "-r", "mitsuba", "-e", f"mitsuba={exe}", *TINY, "-o", out)
    assert proc.returncode in (0, 3), proc.stderr[-2000:]
    image = out / metrics(out)["runs"][0]["image"]
    stamp = (image.stat().st_mtime_ns, image.read_bytes())
    proc = run_batch("--resume", out)
    assert proc.returncode == 2 and "-e NAME=PATH" in proc.stderr and "'mitsuba'" in proc.stderr, proc.stderr[-2000:]
    proc = run_batch("--resume", out, "-e", f"mitsuba={exe}")
    assert proc.returncode in (0, 3), proc.stderr[-2000:]
    assert "1 jobs kept, 0 to run" in proc.stderr, proc.stderr[-2000:]
    assert (image.stat().st_mtime_ns, image.read_bytes()) == stamp
    assert metrics(out)["options"]["exec"] == {"mitsuba": str(exe)}
    for args, option in ((["--spp", "8"], "--spp"), (["-e", "mitsuba=/elsewhere/mitsuba"], "-e"),
                         (["-r", "cycles"], "-r"), (["--passes", "3"], "--passes")):
        proc = run_batch("--resume", out, *(args if option == "-e" else ["-e", f"mitsuba={exe}", *args]))
        assert proc.returncode == 2 and option in proc.stderr and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert (image.stat().st_mtime_ns, image.read_bytes()) == stamp


# -- clusters -------------------------------------------------------------------------------------
@pytest.mark.slow
def test_an_unreachable_scheduler_fails_within_the_timeout(tmp_path):
    # port 1 refuses every connection: any timeout ends in the same error, the shortest costs least
    # (--cluster-timeout takes any number > 0)
    proc = run_batch("-i", GOOD, "-r", "mitsuba", *TINY, "--cluster", "tcp://127.0.0.1:1", "--cluster-timeout", "0.1",
                     "-o", tmp_path / "o", timeout=120)
    assert proc.returncode == 2 and "cannot reach the Dask scheduler" in proc.stderr, proc.stderr[-2000:]


@pytest.mark.slow
def test_a_scheduler_without_workers_fails_within_the_timeout(tmp_path):
    from distributed import LocalCluster
    with LocalCluster(n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1",
                      dashboard_address=None) as cluster:
        # the connection to this scheduler must succeed within the timeout, also on a loaded machine:
        # 0.5 s, not the 0.1 s of the tests where every connection fails
        proc = run_batch("-i", GOOD, "-r", "mitsuba", *TINY, "--cluster", cluster.scheduler_address,
                         "--cluster-timeout", "0.5", "-o", tmp_path / "o", timeout=120)
    assert proc.returncode == 2 and "no Dask worker joined" in proc.stderr, proc.stderr[-2000:]


@pytest.mark.slow
def test_a_plaintext_remote_scheduler_is_warned_about(tmp_path):
    # TEST-NET-1 (RFC 5737): never routed, so the connection fails; the warning comes first
    proc = run_batch("-i", GOOD, "-r", "mitsuba", *TINY, "--cluster", "tcp://192.0.2.1:8786", "--cluster-timeout", "0.1",
                     "-o", tmp_path / "o", timeout=120)
    assert "runs whatever code it receives" in proc.stderr and "tls://" in proc.stderr, proc.stderr[-2000:]
    assert proc.returncode == 2


@pytest.mark.slow
def test_a_local_cluster_listens_on_loopback_without_a_dashboard():
    """local:N: scheduler, workers and the scheduler's HTTP server on 127.0.0.1; the dashboard
    (here Dask's page for it) only with --dashboard."""
    import urllib.error
    import urllib.request
    from spectral_bench.batch.jobs import engines
    assert not engines.plaintext_remote("tcp://127.0.0.1:8786") and not engines.plaintext_remote("tls://10.0.0.1:8786")
    assert engines.plaintext_remote("tcp://10.0.0.1:8786") and engines.plaintext_remote("10.0.0.1:8786")

    def status_page(engine):
        http = engine.cluster.scheduler.http_server
        assert http.address == "127.0.0.1"
        try:
            return urllib.request.urlopen(f"http://127.0.0.1:{http.port}/status", timeout=30).status
        except urllib.error.HTTPError as exc:
            return exc.code

    engine = engines.make("local:1", timeout=60)
    try:
        addresses = [engine.cluster.scheduler_address, *engine.client.scheduler_info()["workers"]]
        assert len(addresses) == 2 and all(a.startswith("tls://127.0.0.1:") for a in addresses), addresses
        assert status_page(engine) == 404
    finally:
        engine.close()
    engine = engines.make("local:1", timeout=60, dashboard="127.0.0.1:0")
    try:
        assert status_page(engine) == 200
    finally:
        engine.close()


@pytest.mark.slow
def test_a_local_cluster_takes_no_client_but_the_runs_own():
    """local:N is TLS with the run's own temporary credentials: a plain connection (tcp:// to the
    same port) and one with credentials of its own (another user's self-signed CA) are refused by
    the scheduler and by a worker, where the run's credentials get an answer (the same request);
    a plain Dask client cannot connect to the scheduler, the run's own client runs code in the workers."""
    import asyncio
    from distributed import Client
    from distributed.comm import connect
    from distributed.security import Security
    from spectral_bench.batch.jobs import engines

    async def identity(address, security):
        comm = await connect(address, timeout=5, **security.get_connection_args("client"))
        try:
            await comm.write({"op": "identity"})
            return await comm.read()
        finally:
            await comm.close()

    engine = engines.make("local:1", timeout=60)
    try:
        worker = next(iter(engine.client.scheduler_info()["workers"]))
        assert engine.client.run(os.getpid)[worker] != os.getpid()  # the run's client works
        for address in (engine.cluster.scheduler_address, worker):
            assert address.startswith("tls://127.0.0.1:")
            assert asyncio.run(identity(address, engine.cluster.security))["type"] in ("Scheduler", "Worker")
            plain = "tcp://" + address[len("tls://"):]
            for target, security in ((plain, Security()), (address, Security.temporary())):
                with pytest.raises((OSError, TimeoutError)):
                    asyncio.run(identity(target, security))
        with pytest.raises((OSError, TimeoutError)):
            Client("tcp://" + engine.cluster.scheduler_address[len("tls://"):], timeout=5).close()
    finally:
        engine.close()


def test_dashboard_only_with_a_local_cluster():
    with pytest.raises(cli.UsageError, match="--dashboard"):
        cli.parse(["--dashboard", "127.0.0.1:8787"])
    assert cli.parse(["--cluster", "local:2", "--dashboard", "127.0.0.1:0"])["dashboard"] == "127.0.0.1:0"


def _certificates(folder):
    """A CA and one certificate signed by it (scheduler, worker and client share it here)."""
    def openssl(*args):
        subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True)
    openssl("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "1",
            "-subj", "/CN=spectral-bench-test-ca")
    openssl("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "node.key", "-out", "node.csr", "-subj", "/CN=127.0.0.1")
    openssl("x509", "-req", "-in", "node.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-out", "node.pem",
            "-days", "1")
    return folder / "ca.pem", folder / "node.pem", folder / "node.key"


@pytest.mark.slow
def test_a_tls_scheduler_is_used_through_dasks_own_settings(tmp_path):
    """The TLS recipe of docs/running.md: a scheduler that requires TLS, workers with the preload, and
    batch/run.py pointed at tls://... with Dask's settings in environment variables: the job runs,
    and without them the run is refused (exit 2), not left waiting."""
    from distributed import LocalCluster
    from distributed.security import Security
    from spectral_bench.batch.jobs import engines
    ca, cert, key = _certificates(tmp_path)
    security = Security(tls_ca_file=str(ca), tls_scheduler_cert=str(cert), tls_scheduler_key=str(key),
                        tls_worker_cert=str(cert), tls_worker_key=str(key), tls_client_cert=str(cert),
                        tls_client_key=str(key), require_encryption=True)
    env = {"DASK_DISTRIBUTED__COMM__REQUIRE_ENCRYPTION": "True", "DASK_DISTRIBUTED__COMM__TLS__CA_FILE": str(ca),
           "DASK_DISTRIBUTED__COMM__TLS__CLIENT__CERT": str(cert), "DASK_DISTRIBUTED__COMM__TLS__CLIENT__KEY": str(key)}
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, protocol="tls://", host="127.0.0.1",
                      security=security, dashboard_address=None, preload=[engines.PRELOAD]) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        without = run_batch("-i", GOOD, "-r", "mitsuba", *TINY, "--cluster", address, "--cluster-timeout", "5",
                            "-o", tmp_path / "plain", timeout=120)
        out = tmp_path / "o"
        proc = subprocess.run([sys.executable, str(ROOT / "batch" / "run.py"), "-i", str(GOOD), "-r", "mitsuba",
                               *map(str, TINY), "--cluster", address, "-o", str(out)],
                              capture_output=True, text=True, timeout=600, cwd=ROOT, env=dict(os.environ, **env))
    assert without.returncode == 2 and "cannot reach the Dask scheduler" in without.stderr, without.stderr[-2000:]
    assert proc.returncode in (0, 3), proc.stderr[-3000:]
    assert "runs whatever code" not in proc.stderr
    assert [r["status"] for r in metrics(out)["runs"]] in (["ok"], ["unjudged"])
