"""A fitted model's scores, as a run's record holds them.

* :func:`scores`: train and test MSE in the experiment's own target (``L``
  directly, ``tau`` indirectly), the readable expression (clipped at
  :data:`MAX_EXPRESSION_CHARS`), and whether it is exactly the true
  Lagrangian (:mod:`bench.evaluation.recovery`), judged within
  :data:`JUDGE_LIMIT_S`;
* :func:`rollout_entry`: the rollout error (:mod:`bench.evaluation.rollout`),
  with a fault of the model's recorded rather than raised.
"""

from __future__ import annotations

from bench.core.data import Dataset, mse
from bench.core.models import FittedModel
from bench.core.system import System
from bench.core.timeouts import Timeout
from bench.evaluation.recovery import judge
from bench.evaluation.rollout import rollout_error

#: longest expression text kept in a record
MAX_EXPRESSION_CHARS = 20000
#: seconds the symbolic half of the exact-recovery judgement of one expression
#: may take: it expands the Euler–Lagrange images, which sympy cannot be asked
#: to stop, and a run's evaluation has a time limit of its own
JUDGE_LIMIT_S = 60.0


def scores(model: FittedModel, experiment: str, train: Dataset, test: Dataset | None, system: System | None = None) -> dict:
    """``train_mse``, ``test_mse`` (``None`` without test data), ``expression``
    and ``exact`` (``None`` unless the model has an expression and the system
    is simulated with a closed-form Lagrangian, so that its truth is known;
    :func:`not_judged` says why not).

    The judgement's symbolic half runs in a child process, stopped after
    :data:`JUDGE_LIMIT_S`; then ``exact`` is ``None`` and ``exact_timed_out``
    holds the limit."""
    expr = model.readable_expression()
    out = {
        "train_mse": mse(model.predict(train, experiment), train.target(experiment)),
        "test_mse": mse(model.predict(test, experiment), test.target(experiment)) if test is not None else None,
        "expression": None if expr is None else clip(str(expr)),
        "exact": None,
    }
    if expr is not None and system is not None and not_judged(system) is None:
        try:
            out["exact"] = judge(expr, system.lagrangian_sympy, system.dof, experiment, domain=system.domain,
                                 symbolic_limit_s=JUDGE_LIMIT_S).exact
        except Timeout:
            out["exact_timed_out"] = JUDGE_LIMIT_S
    return out


def not_judged(system: System) -> str | None:
    """Why no expression can be judged exact on ``system`` (``None``: it can be)."""
    if not system.simulated:
        return "the measured system's Lagrangian is not known"
    if not system.symbolic:
        return "the system has no closed-form Lagrangian (its dynamics come from an engine)"
    return None


def rollout_entry(model: FittedModel, system: System, test: Dataset) -> dict:
    """The record's ``rollout`` entry; a fault in the model's rollout is its own status."""
    try:
        return rollout_error(model, system, test)
    except Exception as exc:  # the model's fault: recorded, not raised
        return {"status": "failed", "q_rmse": None, "detail": f"{type(exc).__name__}: {exc}"}


def clip(text: str) -> str:
    """An expression's text, cut at :data:`MAX_EXPRESSION_CHARS` with a note of its full length."""
    if len(text) <= MAX_EXPRESSION_CHARS:
        return text
    return text[:MAX_EXPRESSION_CHARS] + f" ... [cut: {len(text)} characters in all]"
