"""Joint effects a rigid-body model lacks, defined once for the data
generator (which adds them, undeclared) and the residual loop (which finds
them).

Each effect acts on one joint ``j`` with one coefficient ``c``; its torque is
*added* to the rigid-body torque ``g(L)``, so friction coefficients are
positive. An effect on a joint is a :class:`~bench.core.terms.Term`: a
Lagrangian term where the effect is conservative, a generalized force
otherwise.

============================  ======================  =================================================
name                          torque on joint j       where it belongs
============================  ======================  =================================================
``viscous_friction``          ``c * qd_j``            Rayleigh dissipation ``D = c qd_j^2 / 2``
``coulomb_friction``          ``c * sign(qd_j)``      a generalized force (dissipative)
``armature``                  ``c * qdd_j``           the Lagrangian: ``+ c qd_j^2 / 2`` (rotor inertia)
``spring``                    ``c * q_j``             the Lagrangian: ``- c q_j^2 / 2`` (potential)
``offset``                    ``c``                   a constant generalized force (sensor or cable bias)
============================  ======================  =================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy

from bench.core.data import Dataset
from bench.core.errors import ConfigError
from bench.core.terms import Term


@dataclass(frozen=True)
class Effect:
    """One kind of joint effect.

    Attributes
    ----------
    expr
        ``expr(q_j, qd_j) -> sympy``: the term per unit coefficient, in the
        joint's own symbols: a piece of ``L`` where ``conservative``, else the
        generalized force on the joint.
    """

    name: str
    expr: Callable[[sympy.Symbol, sympy.Symbol], sympy.Expr]
    conservative: bool
    formula: str

    def term(self, joint: int) -> Term:
        """The effect on ``joint`` (0-based) as a term."""
        n = joint + 1
        q, qd = sympy.Symbol(f"q_{n}", real=True), sympy.Symbol(f"qd_{n}", real=True)
        expr = sympy.sympify(self.expr(q, qd))
        if self.conservative:
            return Term.lagrangian(expr, self.name, joint)
        return Term.force(expr, joint, self.name)


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect("viscous_friction", lambda q, qd: qd, False, "c·qd"),
        Effect("coulomb_friction", lambda q, qd: sympy.sign(qd), False, "c·sign(qd)"),
        Effect("armature", lambda q, qd: qd**2 / 2, True, "c·qdd (L += c·qd²/2)"),
        Effect("spring", lambda q, qd: -(q**2) / 2, True, "c·q (L −= c·q²/2)"),
        Effect("offset", lambda q, qd: sympy.Integer(1), False, "c"),
    )
}


def parse_effects(items: list[str], dof: int, source: str = "--effects") -> dict[str, tuple[float, ...]]:
    """``["viscous_friction=0.8,0.5", ...]`` -> ``{"viscous_friction": (0.8, 0.5)}``,
    one coefficient per joint; a clear :class:`ConfigError` otherwise."""
    out = {}
    for item in items:
        name, sep, values = item.partition("=")
        name = name.strip()
        if not sep:
            raise ConfigError(f"{source}: expected NAME=c1,...,c{dof}, got {item!r}")
        if name not in EFFECTS:
            raise ConfigError(f"{source}: unknown effect {name!r}; known: {', '.join(EFFECTS)}")
        try:
            coefs = tuple(float(v) for v in values.split(","))
        except ValueError:
            raise ConfigError(f"{source}: {name} needs numbers, got {values!r}") from None
        if len(coefs) != dof or not all(np.isfinite(coefs)):
            raise ConfigError(f"{source}: {name} needs {dof} finite coefficient(s), one per joint, got {values!r}")
        out[name] = coefs
    return out


def add_effects(data: Dataset, effects: dict[str, tuple[float, ...]]) -> Dataset:
    """``data`` with the effects' torques added (and, for conservative effects,
    their terms added to ``L``)."""
    tau = data.tau.copy()
    L = None if data.L is None else data.L.copy()
    for name, coefs in effects.items():
        for j, c in enumerate(coefs):
            if c == 0:
                continue
            term = EFFECTS[name].term(j)
            tau += c * term.torque(data)
            if L is not None and not term.is_force:
                L += c * term.value(data)
    text = ", ".join(f"{k}={','.join(f'{c:g}' for c in v)}" for k, v in effects.items())
    return data.replace(tau=tau, L=L, source=f"{data.source} + undeclared {text}",
                        meta={**data.meta, "effects": {k: list(v) for k, v in effects.items()}})
