"""The suite's false-alarm budget (tests/conftest.py, benchmarks/TESTS.md) adds up: the random
judgements' shares sum to at most SUITE_ALPHA, every test the table names exists and judges at
RANDOM_TEST_ALPHA, and TESTS.md states the numbers the code uses. No renderer: a fast check that a
test added on LuxCore or ART without its share, or a share changed in one place only, shows here."""
import ast
import re

import pytest

from conftest import N_RANDOM_TESTS, RANDOM_JUDGEMENTS, RANDOM_TEST_ALPHA, ROOT, SUITE_ALPHA


def _functions(module):
    tree = ast.parse((ROOT / "tests" / module).read_text(encoding="utf-8"))
    return {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}


def test_the_shares_add_up_to_at_most_the_suite_budget():
    assert SUITE_ALPHA == 1e-3  # issue 45: less than one false alarm in 1000 runs of the suite
    assert N_RANDOM_TESTS == sum(RANDOM_JUDGEMENTS.values()) and all(
        isinstance(n, int) and n >= 1 for n in RANDOM_JUDGEMENTS.values())
    assert N_RANDOM_TESTS * RANDOM_TEST_ALPHA <= SUITE_ALPHA * (1 + 1e-12)  # Bonferroni


@pytest.mark.parametrize("key", sorted(RANDOM_JUDGEMENTS))
def test_every_counted_judgement_names_a_test_that_judges_at_the_suites_share(key):
    module, rest = key.split("::", 1)
    names = re.findall(r"\b(?:test_\w+|art_runs)\b", rest)
    assert names, key
    defined = _functions(module)
    missing = [n for n in names if n not in defined]
    assert not missing, f"{key}: {missing} not defined in tests/{module}"
    text = (ROOT / "tests" / module).read_text(encoding="utf-8")
    assert "RANDOM_TEST_ALPHA" in text, f"tests/{module} counts random judgements but never judges at RANDOM_TEST_ALPHA"


def test_every_module_judging_at_the_suites_share_is_counted():
    counted = {key.split("::", 1)[0] for key in RANDOM_JUDGEMENTS}
    users = {p.relative_to(ROOT / "tests").as_posix() for p in (ROOT / "tests").glob("*/test_*.py")
             if p.name != "test_suite_budget.py" and re.search(r"\bRANDOM_TEST_ALPHA\b", p.read_text(encoding="utf-8"))}
    assert users <= counted, f"judging at RANDOM_TEST_ALPHA but not counted in RANDOM_JUDGEMENTS: {sorted(users - counted)}"


def test_tests_md_states_the_budget_the_code_uses():
    text = (ROOT / "benchmarks" / "TESTS.md").read_text(encoding="utf-8")

    def short(x):  # as TESTS.md writes them: 1e-3, 4e-5 (two significant digits where needed)
        mantissa, exponent = f"{x:.1e}".split("e")
        return f"{mantissa.removesuffix('.0')}e{int(exponent)}"

    assert f"SUITE_ALPHA = {short(SUITE_ALPHA)}" in text
    assert f"{N_RANDOM_TESTS} families at {short(RANDOM_TEST_ALPHA)} each" in text, (N_RANDOM_TESTS, short(RANDOM_TEST_ALPHA))
