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
"""

from bench.residual.library import loop_library
from bench.residual.job import ResidualJob, run_residual
from bench.residual.loop import residual_loop
from bench.residual.report import write_outputs
from bench.residual.result import ResidualResult
from bench.residual.tracing import trace

__all__ = ["ResidualJob", "ResidualResult", "loop_library", "residual_loop", "run_residual", "trace", "write_outputs"]
