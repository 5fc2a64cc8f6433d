"""Joint effects a rigid-body model lacks, defined once for the data
generator (which adds them, undeclared) and the residual loop (which finds
them).

Each effect acts on one joint ``j`` with one coefficient ``c``; its torque is
*added* to the rigid-body torque ``g(L)``, so friction coefficients are
positive:

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

from bench.data import Dataset
from bench.errors import ConfigError


@dataclass(frozen=True)
class Effect:
    """One kind of joint effect.

    Attributes
    ----------
    feature
        ``feature(q_j, qd_j, qdd_j) -> (n,)``: the torque per unit coefficient.
    lagrangian
        ``lagrangian(q_j, qd_j) -> sympy`` term per unit coefficient for a
        conservative effect, else ``None``.
    """

    name: str
    feature: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    lagrangian: Callable[[sympy.Symbol, sympy.Symbol], sympy.Expr] | None
    formula: str

    def torque(self, data: Dataset, joint: int) -> np.ndarray:
        """``(n, dof)`` torque per unit coefficient on ``joint`` (0-based)."""
        out = np.zeros_like(data.tau)
        out[:, joint] = self.feature(data.q[:, joint], data.qd[:, joint], data.qdd[:, joint])
        return out


EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect("viscous_friction", lambda q, qd, qdd: qd, None, "c·qd"),
        Effect("coulomb_friction", lambda q, qd, qdd: np.sign(qd), None, "c·sign(qd)"),
        Effect("armature", lambda q, qd, qdd: qdd, lambda q, qd: qd**2 / 2, "c·qdd (L += c·qd²/2)"),
        Effect("spring", lambda q, qd, qdd: q, lambda q, qd: -(q**2) / 2, "c·q (L −= c·q²/2)"),
        Effect("offset", lambda q, qd, qdd: np.ones_like(q), None, "c"),
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
    from bench import symbolic

    tau = data.tau.copy()
    L = None if data.L is None else data.L.copy()
    q_syms, qd_syms = symbolic.coordinate_symbols(data.dof)
    for name, coefs in effects.items():
        effect = EFFECTS[name]
        for j, c in enumerate(coefs):
            if c == 0:
                continue
            tau += c * effect.torque(data, j)
            if L is not None and effect.lagrangian is not None:
                term = sympy.lambdify((q_syms[j], qd_syms[j]), effect.lagrangian(q_syms[j], qd_syms[j]), "numpy")
                L += c * np.broadcast_to(term(data.q[:, j], data.qd[:, j]), L.shape)
    text = ", ".join(f"{k}={','.join(f'{c:g}' for c in v)}" for k, v in effects.items())
    return Dataset(data.q, data.qd, data.qdd, tau, L, data.system, f"{data.source} + undeclared {text}",
                   {**data.meta, "effects": {k: list(v) for k, v in effects.items()}})
