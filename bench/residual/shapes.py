"""The nonlinear parameter of a shaped effect (a Stribeck velocity, a
smoothed Coulomb velocity) where the residual loop refines it: a bounded
scalar search of the residual sum of squares, the linear coefficients fitted
at each value (variable projection). A shape on a grid of whole numbers (a
periodic torque's periods a revolution) is not refined: each value is a
term of its own."""

from __future__ import annotations

import math

import numpy as np

from bench.core.data import Dataset
from bench.physics.effects import EFFECTS
from bench.physics.terms import Term
from bench.residual.basis import project_off
from bench.residual.library import SHAPE_GRID

#: a shaped term's parameter is refined within this factor of its grid value
SHAPE_RANGE = 4.0
#: the range a shape is searched in: past the grid's ends by :data:`SHAPE_RANGE`;
#: a shape at either end is not identified (:func:`at_limit`)
SHAPE_LIMITS = (min(SHAPE_GRID) / SHAPE_RANGE, max(SHAPE_GRID) * SHAPE_RANGE)

#: a fit that leaves less than this share of its residual sum of squares is near round-off
#: (:func:`refined_shape`)
NEAR_EXACT = 1e-8

def best_shape(rss, shape: float, factor: float = SHAPE_RANGE) -> float:
    """The value within ``factor`` of ``shape``, and within
    :data:`SHAPE_LIMITS`, where ``rss(value)`` is least: a bounded scalar
    search in ``log(value)``."""
    from scipy.optimize import minimize_scalar  # 0.3 s to import: only a shaped effect needs it

    lo, hi = SHAPE_LIMITS
    shape = min(max(shape, lo), hi)
    bounds = (math.log(max(shape / factor, lo)), math.log(min(shape * factor, hi)))
    x = minimize_scalar(lambda x: rss(math.exp(x)), bounds=bounds, method="bounded", options={"xatol": 1e-10}).x
    return float(math.exp(x))


def shape_rss(Q: np.ndarray, r: np.ndarray, term: Term, data: Dataset, exact: bool = False):
    """``rss(v)``: the residual sum of squares when the shaped ``term``'s column
    at shape ``v`` joins a design with orthonormal basis ``Q`` (rows of
    ``tau.ravel()``) and residual ``r``.

    The column lives on its joint's rows only, and ``r`` is orthogonal to
    ``Q``, so by default each value costs a product of those rows of ``Q``
    with it: ``rss = |r|^2 - (r.g)^2 / (|g|^2 - |Q^T g|^2)``. Its round-off
    is that of ``|r|^2``; ``exact`` projects the column off ``Q`` on every row
    instead (twice), for a fit near round-off (:func:`refined_shape`)."""
    effect, joint = EFFECTS[term.name], term.joint
    rows = slice(joint, None, data.dof)
    Qj, rj = np.ascontiguousarray(Q[rows]), r[rows]
    sign = data.velocity_sign()[:, joint]
    rr = float(r @ r)

    def rss(v: float) -> float:
        g = effect.numeric(data.q[:, joint], data.qd[:, joint], v, sign)
        if exact:
            column = np.zeros(len(r))
            column[rows] = g
            column = project_off(Q, column)
            cc = float(column @ column)
            return max(rr - float(r @ column) ** 2 / cc, 0.0) if cc > 0 else rr
        a = Qj.T @ g
        gg, part = float(g @ g), float(g @ g) - float(a @ a)
        if not part > 1e-12 * gg:  # (nearly) in the design already: it explains nothing more
            return rr
        return max(rr - float(rj @ g) ** 2 / part, 0.0)

    return rss


def refined_shape(Q: np.ndarray, r: np.ndarray, term: Term, data: Dataset) -> float:
    """The shape of ``term`` where its column fits ``r`` best beside ``Q``
    (:func:`best_shape` on :func:`shape_rss`); where that fit leaves less than
    :data:`NEAR_EXACT` of ``|r|^2``, the shape is refined again near it with
    every row projected, so that round-off does not decide it."""
    rss = shape_rss(Q, r, term, data)
    v = best_shape(rss, term.shape)
    if rss(v) <= NEAR_EXACT * float(r @ r):
        v = best_shape(shape_rss(Q, r, term, data, exact=True), v, factor=1.01)
    return v


def refinable(term: Term) -> bool:
    """Whether ``term``'s shape is on a continuous scale, to refine (a Stribeck
    velocity), rather than one of its effect's :attr:`~bench.physics.effects.Effect.grid`
    (a whole number of periods, each value a term of its own)."""
    return term.shape is not None and EFFECTS[term.name].grid is None


def at_limit(shape: float) -> bool:
    """Whether ``shape`` sits at an end of :data:`SHAPE_LIMITS` (within 1 %)."""
    lo, hi = SHAPE_LIMITS
    return shape <= lo * 1.01 or shape >= hi / 1.01
