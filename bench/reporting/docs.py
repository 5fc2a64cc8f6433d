"""The generated blocks of the documentation (:mod:`bench.reporting.pages`):
docs/methods_and_systems.md's tables of the methods and of the systems, and
the README's lists of both, from the registries, so that a method or a
system registered with its ``title`` and ``summary`` is listed without a page
being edited."""

from __future__ import annotations

import sys
from pathlib import Path

from bench.reporting.pages import block
from bench.runner.plugins import MEASURED, URDF
from methods import METHODS
from methods.hybrid import PRIORS
from systems import SYSTEMS

#: the packages whose methods and systems the documentation lists (another package's, or a test's toy, is not
#: the suite's)
SUITE = ("methods", "bench", "systems")
#: the systems a file declares, which no registry holds until a command names the file
FILE_SYSTEMS = {f"{MEASURED}FILE.toml": "any measured arm: a URDF and robot logs grouped by trajectory, in one file "
                                        "(the README's \"A measured arm\")",
                f"{URDF}FILE.urdf": "any arm from its URDF, every movable joint a coordinate (below)"}


def _suite(registry) -> list[str]:
    """The names ``registry`` holds whose class the suite's packages declare, each at the top of its module
    (a class a factory makes, a test's n-link pendulum or measured arm, is not one of the suite's)."""
    def declared(obj) -> bool:
        module = sys.modules.get(obj.__module__)
        return obj.__module__.split(".")[0] in SUITE and getattr(module, obj.__qualname__, None) is obj
    return [n for n in registry.names() if declared(registry.entry(n).obj)]


def suite_methods() -> list[str]:
    """The methods the suite registers itself, by name."""
    return _suite(METHODS)


def suite_systems() -> list[str]:
    """The systems the suite registers itself, by name."""
    return _suite(SYSTEMS)


@block("docs.methods")
def methods_table(root: Path) -> str:
    """Every method the suite registers: its name, its summary and its tags."""
    lines = ["| method | what | tags |", "|---|---|---|"]
    for name in suite_methods():
        entry = METHODS.entry(name)
        lines.append(f"| `{name}` | {entry.obj.summary or entry.obj.display_name()} | {', '.join(sorted(entry.tags))} |")
    return "\n".join(lines)


@block("docs.systems")
def systems_table(root: Path) -> str:
    """Every system the suite registers, its name and its summary, then the systems a file declares."""
    rows = [(f"`{name}`", SYSTEMS[name].summary) for name in suite_systems()]
    rows += [(f"`{name}`", what) for name, what in FILE_SYSTEMS.items()]
    return "\n".join(["| system | what |", "|---|---|", *(f"| {name} | {what} |" for name, what in rows)])


@block("readme.registries")
def readme_lists(root: Path) -> str:
    """The README's lists of the methods and the systems, by name and title."""
    methods = ", ".join(f"{METHODS[n].title} (`{n}`)" for n in suite_methods())
    systems = ", ".join(f"{SYSTEMS[n].title} (`{n}`)" for n in suite_systems())
    priors = ", ".join(f"`{p}`" for p in PRIORS)
    return (f"* **Methods:** {methods}; and hybrids `PRIOR+RESIDUAL`, an identified model ({priors}) plus any "
            f"method that learns the torque it leaves (`standard+gp`).\n"
            f"* **Systems:** {systems}; any arm from its URDF (`{URDF}FILE.urdf`) and any measured arm declared in "
            f"one file (`{MEASURED}FILE.toml`).")
