"""syrenets-bench: learning the dynamics of physical systems, symbolically and neurally.

The package is built in layers, and imports point down only
(``tests/test_architecture.py`` enforces it)::

    bench.cli                       the one command line
    bench.studies               measurement scripts run as subcommands
    bench.reporting, bench.residual tables, plots, leaderboard; the residual loop
    bench.evaluation, bench.runner  scores, recovery, rollouts; runs, records, isolation, the matrix
    methods, systems                the registries (top-level packages)
    bench.core                      data, dynamics, symbolic, terms, models, systems' contract
"""

from __future__ import annotations

__version__ = "0.1.0"
