"""The distance to the nearest training state: the same distances whether a state
comes once or repeated in consecutive rows, and each distinct state looked up once
(a rollout asks for each state's torque at dof + 1 accelerations in a row); a long
log's two-stage search gives scipy's k-d tree's distances."""

from __future__ import annotations

from unittest import mock

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial import cKDTree

from bench.core.data import Dataset
from bench.core import distance
from bench.core.distance import NearestStates, TrainingStates
from bench.physics.models import FittedModel, mass_and_bias


def _data(states: np.ndarray, dof: int) -> Dataset:
    n = len(states)
    return Dataset(states[:, :dof], states[:, dof:], np.zeros((n, dof)), np.zeros((n, dof)))


class _Counting:
    """A nearest-state index that counts the points it is asked for."""

    def __init__(self, index):
        self.index, self.asked = index, 0

    def query(self, x):
        self.asked += len(x)
        return self.index.query(x)


@given(st.lists(st.integers(1, 4), min_size=1, max_size=12), st.integers(0, 2**16))
def test_repeated_states_give_each_rows_distance_and_are_looked_up_once(runs, seed):
    rng = np.random.default_rng(seed)
    dof = 3
    gate = TrainingStates(_data(rng.normal(size=(200, 2 * dof)), dof))
    distinct = rng.normal(size=(len(runs), 2 * dof)) * 2
    rows = np.repeat(distinct, runs, axis=0)
    plain, _ = cKDTree(gate.states).query(rows / gate.scale)
    gate.index = _Counting(gate.index)
    got = gate.distance(_data(rows, dof))
    np.testing.assert_array_equal(got, plain)
    distinct_runs = 1 + int(np.sum(np.any(distinct[1:] != distinct[:-1], axis=1)))
    assert gate.index.asked == distinct_runs


def test_the_forward_dynamics_batch_of_a_gated_model_looks_each_state_up_once():
    rng = np.random.default_rng(0)
    dof, n = 7, 5
    gate = TrainingStates(_data(rng.normal(size=(500, 2 * dof)), dof))
    gate.index = _Counting(gate.index)

    class Gated(FittedModel):  # a model whose torque is the gate's distance on each joint, as a gated residual's weight is
        def predict_lagrangian(self, data):
            return np.zeros(len(data))

        def predict_torque(self, data):
            return np.repeat(gate.distance(data)[:, None], dof, axis=1)

    states = rng.normal(size=(n, 2 * dof))
    M, c = mass_and_bias(Gated(), states[:, :dof], states[:, dof:])
    assert gate.index.asked == n  # not n * (dof + 1)
    assert M.shape == (n, dof, dof) and np.allclose(M, 0.0)  # the distance does not depend on the acceleration


def _motion(rng: np.random.Generator, n: int, dof: int, recordings: int) -> np.ndarray:
    """States along ``recordings`` smooth curves (sums of sines), as logs of an arm's motion hold them."""
    out = []
    for _ in range(recordings):
        t = np.linspace(0, rng.uniform(2, 8), n // recordings)[:, None]
        out.append(np.hstack([np.sin(t * rng.uniform(0.2, 2.0, dof) + rng.uniform(0, 6, dof)) for _ in range(2)]))
    return np.vstack(out)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**16), st.integers(1, 4), st.floats(0.0, 3.0), st.integers(20, 600))
def test_the_two_stage_search_gives_the_k_d_trees_distances(seed, recordings, spread, kept):
    rng = np.random.default_rng(seed)
    states = _motion(rng, 3000, 3, recordings)
    states[rng.integers(0, len(states), 50)] = states[rng.integers(0, len(states), 50)]  # repeated states
    with mock.patch.multiple(distance, THINNED_ABOVE=1000, KEPT=kept, REACH_MAX=np.inf):  # exact at any reach
        index = NearestStates(states)
    assert index.coarse is not None and index.coarse.n < len(states)
    asked = np.vstack([states[rng.integers(0, len(states), 100)] + rng.normal(size=(100, 6)) * spread,
                       states[:5]])  # some on the training states themselves
    np.testing.assert_allclose(index.query(asked), cKDTree(states).query(asked)[0], rtol=1e-12, atol=1e-12)


def test_states_that_are_not_smooth_motion_use_the_plain_tree(monkeypatch):
    monkeypatch.setattr(distance, "THINNED_ABOVE", 1000)
    monkeypatch.setattr(distance, "KEPT", 300)
    rng = np.random.default_rng(1)
    scattered = NearestStates(rng.normal(size=(3000, 6)))
    assert scattered.coarse is None
    asked = rng.normal(size=(50, 6))
    np.testing.assert_array_equal(scattered.query(asked), cKDTree(scattered.states).query(asked)[0])
    assert NearestStates(_motion(rng, 3000, 3, 2)).coarse is not None


def test_an_index_and_its_answers_are_built_once_a_process_for_the_same_states(monkeypatch):
    """A tuned hybrid's fold fits share their fold's states: the same training states give the same index, and
    the same query its answer again, measured once; other states, or a query changed in one number, do not."""
    rng = np.random.default_rng(3)
    train, asked = rng.normal(size=(400, 4)), rng.normal(size=(60, 4)) * 3
    measured = []
    real = NearestStates._measure
    monkeypatch.setattr(NearestStates, "_measure", lambda self, x: measured.append(len(x)) or real(self, x))
    first, again = TrainingStates(_data(train, 2)), TrainingStates(_data(train.copy(), 2))
    assert again.index is first.index
    d1, d2 = first.distance(_data(asked, 2)), again.distance(_data(asked.copy(), 2))
    np.testing.assert_array_equal(d1, cKDTree(first.states).query(asked / first.scale)[0])
    np.testing.assert_array_equal(d1, d2)
    assert measured == [60]
    moved = asked.copy()
    moved[7, 1] += 1e-9
    first.distance(_data(moved, 2))
    assert measured == [60, 60]
    other = train.copy()
    other[0, 0] += 1.0
    assert TrainingStates(_data(other, 2)).index is not first.index
    for k in range(distance.KEPT_INDEXES + 1):  # at most KEPT_INDEXES are kept
        NearestStates.of(rng.normal(size=(50, 4)) + k)
    assert len(NearestStates._built) == distance.KEPT_INDEXES
    assert NearestStates.of(first.states) is not first.index  # pushed out, built again
