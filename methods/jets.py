"""Second-order forward-mode ("jet") evaluation of expression trees in numpy.

A Lagrangian term ``f(z)``, ``z = (q, qd)``, is evaluated together with its
gradient ``G = df/dz`` and the Hessian-vector product ``Hu = (d2f/dz2) u``
along ``u = (qd, qdd)``. Its Euler–Lagrange image follows without autograd:
the suite's one transform (:func:`bench.physics.dynamics.euler_lagrange`) takes
``G`` and ``Hu`` from the jet (:meth:`JetAlgebra.torque`) and forms

    g(f)_i = Hu[qd_i] - G[q_i]

which is what genetic programming needs for every gene of every individual
in the indirect experiment. The rules (for arrays over samples):

* ``a + b``: values, gradients and products add;
* ``a * b``: ``G = a G_b + b G_a``,
  ``Hu = a Hu_b + b Hu_a + G_a (G_b . u) + G_b (G_a . u)``;
* ``phi(a)``: ``G = phi'(a) G_a``, ``Hu = phi'(a) Hu_a + phi''(a) (G_a . u) G_a``.

Zero derivatives are kept as ``None`` so that constants cost nothing. The
evaluator is checked against the suite's autograd transform in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from bench.physics.dynamics import euler_lagrange


@dataclass
class Jet:
    """A value with its gradient and Hessian-vector product (``None`` = zero)."""

    v: np.ndarray
    G: np.ndarray | None = None   # (N, m)
    Hu: np.ndarray | None = None  # (N, m)

    def dot_u(self, u: np.ndarray) -> np.ndarray | None:
        return None if self.G is None else np.einsum("nm,nm->n", self.G, u)


def _add(a, b, sign=1.0):
    if a is None:
        return None if b is None else (b if sign > 0 else -b)
    if b is None:
        return a
    return a + b if sign > 0 else a - b


def _scale(s: np.ndarray, x):
    return None if x is None else s[:, None] * x


@dataclass(frozen=True)
class Unary:
    """``phi`` with ``phi'`` and ``phi''``, each a function of the argument's values."""

    f: Callable[[np.ndarray], np.ndarray]
    d1: Callable[[np.ndarray], np.ndarray]
    d2: Callable[[np.ndarray], np.ndarray]


def _protected_sqrt(x):
    return np.sqrt(np.abs(x))


UNARY: dict[str, Unary] = {
    "sin": Unary(np.sin, np.cos, lambda x: -np.sin(x)),
    "cos": Unary(np.cos, lambda x: -np.sin(x), lambda x: -np.cos(x)),
    "square": Unary(np.square, lambda x: 2 * x, lambda x: np.full_like(x, 2.0)),
    "cube": Unary(lambda x: x**3, lambda x: 3 * x * x, lambda x: 6 * x),
    # protected square root sqrt(|x|), as in GPTIPS; its derivatives blow up at 0
    "sqrt": Unary(
        _protected_sqrt,
        lambda x: np.sign(x) / (2 * _protected_sqrt(x)),
        lambda x: -1.0 / (4 * np.abs(x) ** 1.5),
    ),
}


class JetAlgebra:
    """Jet arithmetic on one batch of states.

    Parameters
    ----------
    q, qd, qdd
        Arrays of shape ``(N, dof)``.
    order
        2: values, gradients and Hessian-vector products (indirect);
        0: values only (direct).
    """

    def __init__(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, order: int = 2):
        self.n, self.dof = q.shape
        self.m = 2 * self.dof
        self.order = order
        self.u = np.concatenate([qd, qdd], axis=1)
        self.states = tuple(torch.from_numpy(np.ascontiguousarray(a, dtype=np.float64)) for a in (q, qd, qdd))
        self.zero = torch.zeros(self.n, self.dof, dtype=torch.float64)  # a derivative that is zero
        z = np.concatenate([q, qd], axis=1)
        self.variables = []
        for k in range(self.m):
            G = None
            if order:
                G = np.zeros((self.n, self.m))
                G[:, k] = 1.0
            self.variables.append(Jet(z[:, k].copy(), G, None))

    def constant(self, c: float) -> Jet:
        return Jet(np.full(self.n, float(c)))

    def add(self, a: Jet, b: Jet) -> Jet:
        return Jet(a.v + b.v, _add(a.G, b.G), _add(a.Hu, b.Hu))

    def sub(self, a: Jet, b: Jet) -> Jet:
        return Jet(a.v - b.v, _add(a.G, b.G, -1.0), _add(a.Hu, b.Hu, -1.0))

    def mul(self, a: Jet, b: Jet) -> Jet:
        v = a.v * b.v
        if not self.order:
            return Jet(v)
        G = _add(_scale(a.v, b.G), _scale(b.v, a.G))
        Hu = _add(_scale(a.v, b.Hu), _scale(b.v, a.Hu))
        if a.G is not None and b.G is not None:
            Hu = _add(Hu, _add(_scale(b.dot_u(self.u), a.G), _scale(a.dot_u(self.u), b.G)))
        return Jet(v, G, Hu)

    def unary(self, name: str, a: Jet) -> Jet:
        op = UNARY[name]
        v = op.f(a.v)
        if not self.order or a.G is None:
            return Jet(v)
        d1 = op.d1(a.v)
        Hu = _scale(d1, a.Hu)
        Hu = _add(Hu, _scale(op.d2(a.v) * a.dot_u(self.u), a.G))
        return Jet(v, _scale(d1, a.G), Hu)

    def torque(self, f: Jet) -> np.ndarray:
        """``g(f)`` of shape ``(N, dof)``, by :func:`~bench.physics.dynamics.euler_lagrange`
        from the jet's own derivatives."""
        return euler_lagrange(_JetLagrangian(self, f), *self.states).numpy()


class _JetLagrangian:
    """A jet of :class:`JetAlgebra` as a Lagrangian that gives its own
    derivatives (:class:`bench.physics.dynamics.TangentLagrangian`): known at
    the algebra's states only, and along its direction ``u = (qd, qdd)``
    only, which is the direction the transform asks for."""

    def __init__(self, algebra: JetAlgebra, f: Jet):
        self.algebra, self.f = algebra, f

    def _check(self, tensors, expected) -> None:
        if any(t.data_ptr() != e.data_ptr() for t, e in zip(tensors, expected)):
            raise ValueError("a jet's derivatives are known at its algebra's states, along (qd, qdd), only")

    def __call__(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        self._check((q, qd), self.algebra.states[:2])
        return torch.from_numpy(self.f.v)

    def tangent(self, q, qd, dq, dqd):
        q0, qd0, qdd0 = self.algebra.states
        self._check((q, qd, dq, dqd), (q0, qd0, qd0, qdd0))
        d, zero = self.algebra.dof, self.algebra.zero
        G, Hu = self.f.G, self.f.Hu
        dL_dq, dL_dqd = (zero, zero) if G is None else (torch.from_numpy(G[:, :d]), torch.from_numpy(G[:, d:]))
        return torch.from_numpy(self.f.v), dL_dq, dL_dqd, zero if Hu is None else torch.from_numpy(Hu[:, d:])
