"""The Euler–Lagrange transform against closed forms that sympy derives."""

from __future__ import annotations

import numpy as np
import pytest
import sympy
import torch

from bench.core import symbolic
from bench.physics.dynamics import euler_lagrange, euler_lagrange_chunked


def sympy_torques(expr: sympy.Expr, dof: int):
    """Closed-form tau(q, qd, qdd) = d/dt dL/dqd - dL/dq by sympy, compiled with numpy."""
    from bench.evaluation.recovery import euler_lagrange_symbolic

    q, qd = symbolic.coordinate_symbols(dof)
    qdd = symbolic.acceleration_symbols(dof)
    taus = [sympy.simplify(t) for t in euler_lagrange_symbolic(expr, dof)]
    f = sympy.lambdify([*q, *qd, *qdd], taus, modules="numpy")
    return lambda Q, QD, QDD: np.stack(np.broadcast_arrays(*f(*Q.T, *QD.T, *QDD.T)), axis=1)


def _magnetic_lagrangian():
    """A charged particle in a non-uniform magnetic field with an anharmonic
    potential: velocity-position coupling makes d2L/dqd dq non-symmetric."""
    (x, y), (xd, yd) = symbolic.coordinate_symbols(2)
    B = 1.3 + sympy.sin(x) * y
    return (
        sympy.Rational(1, 2) * 2.5 * (xd**2 + yd**2)
        + B / 2 * (x * yd - y * xd)
        - sympy.cos(x) * y**2
        - 0.3 * x**4
    )


def _spring_pendulum():
    (r, th), (rd, thd) = symbolic.coordinate_symbols(2)
    m, g, k, l0 = 1.5, 9.81, 40.0, 1.2
    return m / 2 * (rd**2 + r**2 * thd**2) + m * g * r * sympy.cos(th) - k / 2 * (r - l0) ** 2


def _triple_chain():
    """Three coupled rotors with position-dependent inertia."""
    q, qd = symbolic.coordinate_symbols(3)
    return (
        (2 + sympy.cos(q[1])) * qd[0] ** 2
        + qd[1] ** 2 * (1 + q[2] ** 2) / 2
        + qd[0] * qd[2] * sympy.sin(q[0] - q[2])
        + 0.7 * qd[2] ** 2
        + 3 * sympy.cos(q[0]) + sympy.cos(q[1] + q[2])
    )


def _random_states(n, dof, seed, dtype=torch.float64):
    g = torch.Generator().manual_seed(seed)
    return [torch.rand(n, dof, generator=g, dtype=dtype) * 3 - 1.5 for _ in range(3)]


@pytest.mark.parametrize("name", ["double_pendulum", "magnetic", "spring_pendulum", "triple_chain"])
def test_matches_sympy_closed_form_float64(name, double_pendulum):
    if name == "double_pendulum":
        expr, dof = double_pendulum.lagrangian_sympy, 2
    else:
        expr = {"magnetic": _magnetic_lagrangian, "spring_pendulum": _spring_pendulum, "triple_chain": _triple_chain}[name]()
        dof = 3 if name == "triple_chain" else 2
    lag = symbolic.to_torch(expr, dof)
    q, qd, qdd = _random_states(1000, dof, seed=1)
    tau = euler_lagrange(lag, q, qd, qdd).numpy()
    expected = sympy_torques(expr, dof)(q.numpy(), qd.numpy(), qdd.numpy())
    assert tau.shape == (1000, dof)
    np.testing.assert_allclose(tau, expected, rtol=0, atol=1e-10)


def test_float32_is_supported_and_close(double_pendulum):
    q, qd, qdd = _random_states(256, 2, seed=2, dtype=torch.float32)
    tau32 = euler_lagrange(double_pendulum.lagrangian, q, qd, qdd)
    assert tau32.dtype == torch.float32
    tau64 = euler_lagrange(double_pendulum.lagrangian, q.double(), qd.double(), qdd.double())
    scale = tau64.abs().max().item()
    assert (tau32.double() - tau64).abs().max().item() < 1e-5 * scale


def test_create_graph_gives_parameter_gradients_that_match_finite_differences():
    # L = a * qd^2 / 2 + b * cos(q) * qd^2 + c * cos(q); loss on tau depends on a, b, c
    theta = torch.tensor([1.3, 0.4, -2.0], dtype=torch.float64, requires_grad=True)

    def lag(q, qd, th=None):
        th = theta if th is None else th
        return th[0] * qd[:, 0] ** 2 / 2 + th[1] * torch.cos(q[:, 0]) * qd[:, 0] ** 2 + th[2] * torch.cos(q[:, 0])

    q, qd, qdd = _random_states(64, 1, seed=3)
    target = torch.randn(64, 1, dtype=torch.float64, generator=torch.Generator().manual_seed(0))

    def loss_of(th):
        tau = euler_lagrange(lambda a, b: lag(a, b, th), q, qd, qdd, create_graph=True)
        return ((tau - target) ** 2).mean()

    assert torch.autograd.gradcheck(loss_of, (theta,))
    loss_of(theta).backward()
    assert theta.grad is not None and theta.grad.abs().sum() > 0


