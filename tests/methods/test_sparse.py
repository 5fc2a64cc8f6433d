"""Sparse Lagrangian regression: the library and exact recovery in seconds."""

from __future__ import annotations


import pytest
import sympy

from bench.core import symbolic
from bench.core.data import generate, mse
from bench.evaluation.recovery import judge
from methods import METHODS
from bench.physics.terms import lagrangian_library as library
from bench.core.budget import Budget


def test_library_is_built_from_the_coordinates():
    lib = library(2, ("angle", "angle")).expressions
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    assert len(lib) == 6 * 7
    for term in (qd1**2, qd1 * qd2 * sympy.cos(q1 - q2), sympy.cos(q1), qd2**2 * sympy.sin(q2)):
        assert term in lib
    mixed = library(2, ("linear", "angle")).expressions
    assert q1**2 in mixed and q1 * sympy.cos(q2) in mixed and sympy.cos(q1) not in mixed


@pytest.mark.parametrize("experiment", ["direct", "indirect"])
def test_recovers_the_double_pendulum_exactly(double_pendulum, experiment):
    train, test = generate(double_pendulum, 32000, 0), generate(double_pendulum, 2000, 1000)
    m = METHODS["sparse"]().fit(train, experiment, seed=0, budget=Budget(steps=1))  # solved in one step
    assert mse(m.predict(test), test.target(experiment)) < 1e-18
    assert judge(m.expression(), double_pendulum.lagrangian_sympy, 2, experiment).exact
    terms = [t for t in sympy.Add.make_args(m.expression()) if t.free_symbols]
    assert len(terms) == 5
