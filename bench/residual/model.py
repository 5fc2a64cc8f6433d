"""The residual loop's models: a fitted Lagrangian plus the effects accepted so far.

* :class:`LoopModel`: ``tau_hat = g(L_hat) + Phi c``, the rigid model and
  the effects' terms with their coefficients;
* :class:`CrossFitted`: a kept fit with the torque of its cross-fits;
* :class:`Fitter`: how the loop fits its method;
* :func:`rigid_torque`: a rigid model's torque on a data set, remembered.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from bench.core.budget import Budget
from bench.core.data import Dataset
from bench.core.modelfile import Packer, Unpacker, build, loader
from bench.physics.linear import TermModel
from bench.physics.models import FittedModel, term_from_json, term_to_json
from bench.physics.terms import Term, TermLibrary
from methods import METHODS

#: the last rigid-model torques computed, ``(rigid, data, tau)`` (see :func:`rigid_torque`)
_TORQUES: list[tuple] = []


def rigid_torque(rigid: FittedModel, data: Dataset) -> np.ndarray:
    """``rigid.predict_torque(data)`` as float64, remembered for the last few
    ``(rigid, data)`` pairs: the loop asks for a model's torque on the
    training data in every refit and pruning step, and a neural model's costs
    a pass of automatic differentiation. Pairs are matched by identity."""
    for r, d, tau in _TORQUES:
        if r is rigid and d is data:
            return tau
    tau = np.asarray(rigid.predict_torque(data), dtype=np.float64)
    _TORQUES.insert(0, (rigid, data, tau))
    del _TORQUES[4:]
    return tau


class CrossFitted(FittedModel):
    """A kept fit with the cross-fits' torque on the training data
    (:func:`bench.residual.strategies.cross_fit`): ``torque[halves[k]]`` is
    predicted by the method fitted without ``halves[k]``. It predicts as the
    fit on all of it."""

    def __init__(self, fit: FittedModel, halves: list[np.ndarray], torque: np.ndarray):
        self.fit, self.halves, self.torque = fit, halves, torque

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return self.fit.predict_lagrangian(data)

    def predict_torque(self, data: Dataset) -> np.ndarray:
        return self.fit.predict_torque(data)

    def takes_accelerations(self) -> bool:
        return self.fit.takes_accelerations()

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.fit.mass_and_bias(q, qd)

    def expression(self):
        return self.fit.expression()

    def expression_terms_bound(self) -> int | None:
        return self.fit.expression_terms_bound()

    def readable_expression(self):
        return self.fit.readable_expression()

    def saved(self, packer: Packer) -> dict:
        """The fit on all the training data (what it predicts with)."""
        return self.fit.saved(packer)


class LoopModel(FittedModel):
    """``tau_hat = g(L_hat) + Phi c``: a fitted Lagrangian plus accepted effects."""

    def __init__(self, rigid: FittedModel, effects: list[Term], coef, stderr):
        self.rigid, self.effects = rigid, list(effects)
        self.coef, self.stderr = np.asarray(coef, dtype=np.float64), np.asarray(stderr, dtype=np.float64)

    @classmethod
    def bare(cls, rigid: FittedModel) -> "LoopModel":
        """``rigid`` with no effects."""
        return cls(rigid, [], np.zeros(0), np.zeros(0))

    def columns(self, data: Dataset) -> np.ndarray:
        return TermLibrary(self.effects).design(data, "indirect")

    def predict_torque(self, data: Dataset) -> np.ndarray:
        tau = rigid_torque(self.rigid, data)
        if self.effects:
            tau = tau + (self.columns(data) @ self.coef).reshape(tau.shape)
        return tau

    def takes_accelerations(self) -> bool:
        return self.rigid.takes_accelerations() or self._effects.takes_accelerations()

    def mass_and_bias(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rigid model's ``M`` and ``c`` plus the effects'
        (:class:`~bench.physics.linear.TermModel`): each is asked for its own,
        the rigid model's from its engine where it has one (a driven rollout
        asks this at each of its steps)."""
        M, c = self.rigid.mass_and_bias(q, qd)
        M_e, c_e = self._effects.mass_and_bias(q, qd)
        return M + M_e, c + c_e

    @functools.cached_property
    def _effects(self) -> TermModel:
        return TermModel(self.effects, self.coef)

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        """The rigid model's ``L`` plus the conservative effects' terms."""
        L = np.asarray(self.rigid.predict_lagrangian(data), dtype=np.float64)
        return L + self._effects.predict_lagrangian(data)

    def expression(self):
        return self.rigid.expression()

    def saved(self, packer: Packer) -> dict:
        """The rigid model as saved, and each effect's term, coefficient and standard error."""
        return {"kind": "loop", "rigid": self.rigid.saved(packer), "effects": [term_to_json(t) for t in self.effects],
                "coef": packer.array(self.coef), "stderr": packer.array(self.stderr)}


@loader("loop")
def _load(tree: dict, unpacker: Unpacker, context: dict) -> LoopModel:
    effects = [term_from_json(t, unpacker.source) for t in tree["effects"]]
    coef, stderr = unpacker.array(tree["coef"]), unpacker.array(tree["stderr"])
    if not len(effects) == len(coef) == len(stderr):
        raise ValueError(f"{len(effects)} effects with {len(coef)} coefficients")
    return LoopModel(build(tree["rigid"], unpacker, context), effects, coef, stderr)


@dataclass(frozen=True)
class Fitter:
    """How the loop fits its method: by name, seed, budget and hyperparameters."""

    method: str
    seed: int
    budget: Budget
    hyperparameters: dict
    device: str = "cpu"

    def fit(self, train: Dataset) -> FittedModel:
        method = METHODS[self.method](**self.hyperparameters)
        if self.device != "cpu":  # a method trains on the CPU unless told otherwise
            method.use_device(self.device)
        return method.fit(train, "indirect", self.seed, self.budget)
