"""The forward-mode jet evaluator against the suite's autograd transform."""

from __future__ import annotations

import numpy as np
import pytest
import sympy
import torch

from bench.core import symbolic
from bench.physics.dynamics import euler_lagrange
from methods.jets import JetAlgebra


def _states(n=200, dof=2, seed=0):
    g = np.random.default_rng(seed)
    return [g.uniform(-1.5, 1.5, (n, dof)) for _ in range(3)]


@pytest.mark.parametrize("case", ["pendulum", "coupled", "roots_and_powers", "constant"])
def test_jet_torques_equal_autograd(case):
    q, qd, qdd = _states()
    A = JetAlgebra(q, qd, qdd)
    q1, q2, v1, v2 = A.variables
    c = A.constant
    (Q1, Q2), (V1, V2) = symbolic.coordinate_symbols(2)
    if case == "pendulum":
        jet = A.add(A.mul(c(3.5), A.unary("square", v1)), A.mul(c(9.81), A.unary("cos", q1)))
        expr = 3.5 * V1**2 + 9.81 * sympy.cos(Q1)
    elif case == "coupled":
        jet = A.mul(A.mul(v1, v2), A.unary("cos", A.sub(q1, q2)))
        expr = V1 * V2 * sympy.cos(Q1 - Q2)
    elif case == "roots_and_powers":
        jet = A.add(A.unary("cube", A.mul(q2, v1)), A.unary("sqrt", A.add(A.unary("sin", q1), c(2.0))))
        expr = (Q2 * V1) ** 3 + sympy.sqrt(sympy.Abs(sympy.sin(Q1) + 2))
    else:
        jet = c(4.0)
        expr = sympy.Integer(4)
    f = symbolic.to_torch(expr, 2)
    expected = euler_lagrange(f, *(torch.from_numpy(a) for a in (q, qd, qdd))).numpy()
    np.testing.assert_allclose(A.torque(jet), expected, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(jet.v, f(torch.from_numpy(q), torch.from_numpy(qd)).numpy(), rtol=1e-13)


def test_values_only_mode_skips_derivatives():
    q, qd, qdd = _states()
    A = JetAlgebra(q, qd, qdd, order=0)
    jet = A.mul(A.variables[2], A.unary("sin", A.variables[0]))
    assert jet.G is None and jet.Hu is None
    np.testing.assert_allclose(jet.v, qd[:, 0] * np.sin(q[:, 0]))


def test_a_jets_torque_goes_through_the_one_transform_at_its_own_states_only():
    """The transform takes the jet's derivatives (its ``tangent``), which hold
    only at the algebra's states and along (qd, qdd): elsewhere it refuses."""
    from methods.jets import _JetLagrangian

    q, qd, qdd = _states()
    A = JetAlgebra(q, qd, qdd)
    jet = A.mul(A.variables[2], A.unary("sin", A.variables[0]))  # qd1 sin q1
    L = _JetLagrangian(A, jet)
    tau = euler_lagrange(L, *A.states).numpy()
    np.testing.assert_allclose(tau, A.torque(jet), rtol=0, atol=0)
    # d/dt (sin q1) - qd1 cos q1 = 0 for the first joint; nothing for the second
    np.testing.assert_allclose(tau, 0.0, atol=1e-12)
    np.testing.assert_array_equal(L(*A.states[:2]).numpy(), jet.v)  # its value, as a Lagrangian
    other = [torch.from_numpy(a.copy()) for a in (q, qd, qdd)]
    with pytest.raises(ValueError, match="algebra's states"):
        euler_lagrange(L, *other)
    with pytest.raises(ValueError, match="algebra's states"):
        L(*other[:2])
