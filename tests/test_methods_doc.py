"""docs/methods_and_systems.md lists every registered method, with the registry's tags: a method registered
without its row fails here."""

from __future__ import annotations

import re
from pathlib import Path

import bench.residual.prior  # noqa: F401  (registers the loop)
from methods import METHODS

DOC = Path(__file__).resolve().parent.parent / "docs" / "methods_and_systems.md"


def _rows() -> dict[str, set[str]]:
    table = DOC.read_text().split("## Methods", 1)[1].split("\n\n", 2)[1]
    return {m.group(1): {t.strip() for t in m.group(2).split(",")}
            for m in re.finditer(r"^\| `([a-z_]+)` \| .* \| ([a-z, -]+) \|$", table, re.M)}


def test_every_registered_method_has_its_row_with_its_tags():
    rows = _rows()
    assert sorted(rows) == sorted(METHODS)
    for name in METHODS:
        assert rows[name] == set(METHODS.entry(name).tags), name
