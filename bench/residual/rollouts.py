"""What the residual loop reports of its test split, the only place the loop
reads it (:mod:`bench.core.sealed`): each round's test MSE (:func:`test_mse`),
and the driven rollouts it runs after its rounds, on test data with
recordings and time stamps: the model of round 0 and the loop's final model,
each driven by the recorded torques (:func:`bench.evaluation.driven.driven_entry`).
The rollouts' work is the data's and the models', not the budget's; where
they fail, the rounds stand without them."""

from __future__ import annotations

import dataclasses
import traceback

from bench.core.budget import now
from bench.core.data import Dataset, mse
from bench.core.scoring import scoring
from bench.core.errors import first_line
from bench.physics.models import FittedModel
from bench.evaluation.driven import driven_entry
from bench.residual.result import ResidualResult
from bench.residual.sensors import Sensor
from bench.runner.progress import Report


def driven_rollouts(result: ResidualResult, first: FittedModel, model: FittedModel, sensor: Sensor, test: Dataset,
                    report: Report) -> ResidualResult:
    """``result`` with its ``rollout`` (``before``: ``first`` on the test recordings; ``after``:
    ``model``, the arm's model, under the arm's torques as ``sensor``'s laws correct the
    measured ones) and ``rollout_seconds``; where they fail, with why added to ``stopped``."""
    report("driven rollouts of the test recordings, before and after (after the budget: their work is the "
           "data's and the models')")
    t0 = now()
    try:
        with scoring():
            changed = {"rollout": {"before": driven_entry(first, test, report=_indented(report, "before")),
                                   "after": driven_entry(model, sensor.correct(test), report=_indented(report, "after"))}}
    except Exception as exc:  # the rounds stand without their rollouts
        traceback.print_exc()
        failed = f"the driven rollouts after the rounds failed ({type(exc).__name__}: {first_line(exc)}): the rounds are kept"
        changed = {"stopped": failed if result.stopped is None else f"{result.stopped}; {failed}"}
        report(f"stopped: {failed}")
    return dataclasses.replace(result, **changed, rollout_seconds=round(now() - t0, 2))


def test_mse(model: FittedModel, test: Dataset) -> float:
    """``model``'s torque MSE on the test split, to report."""
    with scoring():
        return mse(model.predict_torque(test), test.tau)


def _indented(report: Report, what: str) -> Report:
    """``report`` with each line indented and prefixed by ``what``."""
    return lambda line: report(f"  {what}: {line}")
