"""The constant model every run on measured data is read against: each joint's
training-mean torque, scored as a run is."""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset
from bench.evaluation.reference import constant_reference


def _data(tau: np.ndarray) -> Dataset:
    zeros = np.zeros_like(tau)
    return Dataset(zeros, zeros, zeros, tau, None, "kuka_lwr4", "made")


def test_the_constant_is_the_training_mean_torque_and_is_scored_on_both_parts():
    train = _data(np.array([[1.0, -2.0], [3.0, 0.0]]))
    test = _data(np.array([[2.0, 1.0], [0.0, -1.0]]))
    out = constant_reference(train, test)
    assert out["tau"] == [2.0, -1.0]
    assert out["train_mse"] == 1.0  # each sample 1 away on each joint
    assert out["test_mse"] == (0.0 + 4.0 + 4.0 + 0.0) / 4
    assert constant_reference(train, None)["test_mse"] is None
