"""Progress of a run on stderr: a tqdm bar with rate and ETA on a terminal; on anything else (a
log file, CI, Blender's background run) one plain line per finished job, "[done/total] label",
which the Blender panel and a CI log read as they are."""
import sys


class Progress:
    def __init__(self, total, stream=None):
        self.total, self.done = total, 0
        self.stream = stream or sys.stderr
        self.bar = None
        if hasattr(self.stream, "isatty") and self.stream.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=total, file=self.stream, unit="job", dynamic_ncols=True, leave=True)

    def step(self, label):
        self.done += 1
        if self.bar is not None:
            self.bar.set_postfix_str(label[-60:], refresh=False)
            self.bar.update(1)
        else:
            self.stream.write(f"[{self.done}/{self.total}] {label}\n")
            self.stream.flush()

    def show(self, label):
        """Name the job under way (export-only runs, which finish in a blink)."""
        if self.bar is not None:
            self.bar.set_postfix_str(label[-60:])

    def close(self):
        if self.bar is not None:
            self.bar.close()


class TqdmLogHandler:
    """A logging handler that writes through tqdm, so log lines do not break the bar."""

    def __new__(cls, formatter=None):
        import logging

        class Handler(logging.Handler):
            def emit(self, record):
                from tqdm import tqdm
                tqdm.write(self.format(record), file=sys.stderr)
        h = Handler()
        if formatter is not None:
            h.setFormatter(formatter)
        return h
