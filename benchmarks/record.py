"""Record a benchmark's Markdown section in a results file under a fixed heading, newest first."""
from pathlib import Path


def prepend(path, head, text):
    path = Path(path)
    old = path.read_text() if path.exists() else ""
    old = old[len(head):] if old.startswith(head) else ""
    path.write_text(head + text + "\n" + old)
