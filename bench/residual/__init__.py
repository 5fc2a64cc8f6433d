"""The residual loop: trace what a fitted model lacks to physical effects,
add them, refit, and report the error before and after.

* :mod:`~bench.residual.library`: the named effects and the open-ended
  library, as terms;
* :mod:`~bench.residual.tracing`: stepwise selection with its statistics,
  by the tests of :mod:`~bench.residual.criteria`,
  on :mod:`~bench.residual.basis` (projections off the design) and
  :mod:`~bench.residual.shapes` (a shaped effect's nonlinear parameter);
* :mod:`~bench.physics.sensor_laws`, :mod:`~bench.residual.sensors`: the
  laws of the torque sensor and the drive (a gain, a time shift, a
  load-dependent friction), one class each, which act on the measured torque
  rather than on the arm, and the loop's handling of them;
* :mod:`~bench.residual.strategies`: how the loop refits each kind of model;
* :mod:`~bench.residual.pruning`, :mod:`~bench.residual.tidying`,
  :mod:`~bench.residual.checks`, :mod:`~bench.residual.beyond_data`: what
  follows a refit, what keeps or undoes a round, and what an effect may
  claim beyond the data;
* :mod:`~bench.residual.loop`: the loop, in this process (:func:`residual_loop`);
* :mod:`~bench.residual.job`: the loop through the runner (:func:`run_residual`);
* :mod:`~bench.residual.result`, :mod:`~bench.residual.report`: its typed
  result and its outputs.

The package imports none of them until one of its names is asked for (PEP 562's module ``__getattr__``), so
that :mod:`bench.residual.limits` is read without the loop.
"""

import importlib

_EXPORTS = {
    "ResidualJob": "bench.residual.job", "ResidualResult": "bench.residual.result",
    "loop_library": "bench.residual.library", "residual_loop": "bench.residual.loop",
    "run_residual": "bench.residual.job", "trace": "bench.residual.tracing", "write_outputs": "bench.residual.report",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'bench.residual' has no attribute {name!r}")
