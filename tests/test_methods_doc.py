"""docs/methods_and_systems.md lists every registered method, with the registry's tags and its summary, and
every registered system with its summary, and the README lists both by title: the tables and the lists are
blocks ``python -m bench index`` writes from the registries, so a method or a system registered without its
words, or a page not written again since, fails here (tests/reporting/test_index.py checks that every block is
what its generator makes now)."""

from __future__ import annotations

import re
from pathlib import Path

from bench.reporting.docs import FILE_SYSTEMS, suite_methods, suite_systems
from methods import METHODS
from systems import SYSTEMS

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "methods_and_systems.md"


def _rows() -> dict[str, set[str]]:
    table = DOC.read_text().split("## Methods", 1)[1].split("\n\n", 2)[1]
    return {m.group(1): {t.strip() for t in m.group(2).split(",")}
            for m in re.finditer(r"^\| `([a-z_]+)` \| .* \| ([a-z, -]+) \|$", table, re.M)}


def test_every_registered_method_has_its_row_with_its_tags():
    rows = _rows()
    assert sorted(rows) == suite_methods() and len(rows) >= 11
    for name in rows:
        assert rows[name] == set(METHODS.entry(name).tags), name


def test_every_method_of_the_suite_says_what_it_is():
    assert [n for n in suite_methods() if not METHODS[n].summary] == []


def test_every_registered_system_has_its_row_and_says_what_it_is():
    table = DOC.read_text().split("## Systems", 1)[1].split("\n\n", 2)[1]
    rows = re.findall(r"^\| `([\w:.]+)` \| (.+) \|$", table, re.M)
    assert [name for name, _ in rows] == suite_systems() + list(FILE_SYSTEMS) and len(rows) >= 12
    assert [n for n in suite_systems() if not (SYSTEMS[n].summary and SYSTEMS[n].title)] == []
    assert dict(rows)["kuka_lwr4"] == SYSTEMS["kuka_lwr4"].summary


def test_the_readme_names_every_method_and_system_of_the_registries():
    lists = (ROOT / "README.md").read_text().split("<!-- generated readme.registries -->", 1)[1]
    lists = lists.split("<!-- /generated -->", 1)[0]
    named = set(re.findall(r"\(`(\w+)`\)", lists))
    assert named == set(suite_methods()) | set(suite_systems())
    assert "PRIOR+RESIDUAL" in lists and "measured:FILE.toml" in lists
