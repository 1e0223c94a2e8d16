"""The physical order of the stages: the registry follows the explicit list PHYSICAL_ORDER,
each stage's ``order`` agrees with it, and the docs tables are generated from (or follow) it."""
import re
from pathlib import Path

from clpost import stages
from clpost.stages import PHYSICAL_ORDER, STAGE_ROLES, order_table, registry

ROOT = Path(__file__).resolve().parents[1]


def order_problems(reg: dict) -> list[str]:
    """What is wrong with a registry (name → stage class, in the registry's order) against
    PHYSICAL_ORDER: unlisted or missing stages, a different sequence, ``order`` not increasing."""
    problems = []
    unlisted = [n for n in reg if n not in PHYSICAL_ORDER]
    missing = [n for n in PHYSICAL_ORDER if n not in reg]
    if unlisted:
        problems.append(f"stages {unlisted} are not in clpost.stages.PHYSICAL_ORDER: add them to STAGE_ROLES "
                        "where light reaches them, then run python tools/gen_stage_table.py")
    if missing:
        problems.append(f"PHYSICAL_ORDER names {missing}, which no stage module defines")
    listed = [n for n in reg if n in PHYSICAL_ORDER]
    expected = [n for n in PHYSICAL_ORDER if n in reg]
    if listed != expected:
        problems.append(f"registry order {listed} differs from PHYSICAL_ORDER {expected}: fix the stages' `order`")
    for a, b in zip(expected, expected[1:]):
        if not reg[a].order < reg[b].order:
            problems.append(f"{a}.order = {reg[a].order:g} is not below {b}.order = {reg[b].order:g}")
    return problems


def test_registry_follows_the_explicit_physical_order():
    assert order_problems(registry()) == []
    assert list(registry()) == list(PHYSICAL_ORDER)
    assert len(set(PHYSICAL_ORDER)) == len(PHYSICAL_ORDER) == len(STAGE_ROLES)


def test_the_order_check_catches_a_misplaced_an_unlisted_and_a_missing_stage():
    reg = registry()
    swapped = dict(reg)
    swapped["film"], swapped["sensor"] = (type("Film", (), {"name": "film", "order": 86.0}),
                                          type("Sensor", (), {"name": "sensor", "order": 80.0}))
    swapped = dict(sorted(swapped.items(), key=lambda kv: kv[1].order))
    assert any("differs from PHYSICAL_ORDER" in p for p in order_problems(swapped))
    assert "film.order = 86 is not below sensor.order = 80" in order_problems(swapped)
    extra = {**reg, "halation": type("Halation", (), {"name": "halation", "order": 96.0})}
    assert any("['halation'] are not in" in p for p in order_problems(extra))
    fewer = {n: c for n, c in reg.items() if n != "coma"}
    assert any("['coma'], which no stage module defines" in p for p in order_problems(fewer))


def test_docstring_table_is_generated_from_the_list():
    table = order_table()
    assert table in stages.__doc__, "stale stage-order table: run python tools/gen_stage_table.py"
    rows = [line.split()[:2] for line in table.splitlines() if not line.startswith("=")]
    assert [n for _, n in rows] == list(PHYSICAL_ORDER)
    assert [float(o) for o, _ in rows] == [registry()[n].order for n in PHYSICAL_ORDER]


def test_readme_stage_table_is_in_physical_order():
    text = (ROOT / "README.md").read_text()
    section = text.split("## What is modelled", 1)[1].split("\n## ", 1)[0]
    names = re.findall(r"^\| (\w+) \|", section, re.M)
    assert [n for n in names if n != "stage"] == list(PHYSICAL_ORDER)
