"""The terms of a fitted model's expression, for the residual loop's
expression strategy (:class:`bench.residual.strategies.Expression`): the
coefficient-free terms of the expanded expression, where there are few enough
to refit their coefficients by least squares."""

from __future__ import annotations

import functools

import sympy

from bench.physics.models import FittedModel

#: a symbolic model with more terms than this is refitted like a neural one
#: (a least-squares refit of thousands of terms is neither fast nor meaningful)
MAX_SYMBOLIC_TERMS = 200
#: an expression with more nodes than this is not expanded into terms at all
MAX_SYMBOLIC_NODES = 50 * MAX_SYMBOLIC_TERMS


def expression_terms(model: FittedModel) -> tuple[sympy.Expr, ...] | None:
    """The coefficient-free terms of the model's expanded expression that act on
    the torque; ``None`` where the model says its terms exceed
    :data:`MAX_SYMBOLIC_TERMS` (without building it), where it has no
    expression, or where its expression is too large to expand or has more terms."""
    bound = model.expression_terms_bound()
    if bound is not None and bound > MAX_SYMBOLIC_TERMS:
        return None
    expr = model.expression()
    return None if expr is None else _terms(expr)


def _small(expr: sympy.Expr) -> bool:
    """Whether ``expr`` has at most :data:`MAX_SYMBOLIC_NODES` nodes, found
    without expanding it (counting stops at the limit)."""
    for i, _ in enumerate(sympy.preorder_traversal(expr)):
        if i >= MAX_SYMBOLIC_NODES:
            return False
    return True


@functools.lru_cache(maxsize=16)
def _terms(expr: sympy.Expr) -> tuple[sympy.Expr, ...] | None:
    if not _small(expr):
        return None
    out = []
    for term in sympy.Add.make_args(sympy.expand(expr)):
        _, rest = term.as_coeff_Mul()
        if rest.free_symbols and rest not in out:
            out.append(rest)
    return tuple(out) if len(out) <= MAX_SYMBOLIC_TERMS else None
