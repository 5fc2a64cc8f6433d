"""Multigene GP: planted recovery, least-squares weights, no global state."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import sympy
from deap import creator, gp

from bench.core.data import generate, mse
from bench.evaluation.recovery import judge
from methods import METHODS
from methods.jets import JetAlgebra
from methods.mggp import Individual
from systems import System
from bench.core.budget import Budget


@dataclass(frozen=True)
class PendulumParams:
    m: float = 1.3
    l: float = 0.8
    g: float = 9.81


class Pendulum(System):
    """A point-mass pendulum, defined here and not registered."""

    name = "test_pendulum"
    coordinates = ("theta",)
    Params = PendulumParams
    sysid_unknowns = ("m", "l")

    def lagrangian_expr(self, q, qd, p):
        return p.m * p.l**2 * qd[0] ** 2 / 2 + p.m * p.g * p.l * sympy.cos(q[0])


@pytest.fixture(scope="module")
def pendulum_data():
    s = Pendulum()
    return s, generate(s, 2000, 0), generate(s, 500, 1)


def _smallish(**kw):
    return METHODS["mggp"](population=200, tournament=7, fitness_samples=256, eval_samples=256, **kw)


@pytest.mark.parametrize("experiment", ["direct", "indirect"])
def test_finds_a_planted_pendulum(pendulum_data, experiment):
    system, train, test = pendulum_data
    m = _smallish(max_steps=40).fit(train, experiment, seed=1, budget=Budget(seconds=120))
    assert mse(m.predict(test), test.target(experiment)) < 1e-12
    assert judge(m.expression(), system.lagrangian_sympy, 1, experiment).exact


def test_indirect_weights_are_the_least_squares_solution(pendulum_data):
    system, train, _ = pendulum_data
    m = _smallish(max_steps=1)
    m.experiment, m.dof = "indirect", 1
    m.pset = m._primitive_set(1)
    genes = [gp.PrimitiveTree.from_string(s, m.pset) for s in ("square(qd_1)", "cos(q_1)", "mul(q_1, qd_1)")]
    ind = Individual(genes)
    algebra = JetAlgebra(train.q, train.qd, train.qdd)
    m._score(ind, algebra, train.tau.ravel(), None)
    p = system.params
    # qd^2 and cos q carry the physics; q qd = d/dt(q^2/2) has no torque and gets weight 0
    np.testing.assert_allclose(ind.coef, [p.m * p.l**2 / 2, p.m * p.g * p.l, 0.0], rtol=1e-10, atol=1e-12)
    assert ind.mse < 1e-20


def test_same_seed_same_result_and_no_creator_types(pendulum_data):
    _, train, test = pendulum_data
    before = set(vars(creator))
    a = _smallish(max_steps=3).fit(train, "indirect", seed=5, budget=Budget(seconds=60))
    b = _smallish(max_steps=3).fit(train, "indirect", seed=5, budget=Budget(seconds=60))
    assert str(a.expression()) == str(b.expression())
    assert set(vars(creator)) == before  # no types created in DEAP's global creator
