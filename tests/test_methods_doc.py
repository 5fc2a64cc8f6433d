"""docs/methods_and_systems.md lists every registered method, with the registry's tags and its summary: the
table is a block ``python -m bench index`` writes from the registry, so a method registered without a summary,
or a page not written again since, fails here."""

from __future__ import annotations

import re
from pathlib import Path

from methods import METHODS

DOC = Path(__file__).resolve().parent.parent / "docs" / "methods_and_systems.md"


def _rows() -> dict[str, set[str]]:
    table = DOC.read_text().split("## Methods", 1)[1].split("\n\n", 2)[1]
    return {m.group(1): {t.strip() for t in m.group(2).split(",")}
            for m in re.finditer(r"^\| `([a-z_]+)` \| .* \| ([a-z, -]+) \|$", table, re.M)}


def _built_in() -> list[str]:
    """The methods the suite registers itself (other tests' plugins register toys in the same process)."""
    return sorted(n for n in METHODS if METHODS.entry(n).obj.__module__.split(".")[0] in ("methods", "bench"))


def test_every_registered_method_has_its_row_with_its_tags():
    rows = _rows()
    assert sorted(rows) == _built_in() and len(rows) >= 11
    for name in rows:
        assert rows[name] == set(METHODS.entry(name).tags), name


def test_every_method_of_the_suite_says_what_it_is():
    assert [n for n in _built_in() if not METHODS[n].summary] == []
