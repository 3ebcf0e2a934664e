"""Rows that say the same thing once: a backend skipped (or unsupported) on every scene of a run
with one reason is one line, not a row per scene ("skipped: artist not found" 27 times). Shared
by report.html and summary.md (plain data in, plain data out)."""
from ..verdict.status import NOT_RUN


def not_run_everywhere(runs):
    """(the runs left to list one by one, [{backend, mode, status, reason, scenes}] for each
    (backend, mode) whose every run is one not-run status with one reason, on more than one scene).
    ``runs``: metrics.json run entries (dicts); any other value is left in the first list."""
    by = {}
    for r in runs:
        if isinstance(r, dict):
            by.setdefault((str(r.get("backend")), str(r.get("mode"))), []).append(r)
    grouped, rows = set(), []
    for (backend, mode), rs in by.items():
        kinds = {(str(r.get("status")), str(r.get("reason") or "")) for r in rs}
        if len(rs) > 1 and len(kinds) == 1 and next(iter(kinds))[0] in NOT_RUN:
            status, reason = next(iter(kinds))
            rows.append({"backend": backend, "mode": rs[0].get("mode"), "status": status, "reason": reason,
                         "scenes": len(rs)})
            grouped.add((backend, mode))
    left = [r for r in runs if not (isinstance(r, dict) and (str(r.get("backend")), str(r.get("mode"))) in grouped)]
    return left, rows
