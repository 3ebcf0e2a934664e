"""Record a benchmark's Markdown section in a results file under a fixed heading, newest first,
and describe the machine it ran on."""
import os
import platform
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
RESULTS_HEAD = "# Benchmark results\n\nRecorded by the scripts in `benchmarks/` with `--write`; newest first.\n\n"


def cpu_model():
    """The CPU's model name (from /proc/cpuinfo where there is one)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def machine():
    """One line naming the CPU, its core count and the OS, for a results section."""
    return f"{cpu_model()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}"


def record_result(text):
    """Prepend a section to benchmarks/RESULTS.md."""
    prepend(RESULTS, RESULTS_HEAD, text)


def prepend(path, head, text):
    """Put ``text`` right under the file's ``head`` (written if the file does not start with it);
    everything that was there before stays below it."""
    path = Path(path)
    old = path.read_text() if path.exists() else ""
    old = old[len(head):] if old.startswith(head) else old
    path.write_text(head + text + "\n" + old)


def replace_section(path, heading, text):
    """Put ``text`` under the level-2 ``heading`` of a Markdown file, replacing what was there
    (up to the next level-2 heading); a missing section is appended."""
    path = Path(path)
    old = path.read_text() if path.exists() else ""
    marker = f"## {heading}\n"
    block = marker + "\n" + text.strip() + "\n\n"
    if marker not in old:
        path.write_text(old.rstrip() + ("\n\n" if old else "") + block)
        return
    before, rest = old.split(marker, 1)
    after = rest.split("\n## ", 1)[1] if "\n## " in rest else ""
    path.write_text(before + block + ("## " + after if after else ""))
