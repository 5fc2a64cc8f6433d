"""Effects a rigid-body model lacks, defined once for the data generator
(which adds them, undeclared) and the residual loop (which finds them).

Each effect has one coefficient and acts on one joint or, for the coupled
ones, on a pair of coordinates ``i, j`` through their difference. Its torque
is *added* to the rigid-body torque ``g(L)``, so friction coefficients are
positive. An effect is a :class:`~bench.core.terms.Term` of one of three kinds:

* **conservative**: a term of the Lagrangian, its torque through the
  Euler–Lagrange transform;
* **dissipative**: a term of the Rayleigh dissipation function ``D``, its
  torque ``dD/dqd``; physically admissible only with a coefficient >= 0;
* **force**: a generalized force that is neither (a constant offset: a
  sensor or cable bias).

=====================  =============  ========================================  ===================================
name                   kind           term per unit coefficient                 torque
=====================  =============  ========================================  ===================================
``viscous_friction``   dissipative    ``D = qd_j^2 / 2``                        ``b qd_j`` on joint j
``coulomb_friction``   dissipative    ``D = |qd_j|``                            ``F sign(qd_j)`` on joint j
``armature``           conservative   ``L += qd_j^2 / 2`` (rotor inertia)       ``I qdd_j`` on joint j
``spring``             conservative   ``L += -q_j^2 / 2`` (potential)           ``k q_j`` on joint j
``offset``             force          ``c`` on joint j                          ``c`` on joint j
``coupled_spring``     conservative   ``L += -(q_i - q_j)^2 / 2``               ``k (q_i - q_j)`` on i, minus on j
``coupled_damper``     dissipative    ``D = (qd_i - qd_j)^2 / 2``               ``b (qd_i - qd_j)`` on i, minus on j
=====================  =============  ========================================  ===================================

On absolute angles, ``q_i - q_j`` is the relative angle of the joint
between links ``i`` and ``j``: an elbow spring or damper is one coupled
effect with one coefficient, not a spring on each joint and cross terms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy

from bench.core.data import Dataset
from bench.core.errors import ConfigError
from bench.core.terms import Term


@dataclass(frozen=True)
class Effect:
    """One kind of effect.

    Attributes
    ----------
    expr
        ``expr(q, qd) -> sympy``: the term per unit coefficient, given the
        symbols of the effect's coordinates (one, or a pair ``i, j``).
    kind
        ``conservative`` (a term of ``L``), ``dissipative`` (a term of ``D``)
        or ``force`` (a generalized force on the joint).
    parameter
        The coefficient's name in reports (``b``, ``k``, ...).
    nonnegative
        Whether only a coefficient >= 0 is physical: dissipation cannot
        produce energy, and a rotor inertia or a passive spring's stiffness
        is not negative. An offset may have either sign.
    """

    name: str
    expr: Callable[[tuple, tuple], sympy.Expr]
    kind: str
    parameter: str
    formula: str
    arity: int = 1
    nonnegative: bool = True

    def admissible(self, coefficient: float) -> bool:
        """Whether ``coefficient`` is physical for this effect."""
        return coefficient >= 0 or not self.nonnegative

    @property
    def conservative(self) -> bool:
        return self.kind == "conservative"

    def term(self, *joints: int) -> Term:
        """The effect on ``joints`` (0-based; two for a coupled effect) as a term."""
        if len(joints) != self.arity or len(set(joints)) != len(joints):
            raise ValueError(f"{self.name} acts on {self.arity} distinct joint(s), got {joints}")
        q = tuple(sympy.Symbol(f"q_{j + 1}", real=True) for j in joints)
        qd = tuple(sympy.Symbol(f"qd_{j + 1}", real=True) for j in joints)
        expr = sympy.sympify(self.expr(q, qd))
        joint = joints[0] if self.arity == 1 else None
        if self.kind == "conservative":
            return Term(expr, None, self.name, joint)
        if self.kind == "dissipative":
            return Term(expr, None, self.name, joint, True)
        return Term.force(expr, joints[0], self.name)


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect("viscous_friction", lambda q, qd: qd[0] ** 2 / 2, "dissipative", "b", "b·qd (D = b·qd²/2)"),
        Effect("coulomb_friction", lambda q, qd: sympy.Abs(qd[0]), "dissipative", "F_c", "F_c·sign(qd) (D = F_c·|qd|)"),
        Effect("armature", lambda q, qd: qd[0] ** 2 / 2, "conservative", "I", "I·qdd (L += I·qd²/2)"),
        Effect("spring", lambda q, qd: -(q[0] ** 2) / 2, "conservative", "k", "k·q (L −= k·q²/2)"),
        Effect("offset", lambda q, qd: sympy.Integer(1), "force", "tau_0", "tau_0", nonnegative=False),
        Effect("coupled_spring", lambda q, qd: -((q[0] - q[1]) ** 2) / 2, "conservative", "k",
               "k·(q_i − q_j) on i, −k·(q_i − q_j) on j (L −= k·(q_i − q_j)²/2)", 2),
        Effect("coupled_damper", lambda q, qd: (qd[0] - qd[1]) ** 2 / 2, "dissipative", "b",
               "b·(qd_i − qd_j) on i, −b·(qd_i − qd_j) on j (D = b·(qd_i − qd_j)²/2)", 2),
    )
}

def parse_effects(items: list[str], dof: int, source: str = "--effects") -> dict[str, dict[tuple[int, ...], float]]:
    """``["viscous_friction=0.8,0.5", "coupled_spring=1-2:3.0"]`` ->
    ``{"viscous_friction": {(0,): 0.8, (1,): 0.5}, "coupled_spring": {(0, 1): 3.0}}``.

    A one-joint effect takes one coefficient per joint; a coupled effect
    takes ``i-j:c`` items (joints from 1), comma-separated. A clear
    :class:`ConfigError` otherwise."""
    out = {}
    for item in items:
        name, sep, values = item.partition("=")
        name = name.strip()
        if not sep:
            raise ConfigError(f"{source}: expected NAME=c1,...,c{dof} or NAME=i-j:c, got {item!r}")
        if name not in EFFECTS:
            raise ConfigError(f"{source}: unknown effect {name!r}; known: {', '.join(EFFECTS)}")
        if EFFECTS[name].arity == 1:
            try:
                coefs = tuple(float(v) for v in values.split(","))
            except ValueError:
                raise ConfigError(f"{source}: {name} needs numbers, got {values!r}") from None
            if len(coefs) != dof or not all(np.isfinite(coefs)):
                raise ConfigError(f"{source}: {name} needs {dof} finite coefficient(s), one per joint, got {values!r}")
            out[name] = {(j,): c for j, c in enumerate(coefs)}
            continue
        pairs = {}
        for part in values.split(","):
            joints, colon, value = part.partition(":")
            i, dash, j = joints.partition("-")
            try:
                key, c = (int(i) - 1, int(j) - 1), float(value)
            except ValueError:
                key, c = None, math.nan
            if not (colon and dash and key and math.isfinite(c)) or not (0 <= min(key) and max(key) < dof and key[0] != key[1]):
                raise ConfigError(f"{source}: {name} needs i-j:c items with two distinct joints in 1..{dof} and a "
                                  f"finite coefficient, got {part!r}")
            pairs[key] = c
        out[name] = pairs
    return out


def add_effects(data: Dataset, effects: dict) -> Dataset:
    """``data`` with the effects' torques added (and, for conservative effects,
    their terms added to ``L``); ``effects`` as :func:`parse_effects` gives
    them, or a one-joint effect's coefficients as a sequence, one per joint
    (``{"viscous_friction": (0.8, 0.5)}``)."""
    tau = data.tau.copy()
    L = None if data.L is None else data.L.copy()
    effects = {name: coefs if isinstance(coefs, dict) else {(j,): c for j, c in enumerate(coefs)}
               for name, coefs in effects.items()}
    for name, coefs in effects.items():
        for joints, c in coefs.items():
            if c == 0:
                continue
            term = EFFECTS[name].term(*joints)
            tau += c * term.torque(data)
            if L is not None and not term.is_force:
                L += c * term.value(data)
    text = ", ".join(f"{k}=" + ",".join(f"{'-'.join(str(j + 1) for j in js)}:{c:g}" if len(js) > 1 else f"{c:g}"
                                        for js, c in v.items()) for k, v in effects.items())
    return data.replace(tau=tau, L=L, source=f"{data.source} + undeclared {text}",
                        meta={**data.meta, "effects": {k: {"-".join(str(j + 1) for j in js): c for js, c in v.items()}
                                                       for k, v in effects.items()}})
