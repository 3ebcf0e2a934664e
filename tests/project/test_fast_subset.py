"""The fast subset's rule (tests/conftest.py, docs/developing.md): tests over about 1 s of CPU are
marked slow, and each room (tests/<room>/) keeps fast tests of its code. Read from the test
modules' text (no test is run): a room whose every test were marked slow would leave
`pytest -m "not slow"` silent about that part of the house."""
import ast

from conftest import ROOT

TESTS = ROOT / "tests"


def _marked_slow(decorators):
    return any(ast.unparse(d).replace(" ", "") in ("pytest.mark.slow", "mark.slow") for d in decorators)


def _module_slow(tree):
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in node.targets):
            return "pytest.mark.slow" in ast.unparse(node.value)
    return False


def fast_tests(path):
    """The names of the test functions of module ``path`` not marked slow (by decorator or pytestmark)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    if _module_slow(tree):
        return []
    return [n.name for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")
            and not _marked_slow(n.decorator_list)]


def test_every_room_keeps_fast_tests():
    rooms = sorted(p for p in TESTS.iterdir() if p.is_dir() and any(p.glob("test_*.py")))
    assert len(rooms) >= 10, rooms  # the rooms of docs/developing.md's table
    empty = [room.name for room in rooms if not any(fast_tests(m) for m in room.glob("test_*.py"))]
    assert not empty, f"rooms with no test outside the slow marker: {empty}"


def test_the_marker_states_the_one_second_rule():
    text = (TESTS / "conftest.py").read_text(encoding="utf-8")
    assert "costs over about 1 s of CPU" in text and "under about 1 s of CPU" in text
