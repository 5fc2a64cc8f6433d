"""The code of a run: the source files its result depends on, and their hash
(the record's ``code``, :func:`code_hash`).

A run's code is

* the files of the objects its method names (:meth:`methods.base.Method.code_objects`:
  the method's class, and for a hybrid its residual's class and what
  identifies its prior) and of its system's class, each with its bases'
  files; for a class of a package of its own (``methods/syrenets/``), every
  module of that package;
* every module of the suite (``bench``, ``methods``, ``systems``) that those
  files and the modules that run a method (:data:`RUNS_IN`: the fit, the
  tuning, the scoring) import, however deep: the import statements are read
  from the source (:func:`imported`), function-level ones included. The two
  registries' package modules (``methods/__init__.py``, ``systems/__init__.py``)
  are hashed but not followed: they import every method and every system,
  and a run's own are named above;
* a plugin's file where it defines one of the classes, and the files that
  define the run's system outside the code, whether shipped or given by a
  plugin: its robot description, and a measured arm's file and every
  recording it names (:meth:`~bench.physics.system.System.source_files`), so
  that an edited recording, filter or URDF redoes the runs that read it.

A resumed matrix redoes a run whose record was made by other code
(:func:`bench.runner.matrix.run_matrix`): an edited method, data format,
tuning or scorer is run again instead of being reported from its old record,
and an edited plugin redoes only the runs of what it defines. A module a
plugin file imports from beside it, outside the suite, is not followed.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import inspect
import os
from pathlib import Path

from bench.core.errors import UserError
from bench.core.fileio import file_digest
from bench.runner.plugins import code_plugins, import_plugins, plugin_digest
from bench.runner.provenance import PROJECT_ROOT
import methods
import systems

#: the suite's packages, whose modules a run's code follows
PACKAGES = ("bench", "methods", "systems")
#: the registries' package modules: hashed, their imports (every method, every system) not followed
REGISTRIES = ("methods/__init__.py", "systems/__init__.py")
#: the modules in which a run of a method is fitted, tuned and scored: on its own, or as one seed of a stack
RUNS_IN = ("bench.runner.run", "bench.runner.stacked")


def module_file(name: str) -> Path | None:
    """The suite's source file of the module ``name`` (a package's ``__init__.py``); ``None`` for a module outside
    the suite or a name that is no module (an attribute imported from one)."""
    parts = name.split(".")
    if parts[0] not in PACKAGES:
        return None
    path = PROJECT_ROOT.joinpath(*parts)
    if (path / "__init__.py").is_file():
        return path / "__init__.py"
    return path.with_suffix(".py") if path.with_suffix(".py").is_file() else None


def _module_name(path: Path) -> tuple[list[str], bool]:
    """A suite file's module name, as parts, and whether it is a package's ``__init__.py``."""
    parts = list(path.relative_to(PROJECT_ROOT).with_suffix("").parts)
    package = parts[-1] == "__init__"
    return (parts[:-1] if package else parts), package


def imported(path: Path) -> set[Path]:
    """The suite's files that the source ``path`` imports anywhere in it, with the packages' ``__init__.py``
    above each (Python runs them first)."""
    return set(_imported(path, *_stamp(path)))


def _stamp(path: Path) -> tuple[int, int]:
    stat = path.stat()
    return stat.st_mtime_ns, stat.st_size


def absolute(node: ast.ImportFrom, module: list[str], package: bool) -> str:
    """The absolute name of the module that ``from ... import`` ``node`` reads from, in the module named
    ``module`` (its parts; ``package``: whether it is a package's ``__init__.py``): a relative import climbs
    one package a dot above the first."""
    if not node.level:
        return node.module or ""
    base = module if package else module[:-1]
    base = base[:len(base) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


@functools.lru_cache(maxsize=1024)
def _imported(path: Path, mtime_ns: int, size: int) -> tuple[Path, ...]:
    inside = path.is_relative_to(PROJECT_ROOT)
    here, package = _module_name(path) if inside else ([], False)
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_bytes(), filename=str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level and not inside:  # relative, in a file outside the suite: not the suite's
                continue
            module = absolute(node, here, package)
            names += [module] + [f"{module}.{alias.name}" for alias in node.names]
    found = set()
    for name in names:
        parts = name.split(".")
        for k in range(1, len(parts) + 1):
            file = module_file(".".join(parts[:k]))
            if file is not None:
                found.add(file)
    return tuple(sorted(found))


def read_all_imports() -> None:
    """Read the imports of every file of the suite once (:func:`imported`, cached by each file's stamp): the
    fork server does, so that each run forked from it hashes its code (:func:`code_files`) without parsing
    the files again."""
    for package in PACKAGES:
        for path in sorted((PROJECT_ROOT / package).rglob("*.py")):
            imported(path.resolve())


def closure(roots: list[Path]) -> list[Path]:
    """``roots`` and every suite file they import, however deep (:func:`imported`; the :data:`REGISTRIES` are
    not followed)."""
    seen: set[Path] = set()
    todo = list(roots)
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        if path.is_relative_to(PROJECT_ROOT) and str(path.relative_to(PROJECT_ROOT)) in REGISTRIES:
            continue
        todo += imported(path)
    return sorted(seen)


def _source_file(obj) -> Path | None:
    """The file that defines ``obj``, outside the standard library and installed packages; ``None`` for one
    defined there or built in."""
    try:
        path = Path(inspect.getsourcefile(obj)).resolve()
    except (TypeError, OSError):  # a built-in
        return None
    if "site-packages" in path.parts or "dist-packages" in path.parts or path.is_relative_to(Path(os.__file__).parent):
        return None
    return path


def object_files(obj) -> list[Path]:
    """Source files of ``obj`` (a class with its bases, or a function); for a class of a method or a system
    that is a package of its own (``methods/syrenets/``), every module of that package."""
    files: list[Path] = []
    for item in inspect.getmro(obj) if inspect.isclass(obj) else (obj,):
        path = _source_file(item)
        if path is None:
            continue
        parts = item.__module__.split(".")
        siblings = sorted(path.parent.glob("*.py")) if len(parts) > 2 and parts[0] in ("methods", "systems") else [path]
        files += [p for p in siblings if p not in files]
    return files


def _name(path: Path) -> str:
    return str(path.relative_to(PROJECT_ROOT)) if path.is_relative_to(PROJECT_ROOT) else str(path)


@functools.lru_cache(maxsize=4096)
def _digest(path: Path, mtime_ns: int, size: int) -> str:
    return file_digest(path)[:16]


def code_files(method: str, system: str, plugins: tuple[str, ...] = (),
               runs_in: tuple[str, ...] = RUNS_IN) -> dict[str, str]:
    """``{file: sha256 prefix}`` of a run's code (the module docstring); ``runs_in`` names the modules that run it
    (the residual loop's job names its own)."""
    roots: list[Path] = []
    for obj in (*methods.METHODS[method].code_objects(), systems.SYSTEMS[system]):
        roots += [p for p in object_files(obj) if p not in roots]
    paths = closure(roots + [f for f in map(module_file, runs_in) if f is not None])
    # the files that define the system outside the code: its robot description, a measured arm's file and its
    # recordings
    paths += [p for p in (Path(f).resolve() for f in systems.SYSTEMS[system].source_files() if f) if p.is_file()]
    out = {}
    for path in paths:
        out.setdefault(_name(path), _digest(path, *_stamp(path)))
    return dict(sorted(out.items()))


def code_hash(method: str, system: str, plugins: tuple[str, ...] = (),
              runs_in: tuple[str, ...] = RUNS_IN) -> dict | None:
    """The record's ``code`` entry: ``{"hash": ..., "files": {file: digest}}``, with the plugins imported first,
    and where the run imported plugins that run code, ``"plugins": {plugin: sha256}``, each whole (what ``bench
    rerun`` checks before it imports them again: :func:`bench.runner.replay.check_plugins`); ``None`` where a name
    does not resolve (the run's own process then records why)."""
    try:
        import_plugins(plugins)
        files = code_files(method, system, plugins, runs_in)
    except (UserError, OSError, SyntaxError):
        return None
    joined = "\n".join(f"{k} {v}" for k, v in files.items())
    out = {"hash": hashlib.sha256(joined.encode()).hexdigest()[:16], "files": files}
    run = code_plugins(plugins)
    if run:
        out["plugins"] = {p: plugin_digest(p) for p in run}
    return out
