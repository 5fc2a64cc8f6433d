"""A cart-pole: a cart on a rail with a uniform rod hinged on it.

Coordinates: the cart's position ``x`` (linear, m) and the rod's angle
``theta`` from the downward vertical. With cart mass ``M``, rod mass ``m`` and
length ``l`` (centre of mass at ``l/2``, inertia ``m l^2 / 12`` about it):

.. math::

    L = \\tfrac12 (M + m) \\dot x^2 + \\tfrac12 m l \\dot x \\dot\\theta \\cos\\theta
      + \\tfrac16 m l^2 \\dot\\theta^2 + \\tfrac12 m g l \\cos\\theta
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy

from systems.base import HALF_PI, SYSTEMS, Domain, System


@dataclass(frozen=True)
class CartPoleParams:
    """Cart mass M, rod mass m (kg), rod length l (m), gravity g (m/s^2)."""

    M: float = 1.0
    m: float = 0.3
    l: float = 0.8
    g: float = 9.81


@SYSTEMS.add("cart_pole", "simulated")
class CartPole(System):
    title = "a cart-pole"
    summary = "a cart on a rail (linear coordinate) with a rod hinged on it"
    coordinates = ("x", "theta")
    coordinate_kinds = ("linear", "angle")
    Params = CartPoleParams
    sysid_unknowns = ("M", "m", "l")
    default_domain = Domain(q=((-1.0, 1.0), (-HALF_PI, HALF_PI)))

    def lagrangian_expr(self, q, qd, p):
        x_dot, th, th_dot = qd[0], q[1], qd[1]
        kinetic = (p.M + p.m) * x_dot**2 / 2 + p.m * p.l * x_dot * th_dot * sympy.cos(th) / 2 + p.m * p.l**2 * th_dot**2 / 6
        return kinetic + p.m * p.g * p.l * sympy.cos(th) / 2
