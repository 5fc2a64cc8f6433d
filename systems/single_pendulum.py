"""A single pendulum: a point mass on a massless rod, angle from the downward vertical.

.. math::  L = \\tfrac12 m l^2 \\dot q^2 + m g l \\cos q
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy

from systems.base import SYSTEMS, System


@dataclass(frozen=True)
class SinglePendulumParams:
    """Mass (kg), length (m), gravity (m/s^2)."""

    m: float = 1.0
    l: float = 1.0
    g: float = 9.81


@SYSTEMS.add("single_pendulum", "simulated")
class SinglePendulum(System):
    title = "a single pendulum"
    summary = "a point mass on a massless rod"
    coordinates = ("theta",)
    planar_chain = True
    link_lengths = ("l",)
    Params = SinglePendulumParams
    sysid_unknowns = ("m", "l")

    def lagrangian_expr(self, q, qd, p):
        return p.m * p.l**2 * qd[0] ** 2 / 2 + p.m * p.g * p.l * sympy.cos(q[0])
