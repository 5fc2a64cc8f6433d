"""Systems: domains, the non-conservative hook, the n-link pendulum, the parameters."""

from __future__ import annotations

import numpy as np
import pytest
import sympy
import torch

from bench.core import symbolic
from bench.core.data import generate
from systems import SYSTEMS, Domain

def test_domain_is_configurable_and_checked():
    import math

    wide = SYSTEMS["double_pendulum"](domain=Domain.symmetric(math.pi))
    data = generate(wide, 2000, 0, cache=False)
    assert np.abs(data.q).max() > math.pi / 2
    with pytest.raises(ValueError, match="low < high"):
        Domain(q=(1.0, -1.0))


def test_nonconservative_hook_adds_to_the_torque():
    from systems.double_pendulum import DoublePendulum

    class Damped(DoublePendulum):
        def nonconservative_torque(self, q, qd, qdd):
            return 0.5 * qd

    plain = generate(DoublePendulum(), 50, 3, cache=False)
    damped = generate(Damped(), 50, 3, cache=False)
    np.testing.assert_allclose(damped.tau - plain.tau, 0.5 * plain.qd, atol=1e-12)


def test_double_pendulum_is_the_papers():
    from systems.double_pendulum import DoublePendulumParams

    p = DoublePendulumParams()
    assert (p.m1, p.l1, p.m2, p.l2, p.g) == (3.0, 2.67, 1.0, 1.67, 9.81)
    dp = SYSTEMS["double_pendulum"]()
    (q1, q2), (qd1, qd2) = dp.symbols
    m1, l1, m2, l2, g = 3.0, 2.67, 1.0, 1.67, 9.81
    paper = (
        sympy.Rational(1, 2) * (m1 / 3 + m2) * l1**2 * qd1**2
        + sympy.Rational(1, 2) * (m2 / 3) * l2**2 * qd2**2
        + sympy.Rational(1, 2) * m2 * l1 * l2 * qd1 * qd2 * sympy.cos(q1 - q2)
        + (m1 / 2 + m2) * g * l1 * sympy.cos(q1)
        + (m2 / 2) * g * l2 * sympy.cos(q2)
    )
    rng = np.random.default_rng(1)
    Q, QD = rng.uniform(-2, 2, (50, 2)), rng.uniform(-2, 2, (50, 2))
    f = symbolic.to_numpy(paper, 2)
    np.testing.assert_allclose(dp.lagrangian(torch.from_numpy(Q), torch.from_numpy(QD)).numpy(), f(Q, QD), rtol=1e-13)
    assert dp.domain == Domain()  # U(-pi/2, pi/2), the paper's range


def test_per_coordinate_domains_and_widening_keep_linear_ranges():
    import math

    spring = SYSTEMS["spring_pendulum"]()
    data = generate(spring, 2000, 0, cache=False)
    assert data.q[:, 0].min() >= 0.5 and data.q[:, 0].max() <= 1.5  # the spring's length stays positive
    wide = SYSTEMS["spring_pendulum"](domain=spring.scaled_domain(math.pi))
    lo, hi = wide.domain.bounds("q", 2)
    assert (lo[0], hi[0]) == (0.5, 1.5) and (lo[1], hi[1]) == (-math.pi, math.pi)
    assert wide.domain.bounds("qd", 2)[1].tolist() == [math.pi, math.pi]
    with pytest.raises(ValueError, match="3 ranges for 2 coordinates"):
        Domain(q=((0, 1), (0, 1), (0, 1))).bounds("q", 2)


def test_n_link_pendulum_with_two_links_is_the_papers_double_pendulum():
    from systems.n_link_pendulum import n_link_pendulum

    two = n_link_pendulum(2)(params=n_link_pendulum(2).Params(m1=3.0, l1=2.67, m2=1.0, l2=1.67))
    rng = np.random.default_rng(3)
    Q, QD = rng.uniform(-2, 2, (50, 2)), rng.uniform(-2, 2, (50, 2))
    ours = symbolic.to_numpy(two.lagrangian_sympy, 2)(Q, QD)
    paper = symbolic.to_numpy(SYSTEMS["double_pendulum"]().lagrangian_sympy, 2)(Q, QD)
    np.testing.assert_allclose(ours, paper, rtol=1e-12)
    assert SYSTEMS["triple_pendulum"]().dof == 3
