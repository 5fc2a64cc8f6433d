"""A gated residual's nearest-state query on the forward dynamics' batch: each
state's torque is asked for at ``dof + 1`` accelerations in a row
(:func:`bench.physics.models.mass_and_bias`), and the gate looks each distinct
state up once (``ours``, through :class:`~bench.core.distance.NearestStates`'
two stages) rather than every row, or each distinct state in scipy's k-d tree
of all the states. 70,000 training states of a 7-joint arm along one smooth
trajectory, 300 query states off it (a rollout leaving the training states).
Run with ``make benchmark``; the table after it gives each time relative to
ours."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.data import Dataset
from scipy.spatial import cKDTree

from bench.core.distance import TrainingStates

pytestmark = pytest.mark.benchmark

DOF, N_TRAIN, N_QUERY = 7, 70000, 300


@pytest.fixture(scope="module")
def setup():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 700, N_TRAIN)[:, None]
    q = np.sin(t * rng.uniform(0.2, 1.0, DOF) + rng.uniform(0, 6, DOF))
    qd = np.cos(t * rng.uniform(0.2, 1.0, DOF))
    gate = TrainingStates(Dataset(q, qd, np.zeros_like(q), np.zeros_like(q)))
    states = rng.normal(size=(N_QUERY, 2 * DOF)) * 0.8
    rows = np.repeat(states, DOF + 1, axis=0)
    return gate, Dataset(rows[:, :DOF], rows[:, DOF:], np.zeros((len(rows), DOF)), np.zeros((len(rows), DOF)))


def test_gate_each_distinct_state_once_ours(benchmark, setup):
    gate, batch = setup
    benchmark.group = "gate-query"
    benchmark.pedantic(gate.distance, args=(batch,), rounds=3, iterations=1)


def test_gate_each_distinct_state_in_one_k_d_tree(benchmark, setup):
    gate, batch = setup
    benchmark.group = "gate-query"
    assert gate.index.coarse is not None  # ours is the two-stage search
    tree = cKDTree(gate.states)
    distinct = (np.hstack([batch.q, batch.qd]) / gate.scale)[:: DOF + 1]
    benchmark.pedantic(lambda: tree.query(distinct), rounds=3, iterations=1)


def test_gate_every_row(benchmark, setup):
    gate, batch = setup
    benchmark.group = "gate-query"
    tree = cKDTree(gate.states)
    scaled = np.hstack([batch.q, batch.qd]) / gate.scale
    benchmark.pedantic(lambda: tree.query(scaled), rounds=3, iterations=1)
