"""docs/methods_and_systems.md lists every registered method, with the registry's tags and its summary: the
table is a block ``python -m bench index`` writes from the registry, so a method registered without a summary,
or a page not written again since, fails here."""

from __future__ import annotations

import re
from pathlib import Path

from bench.reporting.docs import suite_methods
from methods import METHODS

DOC = Path(__file__).resolve().parent.parent / "docs" / "methods_and_systems.md"


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
