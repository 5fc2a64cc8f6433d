"""The system contract, for the modules of this package: it lives in
:mod:`bench.physics.system` (below ``methods/``, which reads systems' declared
forms) and is re-exported here; and :func:`register_file`, how a system
given by a file (``urdf:PATH``, ``measured:PATH``) is registered."""

import re
from pathlib import Path
from typing import Callable

import systems
from bench.core.errors import DataError
from bench.physics.system import HALF_PI, SYSTEMS, Domain, ParametricForm, System, get_system

SYSTEMS.built_in = systems.register_built_in

__all__ = ["HALF_PI", "SYSTEMS", "Domain", "ParametricForm", "System", "get_system", "register_file"]


def register_file(prefix: str, path: str | Path, tags: tuple[str, ...], build: Callable[[Path, str], type],
                  source: Callable[[type], object]) -> str:
    """Register the system ``build(path, name)`` makes of the file at ``path``
    under ``<prefix>_<file stem>`` with ``tags``; returns that name.
    Registering the same file again (``source(cls)`` is its path) is a
    no-op; another file of the same stem is refused in one line."""
    path = Path(path).expanduser().resolve()
    name = prefix + "_" + re.sub(r"[^0-9a-zA-Z]+", "_", path.name.split(".")[0]).strip("_").lower()
    if name in SYSTEMS:
        if source(SYSTEMS[name]) in (path, str(path)):
            return name
        raise DataError(f"{path}: another file is registered as {name!r} already")
    SYSTEMS.add(name, *tags)(build(path, name))
    return name
