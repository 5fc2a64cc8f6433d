"""The checks that keep or undo a round of the loop: its model's error on
held-out trajectories, and whether its mass matrix is positive definite."""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset
from bench.physics.models import FittedModel, mass_and_bias
from bench.residual.model import LoopModel
from bench.residual.strategies import Strategy
from bench.residual.validation import FoldFits, cv_mse, row_folds

#: training states the mass matrix is checked at
MASS_STATES = 256


def heldout(strategy: Strategy, model: LoopModel, train: Dataset, scale: np.ndarray | None = None) -> float:
    """The model's torque MSE on held-out data: the linear problem that
    tracing and pruning fit (:meth:`~bench.residual.strategies.Strategy.problem`),
    cross-validated over whole trajectories (:func:`bench.residual.validation.cv_mse`).
    ``scale`` (one factor a joint, or one a sample and joint: a torque sensor's
    gains and a drive's load-dependent friction, :meth:`bench.residual.sensors.Sensor.factor`)
    turns the corrected torques ``train`` holds back into measured ones, so that
    models read through different laws are compared in the same units."""
    return cv_mse(*_problem(strategy, model, train, scale), row_folds(train))


def heldout_by_joint(strategy: Strategy, model: LoopModel, train: Dataset, scale: np.ndarray | None = None) -> np.ndarray:
    """Each joint's torque MSE on held-out data, as :func:`heldout` pools it."""
    r = FoldFits(*_problem(strategy, model, train, scale), row_folds(train)).residuals()
    return np.nanmean(r.reshape(-1, train.dof) ** 2, axis=0)


def _problem(strategy: Strategy, model: LoopModel, train: Dataset, scale: np.ndarray | None):
    """The columns and the target, over rows, that :func:`heldout` validates, in measured units."""
    target, F = strategy.problem(model, train)
    y = target.ravel()
    if scale is not None:
        rows = np.broadcast_to(np.asarray(scale, dtype=np.float64), train.tau.shape).ravel()
        y, F = y * rows, F * rows[:, None]
    return F, y


def smallest_mass_eigenvalue(model: FittedModel, train: Dataset) -> float:
    """The smallest eigenvalue of the model's mass matrix ``d^2 L / dqd^2``
    (with its effects) over up to :data:`MASS_STATES` training states, evenly spread."""
    states = train.subset(train.evenly(MASS_STATES))
    M, _ = mass_and_bias(model, states.q, states.qd)
    return float(np.linalg.eigvalsh(0.5 * (M + np.transpose(M, (0, 2, 1))))[:, 0].min())
