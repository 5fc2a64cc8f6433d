"""The suite's import structure, measured from its source.

``python -m tests.architecture`` prints the figures the layered architecture
is judged by: modules directly in ``bench/``, import cycles between the
suite's modules and between its packages, imports of the suite's own modules
inside functions, imports from ``methods/`` or ``systems/`` into ``bench``
outside ``bench.core`` and ``bench.physics``, and the largest module. ``tests/test_architecture.py``
asserts them.

Counted with ``bench`` as one package, ``bench`` and ``methods`` import each
other by design: ``bench.core`` and ``bench.physics`` lie below ``methods`` and ``bench.runner``
above it. The figure that judges the layers counts each subpackage of
``bench`` as a package of its own.

Every ``import`` statement counts, at module level or inside a function, so
that an import hidden in a function to dodge a cycle is seen. The command
line (``bench.cli``), the top layer, which no cycle can pass through, is
counted apart: a command imports its engine (the methods, the physics, the
runner) in its ``main``, once its input is checked, so that a refused input
is answered before torch, sympy or Pinocchio is imported. ``from a import
b`` counts as an import of the module ``a.b`` where that is a module of the
suite, else of ``a``.
"""

from __future__ import annotations

import ast
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from bench.runner.sources import absolute

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("bench", "methods", "systems")


@dataclass(frozen=True)
class Import:
    importer: str
    target: str
    line: int
    in_function: bool


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def suite_modules(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the suite's packages, by dotted name."""
    out = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            out[module_name(path, root)] = path
    return out


def imports(modules: dict[str, Path]) -> list[Import]:
    """The imports of suite modules by suite modules."""
    found = []
    for name, path in modules.items():
        tree = ast.parse(path.read_text(), str(path))
        is_package = path.name == "__init__.py"

        def visit(node, in_function):
            for child in ast.iter_child_nodes(node):
                inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
                if isinstance(child, ast.Import):
                    targets = [a.name for a in child.names]
                elif isinstance(child, ast.ImportFrom):
                    base = absolute(child, name.split("."), is_package)
                    targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in child.names]
                else:
                    visit(child, inside)
                    continue
                for target in dict.fromkeys(targets):
                    while target and target not in modules:
                        target = target.rpartition(".")[0]
                    if target and target.split(".")[0] in PACKAGES:
                        found.append(Import(name, target, child.lineno, in_function))

        visit(tree, False)
    return found


def cycles(edges: set[tuple[str, str]]) -> list[list[str]]:
    """Groups of nodes that import each other, directly or through others
    (strongly connected components of more than one node)."""
    nodes = sorted({n for e in edges for n in e})
    if not nodes:
        return []
    index = {n: i for i, n in enumerate(nodes)}
    rows, cols = zip(*[(index[a], index[b]) for a, b in edges if a != b]) if any(a != b for a, b in edges) else ((), ())
    graph = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(nodes), len(nodes)))
    _, labels = connected_components(graph, directed=True, connection="strong")
    groups: dict[int, list[str]] = {}
    for node, label in zip(nodes, labels):
        groups.setdefault(label, []).append(node)
    return sorted(g for g in groups.values() if len(g) > 1)


def package_of(module: str) -> str:
    """``bench.<subpackage or module>`` inside bench, else the top-level package."""
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "bench" else parts[0]


def _command_line(module: str) -> bool:
    return module == "bench.cli" or module.startswith("bench.cli.")


#: the layers of ``bench`` below ``methods/`` and ``systems/``, the only ones they may import
BELOW_METHODS = ("bench.core", "bench.physics")


def measure(root: Path = ROOT) -> dict:
    modules = suite_modules(root)
    found = imports(modules)
    module_edges = {(i.importer, i.target) for i in found if i.importer != i.target}
    top_edges = {(i.importer.split(".")[0], i.target.split(".")[0]) for i in found}
    layer_edges = {(package_of(i.importer), package_of(i.target)) for i in found}
    outside_core = [
        i for i in found
        if i.importer.split(".")[0] in ("methods", "systems") and i.target.split(".")[0] == "bench"
        and not any(i.target == below or i.target.startswith(below + ".") for below in BELOW_METHODS)
    ]
    lines = {name: len(path.read_text().splitlines()) for name, path in modules.items()}
    largest = max(lines, key=lines.get)
    return {
        "modules directly in bench/": len(list((root / "bench").glob("*.py"))),
        "module cycles": cycles(module_edges),
        "cycles between packages (methods, systems, each of bench's subpackages or flat modules)": cycles(layer_edges),
        "cycles between top-level packages (bench counted whole, core and all)": cycles(top_edges),
        "in-function imports of suite modules": [i for i in found if i.in_function and not _command_line(i.importer)],
        "in-function imports in the command line (a command's engine, once its input is checked)":
            [i for i in found if i.in_function and _command_line(i.importer)],
        "imports from methods/ or systems/ into bench outside bench.core and bench.physics": outside_core,
        "largest module": (str(modules[largest].relative_to(root)), lines[largest]),
    }


def main() -> int:
    for key, value in measure().items():
        if isinstance(value, list):
            print(f"{key}: {len(value)}")
            for item in value:
                text = " -> ".join(item) if isinstance(item, list) else f"{item.importer}:{item.line} imports {item.target}"
                print(f"    {text}")
        elif isinstance(value, tuple):
            print(f"{key}: {value[0]}, {value[1]} lines")
        else:
            print(f"{key}: {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
