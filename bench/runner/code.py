"""What code made a run: a hash of the files that define its method and system.

:func:`code_hash` hashes the source files of every class in the method's
and the system's class hierarchies that the suite or a plugin defines
(``methods/mlp.py``, ``methods/torch_method.py`` and ``methods/base.py`` for the MLP;
every module of ``methods/syrenets/`` for SyReNets;
``systems/double_pendulum.py`` and ``bench/physics/system.py`` for the double
pendulum), a plugin's file where it defines one of those classes, and the
robot description or measured-arm file a plugin gives the run's system
(:meth:`~bench.physics.system.System.source_files`). A record carries it
(``code``); a resumed matrix redoes a run whose record was made by other
code (:func:`bench.runner.matrix.run_matrix`), so an edited plugin or method
is run again instead of being reported from its old record, and only its
runs: a plugin that defines neither the run's method nor its system is not
the run's code. The rest of the suite (the transform, the data, the runner) is
shared by every run and named by the record's commit (its provenance).
"""

from __future__ import annotations

import hashlib
import inspect
import os
from pathlib import Path

from bench.core.errors import UserError
from bench.core.fileio import file_digest
from bench.runner.plugins import file_prefix, import_plugins
from bench.runner.provenance import PROJECT_ROOT
from methods import METHODS
from systems import SYSTEMS


def _class_files(cls: type) -> list[Path]:
    """Source files of ``cls`` and its bases, outside the standard library and
    installed packages; for a class of a method or system that is a package of
    its own (``methods/syrenets/``), every module of that package."""
    files = []
    for base in inspect.getmro(cls):
        try:
            path = Path(inspect.getsourcefile(base)).resolve()
        except (TypeError, OSError):  # a built-in class
            continue
        if "site-packages" in path.parts or "dist-packages" in path.parts or path.is_relative_to(Path(os.__file__).parent):
            continue
        parts = base.__module__.split(".")
        siblings = sorted(path.parent.glob("*.py")) if len(parts) > 2 and parts[0] in ("methods", "systems") else [path]
        files += [p for p in siblings if p not in files]
    return files


def _name(path: Path) -> str:
    return str(path.relative_to(PROJECT_ROOT)) if path.is_relative_to(PROJECT_ROOT) else str(path)


def code_files(method: str, system: str, plugins: tuple[str, ...] = ()) -> dict[str, str]:
    """``{file: sha256 prefix}`` of the code that defines ``method`` and ``system``
    (a ``.py`` plugin among it where it defines one of their classes), with the
    files of a system that a ``urdf:`` or ``measured:`` plugin gives (the file, and the URDF and logs it names)."""
    paths = _class_files(METHODS[method]) + _class_files(SYSTEMS[system])
    sources = [Path(p).resolve() for p in SYSTEMS[system].source_files() if p]
    given = {Path(p[len(file_prefix(p)):]).expanduser().resolve() for p in plugins if file_prefix(p)}
    if given & set(sources):  # a system given by a plugin's file: that file and the files it names
        paths += [p for p in sources if p.is_file()]
    out = {}
    for path in paths:
        out.setdefault(_name(path), file_digest(path)[:16])
    return dict(sorted(out.items()))


def code_hash(method: str, system: str, plugins: tuple[str, ...] = ()) -> dict | None:
    """The record's ``code`` entry: ``{"hash": ..., "files": {file: digest}}``,
    with the plugins imported first; ``None`` where a name does not resolve
    (the run's own process then records why)."""
    try:
        import_plugins(plugins)
        files = code_files(method, system, plugins)
    except (UserError, OSError):
        return None
    joined = "\n".join(f"{k} {v}" for k, v in files.items())
    return {"hash": hashlib.sha256(joined.encode()).hexdigest()[:16], "files": files}
