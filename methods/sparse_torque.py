"""Sparse regression of the torque, joint by joint, on terms a reader can name.

A symbolic residual for a hybrid (``standard+sparse_torque``,
:mod:`methods.hybrid`): joint ``j``'s torque is a sparse sum of

its own terms: ``1`` (an offset), ``sign(qd_j)`` (a Coulomb level; the sign
as the torque's filter saw it), ``qd_j`` (viscous), ``qd_j |qd_j|`` (quadratic
drag), ``q_j``, ``sin q_j``, ``cos q_j`` (a spring, a gravity or cogging
term). Other joints' terms are left out: on one training trajectory their
columns are near copies of each other, and their fitted sum did not carry to
another trajectory (a library with every joint's ``sin q_i`` and ``cos q_i``
gave the KUKA LWR4+'s default split 351 times the standard model's test MSE),

fitted by sequentially thresholded least squares with the sparsity chosen on
held-out samples (:func:`bench.physics.regression.fit_columns`, on the validation
protocol's folds, :mod:`bench.core.folds`), one solve a
joint: the method's one step. Its result is one equation a joint, in those
names (``record_details``). Its torque takes no accelerations: beside a prior
the hybrid's mass matrix is the prior's. It has no Lagrangian: offsets and
friction are generalized forces.

**A joint's position terms hold past its training range.** Past the lowest
or highest ``q_j`` the fit saw, the terms in ``q_j`` (a spring, a gravity or
cogging term) take their value at that end of the range; the terms in
``qd_j`` (the friction laws) go on. A sum such as ``-18 q + 19 sin q`` fits a
cogging torque over the range it saw and is, past it, a cubic that grows
without bound; the friction laws are laws of the velocity and hold past it.
Each joint's range is kept in the model file (``q_range``); a file without
one predicts as it was fitted, unheld.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np

from bench.core.experiment import INDIRECT
from bench.physics import regression
from bench.core.folds import folds
from bench.core.data import Dataset
from bench.core.modelfile import loader
from methods.base import METHODS, Method, restored, saved_hyperparameters
from methods.config import MethodConfig, Range
from methods.progress import Progress


@dataclass(frozen=True)
class SparseTorqueConfig(MethodConfig):
    """Attributes: the sparsity ``threshold`` (``None``: chosen on held-out samples)."""

    threshold: Annotated[float, Range(0)] | None = None


def terms(data: Dataset, j: int) -> tuple[list[str], np.ndarray]:
    """Joint ``j``'s library of terms (0-based ``j``): their names and columns ``(n, k)``."""
    n, k = len(data), j + 1
    q, qd, sign = data.q[:, j], data.qd[:, j], data.velocity_sign()[:, j]
    names = ["1", f"sign(qd_{k})", f"qd_{k}", f"qd_{k}*|qd_{k}|", f"q_{k}", f"sin(q_{k})", f"cos(q_{k})"]
    cols = [np.ones(n), sign, qd, qd * np.abs(qd), q, np.sin(q), np.cos(q)]
    return names, np.stack(cols, axis=1)


@METHODS.add("sparse_torque", "regression", "residual")
class SparseTorque(Method):
    """Sparse regression of each joint's torque (see the module docstring)."""

    title = "sparse torque terms"
    #: what the method is, for docs/methods_and_systems.md (generated from the registry)
    summary = ("a sparse regression of each joint's torque on terms a reader can name (an offset, a Coulomb "
               "level, viscous friction, quadratic drag, a spring, gravity or cogging terms of that joint); a "
               "symbolic residual of the hybrids (`feasible+sparse_torque`)")

    Config = SparseTorqueConfig
    experiments: ClassVar[tuple[str, ...]] = (INDIRECT,)
    not_applicable: ClassVar[str] = "a sparse regression of the torque learns torques: the direct experiment has none"
    smoke = {"max_steps": 1, "eval_samples": 128}
    work = 1  # one solve
    has_lagrangian: ClassVar[bool] = False

    #: each joint's training range of ``q``, shape ``(2, dof)`` (lowest, highest); ``None``: unheld
    q_range: np.ndarray | None = None

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        self.coef = [np.zeros(len(terms_names(train.dof, j))) for j in range(train.dof)]
        self.q_range = np.stack([train.q.min(axis=0), train.q.max(axis=0)])
        held = folds(train).indices() if train.trajectories() else None
        while progress.step():
            for j in range(train.dof):
                _, F = terms(train, j)
                self.coef[j] = regression.fit_columns(F, train.tau[:, j], len(train), self.config.threshold,
                                                      deadline=progress.deadline, folds=held)
            progress.stop("solved")

    def _get_state(self):
        return [c.copy() for c in self.coef]

    def _set_state(self, state) -> None:
        self.coef = [c.copy() for c in state]

    def held(self, data: Dataset) -> Dataset:
        """``data`` with each joint's position held in its training range (the module docstring)."""
        if self.q_range is None:
            return data
        return data.replace(q=np.clip(data.q, self.q_range[0], self.q_range[1]))

    def predict_torque(self, data: Dataset) -> np.ndarray:
        data = self.held(data)
        out = np.zeros((len(data), data.dof))
        for j, c in enumerate(self.coef):
            out[:, j] = terms(data, j)[1] @ c
        return out

    def takes_accelerations(self) -> bool:
        return False

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        """A regression of the torque has no Lagrangian: ``nan``."""
        return np.full(len(data), math.nan)

    def saved(self, packer) -> dict:
        """Each joint's coefficients, with the hyperparameters."""
        return {"kind": "sparse_torque", "method": self.name, "hyperparameters": saved_hyperparameters(self),
                "coef": [packer.array(c) for c in self.coef],
                **({} if self.q_range is None else {"q_range": packer.array(self.q_range)})}

    def equations(self) -> list[str]:
        """Each joint's torque as the sum of its kept terms."""
        out = []
        for j, c in enumerate(self.coef):
            names = terms_names(self.dof, j)
            kept = [f"{v:+.4g}*{n}" if n != "1" else f"{v:+.4g}" for v, n in zip(c, names) if v != 0.0]
            out.append(f"tau_{j + 1} = " + (" ".join(kept) if kept else "0"))
        return out

    def size(self) -> dict:
        coef = getattr(self, "coef", None)
        return {} if coef is None else {"terms": int(sum(np.count_nonzero(c) for c in coef))}

    def record_details(self) -> dict:
        coef = getattr(self, "coef", None)
        if coef is None or self.dof is None:
            return {}
        return {"terms": int(sum(np.count_nonzero(c) for c in coef)), "equations": self.equations()}


@loader("sparse_torque")
def _load(tree: dict, unpacker, context: dict) -> SparseTorque:
    method = restored(tree, context)
    method.coef = [np.array(unpacker.array(c), dtype=np.float64) for c in tree["coef"]]
    if len(method.coef) != method.dof:
        raise ValueError(f"{len(method.coef)} joints' coefficients for {method.dof} joints")
    if "q_range" in tree:
        q_range = np.array(unpacker.array(tree["q_range"]), dtype=np.float64)
        if q_range.shape != (2, method.dof) or np.any(q_range[0] > q_range[1]):
            raise ValueError(f"q_range is not each joint's lowest and highest position (2 x {method.dof}, "
                             "lowest first)")
        method.q_range = q_range
    return method


def terms_names(dof: int, j: int) -> list[str]:
    """The names of joint ``j``'s library of terms, for a system of ``dof`` joints."""
    zero = Dataset(np.zeros((1, dof)), np.zeros((1, dof)), np.zeros((1, dof)), np.zeros((1, dof)))
    return terms(zero, j)[0]
