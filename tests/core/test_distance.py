"""The distance to the nearest training state: the same distances whether a state
comes once or repeated in consecutive rows, and each distinct state looked up once
(a rollout asks for each state's torque at dof + 1 accelerations in a row)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, strategies as st

from bench.core.data import Dataset
from bench.core.distance import TrainingStates
from bench.physics.models import FittedModel, mass_and_bias


def _data(states: np.ndarray, dof: int) -> Dataset:
    n = len(states)
    return Dataset(states[:, :dof], states[:, dof:], np.zeros((n, dof)), np.zeros((n, dof)))


class _Counting:
    """A k-d tree that counts the points it is asked for."""

    def __init__(self, tree):
        self.tree, self.asked = tree, 0

    def query(self, x, *args, **kwargs):
        self.asked += len(x)
        return self.tree.query(x, *args, **kwargs)


@given(st.lists(st.integers(1, 4), min_size=1, max_size=12), st.integers(0, 2**16))
def test_repeated_states_give_each_rows_distance_and_are_looked_up_once(runs, seed):
    rng = np.random.default_rng(seed)
    dof = 3
    gate = TrainingStates(_data(rng.normal(size=(200, 2 * dof)), dof))
    distinct = rng.normal(size=(len(runs), 2 * dof)) * 2
    rows = np.repeat(distinct, runs, axis=0)
    plain, _ = gate.tree.query(rows / gate.scale)
    gate.tree = _Counting(gate.tree)
    got = gate.distance(_data(rows, dof))
    np.testing.assert_array_equal(got, plain)
    distinct_runs = 1 + int(np.sum(np.any(distinct[1:] != distinct[:-1], axis=1)))
    assert gate.tree.asked == distinct_runs


def test_the_forward_dynamics_batch_of_a_gated_model_looks_each_state_up_once():
    rng = np.random.default_rng(0)
    dof, n = 7, 5
    gate = TrainingStates(_data(rng.normal(size=(500, 2 * dof)), dof))
    gate.tree = _Counting(gate.tree)

    class Gated(FittedModel):  # a model whose torque is the gate's distance on each joint, as a gated residual's weight is
        def predict_lagrangian(self, data):
            return np.zeros(len(data))

        def predict_torque(self, data):
            return np.repeat(gate.distance(data)[:, None], dof, axis=1)

    states = rng.normal(size=(n, 2 * dof))
    M, c = mass_and_bias(Gated(), states[:, :dof], states[:, dof:])
    assert gate.tree.asked == n  # not n * (dof + 1)
    assert M.shape == (n, dof, dof) and np.allclose(M, 0.0)  # the distance does not depend on the acceleration
