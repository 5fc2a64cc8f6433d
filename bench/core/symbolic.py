"""Sympy helpers shared by systems and symbolic methods.

Every Lagrangian in the suite is written in the same symbols, named like the
columns of the data format: ``q_1 .. q_n`` and ``qd_1 .. qd_n``. This module
builds those symbols and compiles sympy expressions into batched torch
functions ``f(q, qd, *extra) -> (batch,)``.
"""

from __future__ import annotations

from typing import Callable, Sequence

import sympy
import torch


def coordinate_symbols(dof: int) -> tuple[tuple[sympy.Symbol, ...], tuple[sympy.Symbol, ...]]:
    """Return ``(q, qd)`` symbol tuples for ``dof`` degrees of freedom."""
    q = sympy.symbols(f"q_1:{dof + 1}", real=True)
    qd = sympy.symbols(f"qd_1:{dof + 1}", real=True)
    return tuple(q), tuple(qd)


def acceleration_symbols(dof: int) -> tuple[sympy.Symbol, ...]:
    return tuple(sympy.symbols(f"qdd_1:{dof + 1}", real=True))


TorchLagrangian = Callable[..., torch.Tensor]


def numeric_subexpressions_to_floats(expr: sympy.Expr) -> sympy.Expr:
    """Evaluate function calls and powers of numbers (``sin(1/2)``, ``sqrt(2)``),
    which torch cannot take."""
    return expr.replace(lambda e: isinstance(e, (sympy.Function, sympy.Pow)) and e.is_number,
                        lambda e: sympy.Float(e.evalf()))


def to_torch(
    expr: sympy.Expr,
    dof: int,
    extra: Sequence[sympy.Symbol] = (),
) -> TorchLagrangian:
    """Compile ``expr(q, qd, extra)`` into a batched torch function.

    Parameters
    ----------
    expr
        A sympy expression in the symbols of :func:`coordinate_symbols` and,
        optionally, the symbols in ``extra``.
    dof
        Number of degrees of freedom.
    extra
        Further symbols, given to the compiled function as one tensor of shape
        ``(len(extra),)`` (for example the unknown parameters of a parametric
        Lagrangian) or ``(batch, len(extra))``.

    Returns
    -------
    callable
        ``f(q, qd)`` or ``f(q, qd, theta)`` with ``q, qd`` of shape
        ``(batch, dof)``, returning a tensor of shape ``(batch,)`` in the dtype
        of ``q``.
    """
    q, qd = coordinate_symbols(dof)
    args = list(q) + list(qd) + list(extra)
    expr = numeric_subexpressions_to_floats(sympy.sympify(expr))
    unknown = expr.free_symbols - set(args)
    if unknown:
        names = ", ".join(sorted(map(str, unknown)))
        raise ValueError(f"expression has symbols outside q, qd and the parameters: {names}")
    raw = sympy.lambdify(args, expr, modules="torch", cse=True)
    n_extra = len(extra)

    def f(q_t: torch.Tensor, qd_t: torch.Tensor, theta: torch.Tensor | None = None) -> torch.Tensor:
        cols = list(q_t.unbind(-1)) + list(qd_t.unbind(-1))
        if n_extra:
            if theta is None:
                raise TypeError(f"this Lagrangian needs {n_extra} parameters")
            cols += list(theta.unbind(-1))
        out = raw(*cols)
        # a term-free (constant) expression comes back as a Python number
        zero = q_t[..., 0] * 0
        return zero + out

    f.expr = expr  # type: ignore[attr-defined]
    return f


class SymbolicTangent:
    """A Lagrangian term ``expr(q, qd)`` compiled to torch with its derivatives, a
    :class:`~bench.physics.dynamics.TangentLagrangian`: the Euler–Lagrange transform then takes its
    derivatives from here rather than from two reverse passes.

    ``dL/dq``, ``dL/dqd`` and the derivative of ``dL/dqd`` along ``(dq, dqd)`` are derived by sympy once,
    and compiled into one function with ``L`` (common subexpressions shared): for a term evaluated again and
    again (:meth:`bench.physics.terms.Term.torque`'s ``often``), where autograd's two passes cost twice the
    term's evaluation. ``tests/physics/test_terms.py`` holds its torques to the reverse passes'."""

    def __init__(self, expr: sympy.Expr, dof: int):
        q, qd = coordinate_symbols(dof)
        dq = sympy.symbols(f"dq_1:{dof + 1}", real=True)
        dqd = sympy.symbols(f"dqd_1:{dof + 1}", real=True)
        self.expr = expr = numeric_subexpressions_to_floats(sympy.sympify(expr))
        unknown = expr.free_symbols - set(q) - set(qd)
        if unknown:
            raise ValueError(f"expression has symbols outside q and qd: {', '.join(sorted(map(str, unknown)))}")
        d_q = [sympy.diff(expr, s) for s in q]
        d_qd = [sympy.diff(expr, s) for s in qd]
        along = [sum((sympy.diff(p, a) * b for a, b in zip(q + qd, dq + dqd)), sympy.Integer(0)) for p in d_qd]
        self.dof = dof
        self._raw = sympy.lambdify(list(q) + list(qd) + list(dq) + list(dqd), [expr, *d_q, *d_qd, *along],
                                   modules="torch", cse=True)

    def _parts(self, q, qd, dq, dqd):
        zero = q[..., 0] * 0
        out = [zero + v for v in self._raw(*q.unbind(-1), *qd.unbind(-1), *dq.unbind(-1), *dqd.unbind(-1))]
        n = self.dof
        return out[0], torch.stack(out[1:1 + n], -1), torch.stack(out[1 + n:1 + 2 * n], -1), \
            torch.stack(out[1 + 2 * n:], -1)

    def __call__(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self._parts(q, qd, torch.zeros_like(q), torch.zeros_like(qd))[0]

    def tangent(self, q, qd, dq, dqd):
        return self._parts(q, qd, dq, dqd)


def to_numpy(expr: sympy.Expr, dof: int) -> Callable:
    """Compile ``expr(q, qd)`` into a numpy function of ``(batch, dof)`` arrays."""
    import numpy as np

    q, qd = coordinate_symbols(dof)
    expr = numeric_subexpressions_to_floats(sympy.sympify(expr))
    raw = sympy.lambdify(list(q) + list(qd), expr, modules="numpy", cse=True)

    def f(q_a, qd_a):
        out = raw(*q_a.T, *qd_a.T)
        return np.zeros(q_a.shape[0]) + out

    return f
