"""Which scores beyond the train and test MSE apply to a run, and their
entries in its record: the one place that tells a simulated system from a
measured one, the direct experiment from the indirect, and a time budget
from a work budget, for scoring.

* a **rollout**: on a simulated system, the model's own trajectories from the
  test states (:mod:`bench.evaluation.rollout`), at most
  :data:`ROLLOUT_LIMIT_S` under a time budget; on measured recordings with
  time stamps, in the indirect experiment, the model driven by the recorded
  torques (:mod:`bench.evaluation.driven`);
* on a **measured** system, in the indirect experiment: the constant model
  and the error per joint and trajectory;
* the models a method is **made of** (a hybrid's prior), beside it;
* where the system has a **standard model** (a measured arm), in the indirect
  experiment: that model, fitted on the same samples;
* the **force decomposition** on the first :data:`FORCES_SAMPLES` test samples.
"""

from __future__ import annotations

import time

from bench.core.experiment import Experiment
from bench.core.data import Dataset
from bench.physics.system import System
from bench.evaluation.driven import driven_entry
from bench.evaluation.forces import forces_entry
from bench.evaluation.per_joint import per_joint_entry
from bench.evaluation.reference import against, applies as has_standard_model, constant_reference, standard_reference
from bench.evaluation.scores import Stages, rollout_entry

#: test samples the force decomposition is scored on (:mod:`bench.evaluation.forces`)
FORCES_SAMPLES = 2000
#: seconds a rollout of a time-budgeted run may take (under a work budget only its count of evaluations bounds it)
ROLLOUT_LIMIT_S = 120.0


def assess(method, experiment: str, system: System, train: Dataset, test: Dataset | None, test_prediction,
           stages: Stages, *, rollout: bool, timed: bool, timing: dict, own_data: bool) -> tuple[dict | None, dict]:
    """The run's rollout entry (``None`` where none applies or ``rollout`` is off) and
    the entries the scores that apply add to its record's details. Each is a stage
    of ``stages``: one that fails is named there, and the others still run. ``timed``:
    the run has a time budget; the seconds of each part go into ``timing``. ``own_data``:
    the data are the system's own split, not files given for it, so that its logged
    torque is the test samples'."""
    details, entry = {}, None
    indirect = Experiment.of(experiment).learns_torque
    if test is not None and rollout and (system.simulated or (test.time is not None and indirect)):
        clock = time.perf_counter()
        if system.simulated:
            entry = stages.run("rollout", rollout_entry, method, system, test, ROLLOUT_LIMIT_S if timed else None)
        else:  # measured recordings: driven by their torques
            entry = stages.run("rollout", driven_entry, method, test)
        timing["rollout_s"] = time.perf_counter() - clock
    if not system.simulated and indirect:
        details["constant_model"] = constant_reference(train, test)
        by_joint = stages.run("per joint", per_joint_entry, test_prediction, system, test, own_data)
        if by_joint is not None:
            details["per_joint"] = by_joint
    references = {name: stages.run(f"reference {name}", against, method, ref, train, test)
                  for name, ref in method.references().items()}
    if references:
        details["references"] = references
    if has_standard_model(system) and indirect:
        clock = time.perf_counter()
        details["standard_model"] = stages.run("standard model", standard_reference, system, train, test)
        timing["standard_model_s"] = time.perf_counter() - clock
    if test is not None:
        clock = time.perf_counter()
        part = test.subset(slice(0, FORCES_SAMPLES))
        forces = stages.run("forces", forces_entry, method, system, part)
        if forces is not None:
            details["forces"] = {"n": len(part), **forces}
        timing["forces_s"] = time.perf_counter() - clock
    return entry, details
