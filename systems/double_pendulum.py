"""The paper's double pendulum: two uniform rods, absolute angles.

.. math::

    L = \\tfrac12\\left(\\tfrac{m_1}{3} + m_2\\right) l_1^2 \\dot q_1^2
      + \\tfrac12 \\tfrac{m_2}{3} l_2^2 \\dot q_2^2
      + \\tfrac12 m_2 l_1 l_2 \\dot q_1 \\dot q_2 \\cos(q_1 - q_2)
      + \\left(\\tfrac{m_1}{2} + m_2\\right) g l_1 \\cos q_1
      + \\tfrac{m_2}{2} g l_2 \\cos q_2

Both angles are measured from the downward vertical (``q = 0`` hangs down),
each absolute, not relative to the previous link. Parameters and the sampling
range U(-pi/2, pi/2) for q, qd and qdd follow Valle & Haddadin (2021),
"SyReNets: Symbolic Residual Neural Networks", Section IV.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy

from systems.base import SYSTEMS, System


@dataclass(frozen=True)
class DoublePendulumParams:
    """Rod masses (kg), lengths (m) and gravity (m/s^2)."""

    m1: float = 3.0
    l1: float = 2.67
    m2: float = 1.0
    l2: float = 1.67
    g: float = 9.81


@SYSTEMS.add("double_pendulum", "simulated", "paper")
class DoublePendulum(System):
    title = "the paper's double pendulum"
    summary = "the paper's double pendulum of two rods, absolute angles; m1 = 3, l1 = 2.67, m2 = 1, l2 = 1.67, g = 9.81"
    coordinates = ("theta1", "theta2")
    absolute_angles = True
    planar_chain = True
    link_lengths = ("l1", "l2")
    Params = DoublePendulumParams
    sysid_unknowns = ("m1", "l1", "m2", "l2")
    reference = ("Valle & Haddadin (2021), Tables 1 and 2: SyReNets' All 10 test MSE after 2000 s on an "
                 "RTX 2080 Ti, with q, q̇, q̈ ~ U(−π/2, π/2), is 0.137 in the direct experiment (L) and 0.012 "
                 "in the indirect one (τ).")

    def lagrangian_expr(self, q, qd, p):
        half = sympy.Rational(1, 2)
        third = sympy.Rational(1, 3)
        kinetic = (
            half * (p.m1 * third + p.m2) * p.l1**2 * qd[0] ** 2
            + half * (p.m2 * third) * p.l2**2 * qd[1] ** 2
            + half * p.m2 * p.l1 * p.l2 * qd[0] * qd[1] * sympy.cos(q[0] - q[1])
        )
        # potential energy is -(...) so it enters L with a plus sign
        gravity = (p.m1 * half + p.m2) * p.g * p.l1 * sympy.cos(q[0]) + p.m2 * half * p.g * p.l2 * sympy.cos(q[1])
        return kinetic + gravity