def test_without_create_graph_the_result_is_detached(double_pendulum):
    q, qd, qdd = _random_states(8, 2, seed=4)
    assert not euler_lagrange(double_pendulum.lagrangian, q, qd, qdd).requires_grad


def test_lagrangian_independent_of_q_gives_inertial_torque_only():
    q, qd, qdd = _random_states(16, 2, seed=5)
    tau = euler_lagrange(lambda a, b: 0.5 * 3.0 * (b**2).sum(-1), q, qd, qdd)
    torch.testing.assert_close(tau, 3.0 * qdd)


def test_constant_lagrangian_gives_zero_torque():
    q, qd, qdd = _random_states(4, 2, seed=6)
    tau = euler_lagrange(lambda a, b: torch.zeros(a.shape[0], dtype=a.dtype), q, qd, qdd)
    assert torch.equal(tau, torch.zeros_like(q))


def test_chunked_equals_unchunked(double_pendulum):
    q, qd, qdd = _random_states(1000, 2, seed=7)
    tau, L = euler_lagrange(double_pendulum.lagrangian, q, qd, qdd, return_lagrangian=True)
    tau_c, L_c = euler_lagrange_chunked(double_pendulum.lagrangian, q, qd, qdd, chunk=300)
    torch.testing.assert_close(tau_c, tau, rtol=0, atol=0)
    torch.testing.assert_close(L_c, L, rtol=0, atol=0)


def test_shape_errors_are_clear(double_pendulum):
    q, qd, qdd = _random_states(4, 2, seed=8)
    with pytest.raises(ValueError, match="share one"):
        euler_lagrange(double_pendulum.lagrangian, q, qd[:3], qdd)
    with pytest.raises(ValueError, match="returned shape"):
        euler_lagrange(lambda a, b: (a * b).sum(), q, qd, qdd)


def test_numeric_function_calls_and_powers_compile():
    (q1, _), (qd1, _) = symbolic.coordinate_symbols(2)
    f = symbolic.to_torch(qd1**2 * sympy.sin(sympy.Rational(1, 2)) + sympy.cos(2) * q1 + sympy.sqrt(2) * sympy.sqrt(sympy.Abs(q1)), 2)
    x = torch.ones(3, 2, dtype=torch.float64)
    torch.testing.assert_close(f(x, x), torch.full((3,), np.sin(0.5) + np.cos(2.0) + np.sqrt(2), dtype=torch.float64))


class _OwnDerivatives:
    """``L = 1/2 qd^T M qd + k . cos q`` with its derivatives written out:
    dL/dq = -k sin q, dL/dqd = M qd, and dL/dqd along (dq, dqd) is M dqd."""

    M = torch.tensor([[2.0, 0.5], [0.5, 1.0]], dtype=torch.float64)
    k = torch.tensor([3.0, 1.5], dtype=torch.float64)

    def __init__(self):
        self.calls = 0

    def __call__(self, q, qd):
        return 0.5 * ((qd @ self.M) * qd).sum(-1) + (self.k * torch.cos(q)).sum(-1)

    def tangent(self, q, qd, dq, dqd):
        self.calls += 1
        return self(q, qd), -self.k * torch.sin(q), qd @ self.M, dqd @ self.M


def test_a_lagrangian_that_gives_its_own_derivatives_gets_the_same_torques():
    q, qd, qdd = _random_states(32, 2, seed=7)
    own = _OwnDerivatives()
    tau, L = euler_lagrange(own, q, qd, qdd, return_lagrangian=True)
    assert own.calls == 1  # the transform took the derivatives from the Lagrangian
    torch.testing.assert_close(tau, qdd @ own.M + own.k * torch.sin(q))
    torch.testing.assert_close(tau, euler_lagrange(own.__call__, q, qd, qdd))  # the reverse passes
    torch.testing.assert_close(L, own(q, qd))
    assert not tau.requires_grad


def test_a_lagrangian_whose_own_derivatives_have_the_wrong_shape_is_refused():
    q, qd, qdd = _random_states(4, 2, seed=8)
    own = _OwnDerivatives()
    own.tangent = lambda q, qd, dq, dqd: (torch.zeros(4, 1), q, qd, dqd)
    with pytest.raises(ValueError, match="expected \\(4,\\)"):
        euler_lagrange(own, q, qd, qdd)
