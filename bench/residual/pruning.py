"""What the loop does to its effects after each joint refit: drop the
redundant ones, refine the shaped ones' nonlinear parameter, and drop the
ones the refit made impossible. Each works through the model's refit
strategy (:mod:`bench.residual.strategies`)."""

from __future__ import annotations

import math

import numpy as np

from bench.core.data import Dataset
from bench.core.effects import EFFECTS
from bench.core.regression import fit_statistics
from bench.core.terms import Term
from bench.residual.candidates import admissible, label
from bench.residual.model import LoopModel
from bench.residual.selection import MIN_BIC_DROP, ROUNDOFF, best_shape, bic
from bench.residual.strategies import Strategy
from bench.runner.progress import Report


def prune(strategy: Strategy, model: LoopModel, train: Dataset, report: Report) -> tuple[LoopModel, list[str]]:
    """Backward elimination after a joint refit: drop an effect whose removal
    raises the BIC by less than :data:`MIN_BIC_DROP` (it became redundant with
    the refitted model), then refit; repeat until every effect holds."""
    removed = []
    while model.effects:
        target, F = strategy.problem(model, train)
        y = target.ravel()
        n, k = len(y), F.shape[1]
        first = k - len(model.effects)  # the effects' columns come last
        # residual sums below round-off are equal: their ratios are floating-point noise
        floor = ROUNDOFF * float(np.mean(train.tau**2)) * n
        rss_all = max(fit_statistics(F, y)[2], floor)
        weakest, weakest_gain = None, math.inf
        for i in range(len(model.effects)):
            rss_without = max(fit_statistics(np.delete(F, first + i, axis=1), y)[2], floor)
            gain = bic(rss_without, n, k - 1) - bic(rss_all, n, k)
            if gain < weakest_gain:
                weakest, weakest_gain = i, gain
        if weakest_gain >= MIN_BIC_DROP:
            break
        gone = model.effects[weakest]
        removed.append(label(gone))
        report(f"  dropping {label(gone)}: redundant after the joint refit (BIC gain {weakest_gain:.3g})")
        model = strategy.refit(model, train, model.effects[:weakest] + model.effects[weakest + 1:])
    return model, removed


def _shape_rss(strategy: Strategy, model: LoopModel, train: Dataset, index: int):
    """``rss(v)``: the residual sum of squares of the linear problem
    (:meth:`Strategy.problem`) with effect ``index``'s nonlinear parameter at ``v``."""
    target, F = strategy.problem(model, train)
    y = target.ravel()
    column = F.shape[1] - len(model.effects) + index
    term = model.effects[index]

    def rss(v: float) -> float:
        F[:, column] = EFFECTS[term.name].numeric_torque(train, term.joint, v).ravel()
        return fit_statistics(F, y)[2]

    return rss, len(y), F.shape[1]


def refine_shapes(strategy: Strategy, model: LoopModel, train: Dataset, report: Report) -> LoopModel:
    """Each shaped effect's nonlinear parameter (a Stribeck velocity) by a
    bounded scalar search of the residual sum of squares, the linear
    coefficients refitted at each value (variable projection), near where it
    stands (:func:`~bench.residual.selection.best_shape`); then a joint refit."""
    for i, term in enumerate(model.effects):
        if term.shape is None:
            continue
        v = best_shape(_shape_rss(strategy, model, train, i)[0], term.shape)
        refined = EFFECTS[term.name].term(term.joint, shape=v)
        report(f"  {label(term)}: {EFFECTS[term.name].shaped} refined to {v:.5g}")
        model = strategy.refit(model, train, model.effects[:i] + [refined] + model.effects[i + 1:])
    return model


def shape_stderr(strategy: Strategy, model: LoopModel, train: Dataset) -> dict[Term, float]:
    """The standard error of each shaped effect's parameter, from the
    curvature of the residual sum of squares: ``sqrt(2 sigma^2 / rss''(v))``."""
    out = {}
    for i, term in enumerate(model.effects):
        if term.shape is None:
            continue
        rss, n, k = _shape_rss(strategy, model, train, i)
        v, h = term.shape, 1e-3 * term.shape
        r0 = rss(v)
        curvature = (rss(v + h) - 2 * r0 + rss(v - h)) / h**2
        sigma2 = r0 / max(n - k - 1, 1)
        out[term] = math.sqrt(2 * sigma2 / curvature) if curvature > 0 else float("inf")
    return out


def drop_inadmissible(strategy: Strategy, model: LoopModel, train: Dataset, report: Report) -> tuple[LoopModel, list[tuple]]:
    """Drop effects whose coefficient the joint refit made impossible (a
    negative friction, say), one at a time, refitting after each; returns
    the model and the dropped ``(term, coefficient, stderr)``."""
    dropped = []
    while True:
        bad = [i for i, (t, c) in enumerate(zip(model.effects, model.coef)) if not admissible(t, c)]
        if not bad:
            return model, dropped
        i = bad[0]
        dropped.append((model.effects[i], float(model.coef[i]), float(model.stderr[i])))
        report(f"  dropping {label(model.effects[i])}: the joint refit gives it an impossible coefficient {model.coef[i]:.4g}")
        model = strategy.refit(model, train, model.effects[:i] + model.effects[i + 1:])
