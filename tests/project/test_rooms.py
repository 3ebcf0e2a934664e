"""Tests where a developer looks for them (issue 45 item 4): each test module imports other test
modules only from its own room (tests/<room>/); what rooms share lives in the helper modules of
tests/ (conftest, installed, fake_renderer, noisy_runs, ...). Read from the modules' text (no test is run)."""
import ast

from conftest import ROOT

TESTS = ROOT / "tests"


def imported_test_modules(path):
    """The names of the test_* modules that the module at ``path`` imports (anywhere in it)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names if a.name.startswith("test_"))
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("test_"):
            names.add(node.module)
    return names


def test_a_test_module_imports_test_modules_of_its_own_room_only():
    rooms = {p.stem: p.parent.name for p in TESTS.glob("*/test_*.py")}
    assert len(rooms) > 50 and len(set(rooms.values())) >= 10, rooms
    crossing = sorted(f"{path.parent.name}/{path.name} imports {name} ({rooms.get(name, 'no room')})"
                      for path in TESTS.glob("*/test_*.py") for name in imported_test_modules(path)
                      if rooms.get(name) != path.parent.name)
    assert not crossing, "shared pieces belong in a helper module of tests/: " + "; ".join(crossing)


def test_the_check_sees_a_module_of_another_room(tmp_path):
    module = tmp_path / "test_x.py"
    module.write_text("import json\nfrom test_pbrt import needs_pbrt\n\ndef f():\n    import test_report as r\n")
    assert imported_test_modules(module) == {"test_pbrt", "test_report"}
