"""An n-link planar pendulum of uniform rods, absolute angles from the downward vertical.

Link ``i`` has mass ``m_i`` and length ``l_i``, its centre of mass at
``l_i / 2`` and inertia ``m_i l_i^2 / 12`` about it. With ``a_k = l_k`` for the
links above ``i`` and ``a_i = l_i / 2``, the velocity of its centre of mass
gives

.. math::

    T_i = \\tfrac12 m_i \\sum_{j,k \\le i} a_j a_k \\dot q_j \\dot q_k \\cos(q_j - q_k)
        + \\tfrac1{24} m_i l_i^2 \\dot q_i^2, \\qquad
    V_i = -m_i g \\sum_{k \\le i} a_k \\cos q_k,

and ``L = sum_i T_i - V_i``. For n = 2 and the paper's parameters this is the
paper's double pendulum. :func:`n_link_pendulum` builds the system for any n;
the registry holds n = 3.
"""

from __future__ import annotations

import dataclasses
import functools

import sympy

from systems.base import SYSTEMS, System


@functools.lru_cache(maxsize=None)
def n_link_pendulum(n: int) -> type[System]:
    """The System class of an ``n``-link rod pendulum (masses 1, lengths 1 by default)."""
    if n < 1:
        raise ValueError("an n-link pendulum needs n >= 1")
    fields = [(f"m{i}", float, dataclasses.field(default=1.0)) for i in range(1, n + 1)]
    fields += [(f"l{i}", float, dataclasses.field(default=1.0)) for i in range(1, n + 1)]
    fields += [("g", float, dataclasses.field(default=9.81))]
    Params = dataclasses.make_dataclass(f"Link{n}PendulumParams", fields, frozen=True)

    class NLinkPendulum(System):
        coordinates = tuple(f"theta{i}" for i in range(1, n + 1))
        absolute_angles = True
        planar_chain = True
        link_lengths = tuple(f"l{i}" for i in range(1, n + 1))
        sysid_unknowns = tuple(f"m{i}" for i in range(1, n + 1)) + tuple(f"l{i}" for i in range(1, n + 1))

        def lagrangian_expr(self, q, qd, p):
            m = [getattr(p, f"m{i}") for i in range(1, n + 1)]
            length = [getattr(p, f"l{i}") for i in range(1, n + 1)]
            L = 0
            for i in range(n):
                a = [length[k] for k in range(i)] + [length[i] / 2]
                speed2 = sum(a[j] * a[k] * qd[j] * qd[k] * sympy.cos(q[j] - q[k]) for j in range(i + 1) for k in range(i + 1))
                L += m[i] * speed2 / 2 + m[i] * length[i] ** 2 * qd[i] ** 2 / 24
                L += m[i] * p.g * sum(a[k] * sympy.cos(q[k]) for k in range(i + 1))
            return L

    NLinkPendulum.Params = Params
    NLinkPendulum.__name__ = NLinkPendulum.__qualname__ = f"Link{n}Pendulum"
    return NLinkPendulum


@SYSTEMS.add("triple_pendulum", "simulated")
class TriplePendulum(n_link_pendulum(3)):
    """The n-link rod pendulum with n = 3."""
    title = "a triple pendulum"
    summary = "the n-link rod pendulum with n = 3; `systems.n_link_pendulum.n_link_pendulum(n)` builds any n"
