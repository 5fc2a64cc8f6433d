"""syrenets-bench: learning the dynamics of physical systems, symbolically and neurally.

The package is built in layers, and imports point down only
(``tests/test_architecture.py`` enforces it)::

    bench.cli                       the one command line
    bench.experiments               measurement scripts run as subcommands
    bench.reporting, bench.residual tables, plots, leaderboard; the residual loop
    bench.evaluation, bench.runner  scores, recovery, rollouts; runs, records, isolation, the matrix
    methods, systems                the registries (top-level packages)
    bench.core                      data, dynamics, symbolic, terms, models, systems' contract

Modules that lived directly in ``bench/`` before it was split into layers
still import under their old names (``from bench import harness``,
``from bench.dynamics import euler_lagrange``): :data:`MOVED` maps each to its
new home, and importing the old name gives the very same module object.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys

__version__ = "0.1.0"

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
        module = importlib.import_module(MOVED[spec.name])
        self._own_specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module):
        # the import system has stamped the old name's spec on the module: give it back its own
        module.__spec__ = self._own_specs.pop(module.__spec__.name)


if not any(isinstance(finder, _MovedModules) for finder in sys.meta_path):
    sys.meta_path.append(_MovedModules())
