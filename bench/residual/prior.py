"""The residual loop's final model as a method, ``loop``, and as a hybrid's
prior, ``loop+RESIDUAL`` (``loop+gp``), wherever a method name goes.

The loop (:func:`bench.residual.loop.residual_loop`) fits SysId's feasible
rigid body on the training data and adds the laws of the arm, the sensor and
the drive that the data identify; its final model (the rigid body, its named
laws, read through the sensor's laws) is the prior, and the residual learner
of :mod:`methods.hybrid` is fitted to what it leaves.

The loop's rounds are bounded by work, never by a share of seconds, so that
the same samples and seed give the same model on any machine:

* as a hybrid's prior it runs as ``bench residual --steps 1`` runs it
  (SysId's one solve a fit) until a round accepts nothing, at most
  :data:`~bench.residual.limits.MAX_ROUNDS` rounds, whatever the hybrid's
  budget; being fixed work, it is identified before that budget starts
  (:meth:`methods.hybrid.Hybrid.prepare_samples`);
* as the method ``loop`` a round is its step: under a work budget of ``N``
  steps it runs at most ``N`` rounds (and at most ``MAX_ROUNDS``), so that a
  tuned or selected ``loop`` is validated at the rounds its final fit runs
  (:mod:`bench.evaluation.tuning`); under a time budget the budget bounds it.

The method registry imports this module, which registers the method and the
prior, the first time it is asked for a method: ``pyproject.toml`` declares it
as an entry point of the registry's group (:mod:`bench.core.registry`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from bench.core.experiment import INDIRECT
from bench.core.budget import Budget
from bench.core.data import Dataset
from bench.physics.models import FittedModel
from bench.residual.limits import MAX_ROUNDS
from bench.residual.loop import not_started, residual_loop
from bench.residual.result import ResidualResult
from methods.base import METHODS, Method
from methods.config import MethodConfig, Named
from methods.hybrid import Prior, keep_shared, prior_unavailable, register_prior
from methods.progress import Progress

#: the method whose model the loop extends
METHOD = "sysid"


@dataclass(frozen=True)
class LoopConfig(MethodConfig):
    """``friction``: the loop starts from select's ``feasible`` model (SysId's ``feasible`` configuration: the
    feasible rigid body with Coulomb and viscous friction and rotor inertia held at 0 or above and a torque offset
    on each joint), rather than from the rigid body alone; those laws are then the start's, and the loop traces
    what that model lacks."""

    friction: bool = False


def identify(train: Dataset, system, seed: int) -> FittedModel:
    """The loop's final model on ``train``: SysId's one solve a fit, until a round accepts nothing (at most
    :data:`~bench.residual.limits.MAX_ROUNDS` rounds), its progress printed line by line."""
    return run(train, seed, Budget(steps=1), MAX_ROUNDS).models[1]


def run(train: Dataset, seed: int, budget: Budget, rounds: int | None = None, friction: bool = False) -> ResidualResult:
    """The loop on ``train`` within ``budget``, at most ``rounds`` rounds (default: under a work budget of ``N``
    steps, ``N``; under a time budget, :data:`~bench.residual.limits.MAX_ROUNDS`), from the rigid body alone or,
    with ``friction``, from SysId's feasible model with each joint's laws (:class:`LoopConfig`), its progress
    printed line by line."""
    if rounds is None:
        rounds = MAX_ROUNDS if budget.steps is None else budget.steps
    return residual_loop(METHOD, train, None, budget=Budget(steps=budget.steps) if budget.steps is not None else budget,
                         seed=seed, hyperparameters=METHODS[METHOD].configuration("feasible") if friction else None,
                         max_rounds=min(rounds, MAX_ROUNDS),
                         report=lambda line: print(f"prior: {line}", flush=True))


def rounds_run(result: ResidualResult) -> int:
    """The rounds after round 0 that the loop ran, finished or undone (one not started is not counted)."""
    skipped = None if result.budget_s is None else not_started(result.budget_s)
    return sum(1 for r in result.rounds if r["round"] > 0 and (skipped is None or r.get("stop") != skipped))


PRIOR = register_prior(Prior("loop", "the residual loop's model from SysId (the feasible rigid body and its named laws)",
                             identify, "the loop's model"))


@METHODS.add("loop", "symbolic", "residual")
class Loop(Method):
    """The residual loop's final model from SysId as a method of its own
    (``bench run --methods loop``, a candidate of ``bench select``): fitted by
    :func:`run` within the run's whole budget, a round its step (under a work
    budget of ``N`` steps, at most ``N`` rounds)."""

    title = "the residual loop's model from SysId"
    #: what the method is, for docs/methods_and_systems.md (generated from the registry)
    summary = ("the residual loop's final model as a method: SysId's rigid body and the laws of the arm, the "
               "sensor and the drive that the data identify (a round a step); `--config loop=feasible` starts it "
               "from the feasible body with Coulomb and viscous friction, rotor inertia and a torque offset on each "
               "joint; also a hybrid's prior, "
               "`loop+RESIDUAL` (`loop+gp`)")

    Config = LoopConfig
    configurations = {"feasible": Named("the loop from select's feasible model: the feasible rigid body with Coulomb "
                                        "and viscous friction, rotor inertia and a torque offset on each joint",
                                        {"friction": True})}
    experiments: ClassVar[tuple[str, ...]] = (INDIRECT,)
    not_applicable: ClassVar[str] = "the residual loop traces torques: the direct experiment has none"
    smoke = {"max_steps": 1, "eval_samples": 128}
    work = MAX_ROUNDS  # a step is a round

    @classmethod
    def not_applicable_reason(cls, experiment: str, system=None) -> str | None:
        reason = super().not_applicable_reason(experiment, system)
        if reason:
            return reason
        if system is not None and system.linear_form() is None:
            return prior_unavailable("loop", system)
        return None

    @classmethod
    def refused_on(cls, system) -> str | None:
        return None if system.linear_form() is not None else f"loop: {prior_unavailable('loop', system)}"

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        result = run(train, self.seed, self.budget, friction=self.config.friction)
        self.model, self._rounds = result.models[1], rounds_run(result)
        if not self.config.friction and self.budget.steps is not None and self.budget.steps >= MAX_ROUNDS:
            keep_shared(PRIOR.name, train, self.system, self.seed, self.model)  # the prior's own rounds: shared
        progress.stop("solved")

    def _work_done(self, progress: Progress) -> int:
        return getattr(self, "_rounds", 0)

    def _get_state(self):
        return self.model

    def _set_state(self, state) -> None:
        self.model = state

    def predict_torque(self, data: Dataset) -> np.ndarray:
        return self.model.predict_torque(data)

    def takes_accelerations(self) -> bool:
        return self.model.takes_accelerations()

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.model.mass_and_bias(q, qd)

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return self.model.predict_lagrangian(data)

    def saved(self, packer) -> dict:
        return self.model.saved(packer)

    def size(self) -> dict:
        model = getattr(self, "model", None)
        inner = getattr(getattr(model, "model", None), "effects", None)
        return {} if inner is None else {"laws": len(inner)}

