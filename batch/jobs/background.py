"""The batch runner as a background child process, for the Blender panel: start, poll
progress from metrics.json (rewritten after every job), cancel cleanly.

Cancel stops the runner and its renders (one process group) between or during jobs; every job
that finished is already in metrics.json and stays there.
"""
import os
import signal
import subprocess
import sys
from pathlib import Path

from .. import run_folder

RUN_PY = Path(__file__).resolve().parents[1] / "run.py"


class BackgroundRun:
    def __init__(self, inputs, out_dir, total_jobs, extra_args=(), python=None):
        self.out_dir = Path(out_dir)
        self.total = total_jobs
        self.cmd = [python or sys.executable, str(RUN_PY), "-i", *map(str, inputs), "-o", str(out_dir), *extra_args]
        self.proc = None
        self.cancelled = False
        self.log_path = self.out_dir.parent / f"{self.out_dir.name}.log"

    def start(self):
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen(self.cmd, stdout=self.log, stderr=subprocess.STDOUT, env=env,
                                     start_new_session=True)
        return self

    def done_jobs(self):
        data = run_folder.load(self.out_dir)
        return len(data.entries("runs")) if data is not None else 0

    def running(self):
        return self.proc is not None and self.proc.poll() is None

    def progress(self):
        """(jobs done, total, finished?)"""
        return self.done_jobs(), self.total, not self.running()

    def returncode(self):
        return None if self.proc is None else self.proc.poll()

    def cancel(self, timeout=10):
        """Stop the runner and its child renders; finished results stay in metrics.json."""
        if not self.running():
            return
        self.cancelled = True
        os.killpg(self.proc.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        self.log.close()

    def wait(self, timeout=None):
        self.proc.wait(timeout)
        self.log.close()
        return self.proc.returncode
