"""An elastic (spring) pendulum: a point mass on a spring, swinging in a plane.

Coordinates: the spring's length ``r`` (linear, m, kept positive by the
domain) and the angle ``theta`` from the downward vertical. With mass ``m``,
stiffness ``k`` and rest length ``l0``:

.. math::

    L = \\tfrac12 m (\\dot r^2 + r^2 \\dot\\theta^2) + m g r \\cos\\theta - \\tfrac12 k (r - l_0)^2
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy

from systems.base import HALF_PI, SYSTEMS, Domain, System


@dataclass(frozen=True)
class SpringPendulumParams:
    """Mass (kg), stiffness (N/m), rest length (m), gravity (m/s^2)."""

    m: float = 1.0
    k: float = 40.0
    l0: float = 1.0
    g: float = 9.81


@SYSTEMS.add("spring_pendulum", "simulated")
class SpringPendulum(System):
    title = "a spring pendulum"
    summary = "a mass on a spring swinging in a plane (length r > 0 and angle)"
    coordinates = ("r", "theta")
    coordinate_kinds = ("linear", "angle")
    Params = SpringPendulumParams
    sysid_unknowns = ("m", "k", "l0")
    default_domain = Domain(q=((0.5, 1.5), (-HALF_PI, HALF_PI)))

    def lagrangian_expr(self, q, qd, p):
        r, th = q
        r_dot, th_dot = qd
        return p.m * (r_dot**2 + r**2 * th_dot**2) / 2 + p.m * p.g * r * sympy.cos(th) - p.k * (r - p.l0) ** 2 / 2
