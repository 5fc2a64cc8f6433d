"""Old module names, from before ``bench/`` was split into layers.

Importing one (``from bench import harness``, ``import bench.dynamics``)
gives the module that holds it now, the very same object, and warns once
with a :class:`FutureWarning` that names the new module. Nothing in the
suite imports an old name (``tests/test_architecture.py`` checks it).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

#: old module name -> the module that holds it now
MOVED = {
    "bench.errors": "bench.core.errors",
    "bench.fileio": "bench.core.fileio",
    "bench.registry": "bench.core.registry",
    "bench.data": "bench.core.data",
    "bench.dynamics": "bench.core.dynamics",
    "bench.symbolic": "bench.core.symbolic",
    "bench.regression": "bench.core.regression",
    "bench.effects": "bench.core.effects",
    "bench.timeouts": "bench.core.timeouts",
    "bench.recovery": "bench.evaluation.recovery",
    "bench.rollout": "bench.evaluation.rollout",
    "bench.harness": "bench.runner.matrix",
    "bench.records": "bench.runner.records",
    "bench.tables": "bench.reporting.tables",
    "bench.plots": "bench.reporting.plots",
    "bench.leaderboard": "bench.reporting.leaderboard",
    "bench.adaptation": "bench.experiments.adaptation",
    "bench.residual_acceptance": "bench.experiments.residual_acceptance",
    "bench.overhead": "bench.experiments.overhead",
    "bench.dfki_filter": "bench.experiments.dfki_filter",
}


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Imports an old module name as the module that holds it now."""

    def __init__(self):
        self._own_specs = {}

    def find_spec(self, name, path=None, target=None):
        return importlib.util.spec_from_loader(name, self) if name in MOVED else None

    def create_module(self, spec):
        warnings.warn(f"{spec.name} is now {MOVED[spec.name]}; import it under that name", FutureWarning, stacklevel=2)
        module = importlib.import_module(MOVED[spec.name])
        self._own_specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module):
        # the import system has stamped the old name's spec on the module: give it back its own
        module.__spec__ = self._own_specs.pop(module.__spec__.name)


def install() -> None:
    """Let the old names import (once per process)."""
    if not any(isinstance(finder, _MovedModules) for finder in sys.meta_path):
        sys.meta_path.append(_MovedModules())
