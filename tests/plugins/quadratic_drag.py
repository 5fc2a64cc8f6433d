"""A law of the joint as a plugin (docs/extending.md, "A law of the joint"):
quadratic drag, ``tau_j = c_j qd_j |qd_j|``, the torque of the dissipation
function ``D = c |qd|^3 / 3``."""

import sympy

from bench.physics.effects import Effect
from bench.physics.laws import LAWS

LAWS.declare(Effect("quadratic_drag", lambda q, qd: sympy.Abs(qd[0]) ** 3 / 3, "D", "c", "c·qd·|qd| (D = c·|qd|³/3)"),
             "drag")
