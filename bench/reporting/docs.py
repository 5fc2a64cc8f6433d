"""The generated blocks of the documentation (:mod:`bench.reporting.pages`):
docs/methods_and_systems.md's table of the methods, from the method registry,
so that a method registered with its :attr:`~methods.base.Method.summary` is
listed with its tags without the page being edited."""

from __future__ import annotations

from pathlib import Path

from bench.reporting.pages import block
from methods import METHODS

#: the packages whose methods the documentation lists (another package's, or a test's toy, is not the suite's)
SUITE = ("methods", "bench")


def suite_methods() -> list[str]:
    """The methods the suite registers itself, by name."""
    return [n for n in METHODS.names() if METHODS.entry(n).obj.__module__.split(".")[0] in SUITE]


@block("docs.methods")
def methods_table(root: Path) -> str:
    """Every method the suite registers: its name, its summary and its tags."""
    lines = ["| method | what | tags |", "|---|---|---|"]
    for name in suite_methods():
        entry = METHODS.entry(name)
        lines.append(f"| `{name}` | {entry.obj.summary or entry.obj.display_name()} | {', '.join(sorted(entry.tags))} |")
    return "\n".join(lines)
