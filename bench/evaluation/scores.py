"""A fitted model's scores, as a run's record holds them, stage by stage.

* :func:`errors`: train and test MSE in the experiment's own target (``L``
  directly, ``tau`` indirectly);
* :func:`expression_entry`: the readable expression, clipped at
  :data:`MAX_EXPRESSION_CHARS`;
* :func:`exact_entry`: whether it is exactly the true Lagrangian
  (:mod:`bench.evaluation.recovery`), judged within :data:`JUDGE_LIMIT_S`;
* :func:`rollout_entry`: the rollout error (:mod:`bench.evaluation.rollout`),
  with a fault of the model's recorded rather than raised.

:func:`scores` runs the first three through :class:`Stages`: a stage that
raises is named with its error and the others still run, so that a fault
in what follows a fit never discards the fit's MSE.
"""

from __future__ import annotations

import traceback
from typing import Any, Callable

import numpy as np

from bench.core.data import Dataset, mse
from bench.physics.models import FittedModel
from bench.physics.system import System
from bench.core.timeouts import Timeout
from bench.evaluation.recovery import judge
from bench.evaluation.rollout import rollout_error

#: longest expression text kept in a record
MAX_EXPRESSION_CHARS = 20000
#: seconds the symbolic half of the exact-recovery judgement of one expression
#: may take: it expands the Euler–Lagrange images, which sympy cannot be asked
#: to stop, and a run's evaluation has a time limit of its own
JUDGE_LIMIT_S = 60.0


class Stages:
    """Runs the stages that follow a fit. A stage that raises is recorded in
    :attr:`failed` (``{name: "Type: message"}``), its traceback printed to
    stderr (a run's log), and its result is ``default``."""

    def __init__(self, prefix: str = ""):
        self.prefix = prefix
        self.failed: dict[str, str] = {}

    def run(self, name: str, fn: Callable[..., Any], *args, default: Any = None, **kwargs) -> Any:
        try:
            return fn(*args, **kwargs)
        except Exception as exc:
            self.failed[self.prefix + name] = f"{type(exc).__name__}: {exc}"
            print(f"stage {self.prefix + name} failed:", flush=True)
            traceback.print_exc()
            return default


def errors(model: FittedModel, experiment: str, train: Dataset, test: Dataset | None,
           test_prediction: np.ndarray | None = None) -> dict:
    """``train_mse`` and ``test_mse`` (``None`` without test data); ``test_prediction``
    is the model's prediction on ``test`` where the caller has made it already."""
    if test is not None and test_prediction is None:
        test_prediction = model.predict(test, experiment)
    return {
        "train_mse": mse(model.predict(train, experiment), train.target(experiment)),
        "test_mse": mse(test_prediction, test.target(experiment)) if test is not None else None,
    }


def expression_entry(model: FittedModel) -> str | None:
    """The model's readable expression as text, clipped; ``None`` without one."""
    expr = model.readable_expression()
    return None if expr is None else clip(str(expr))


def exact_entry(model: FittedModel, experiment: str, system: System | None) -> dict:
    """``{"exact": True/False/None}``, with ``exact_timed_out`` (the limit)
    where the judgement's symbolic half ran past :data:`JUDGE_LIMIT_S`, and
    ``exact_not_applicable`` where the model is no Lagrangian of (q, qd)."""
    if system is None or not_judged(system) is not None:
        return {"exact": None}
    reason = model.not_a_lagrangian()
    if reason:
        return {"exact": None, "exact_not_applicable": reason}
    expr = model.readable_expression()
    if expr is None:
        return {"exact": None}
    try:
        return {"exact": judge(expr, system.lagrangian_sympy, system.dof, experiment, domain=system.domain,
                               symbolic_limit_s=JUDGE_LIMIT_S).exact}
    except Timeout:
        return {"exact": None, "exact_timed_out": JUDGE_LIMIT_S}


def scores(model: FittedModel, experiment: str, train: Dataset, test: Dataset | None, system: System | None = None,
           stages: Stages | None = None) -> dict:
    """``train_mse``, ``test_mse``, ``expression`` and ``exact`` (``None``
    unless the model has an expression and the system is simulated with a
    closed-form Lagrangian, so that its truth is known; :func:`not_judged`
    says why not), each later stage run through ``stages`` (a new
    :class:`Stages` by default)."""
    stages = stages if stages is not None else Stages()
    out = errors(model, experiment, train, test)
    out["expression"] = stages.run("expression", expression_entry, model)
    out.update(stages.run("exact", exact_entry, model, experiment, system, default={"exact": None}))
    return out


#: why no expression is judged exact on measured data
MEASURED = "the measured system's Lagrangian is not known"


def not_judged(system: System) -> str | None:
    """Why no expression can be judged exact on ``system`` (``None``: it can be)."""
    if not system.simulated:
        return MEASURED
    if not system.symbolic:
        return "the system has no closed-form Lagrangian (its dynamics come from an engine)"
    return None


def rollout_entry(model: FittedModel, system: System, test: Dataset, time_limit_s: float | None = 120.0) -> dict:
    """The record's ``rollout`` entry; a fault in the model's rollout is its own status.
    ``time_limit_s=None`` bounds the integration by its count of evaluations only."""
    reason = model.not_a_lagrangian()
    if reason:
        return {"status": "not_applicable", "q_rmse": None, "detail": reason}
    try:
        return rollout_error(model, system, test, time_limit_s=time_limit_s)
    except Exception as exc:  # the model's fault: recorded, not raised
        return {"status": "failed", "q_rmse": None, "detail": f"{type(exc).__name__}: {exc}"}


def clip(text: str) -> str:
    """An expression's text, cut at :data:`MAX_EXPRESSION_CHARS` with a note of its full length."""
    if len(text) <= MAX_EXPRESSION_CHARS:
        return text
    return text[:MAX_EXPRESSION_CHARS] + f" ... [cut: {len(text)} characters in all]"
