"""Stacking: the candidates' predictions combined with weights chosen on their
held-out predictions (Breiman, "Stacked regressions", Machine Learning 24, 1996;
the super learner of van der Laan, Polley & Hubbard, 2007).

Each tuned candidate keeps its predictions on every validation fold's scored
samples, made by its fold fits at the final fit's work
(:attr:`bench.evaluation.tuning.Tuned.held_out`). The stack's weights are the
super learner's: nonnegative and summing to one, by least squares of the
training targets on those predictions, each fold's samples weighted by one over
their count, so that the least squares minimise the mean over the folds of each
fold's MSE, as a candidate's validation MSE is. Breiman's nonnegative least
squares alone may scale the torque as well as mix the candidates (a sum of
weights of 1.04 on one of the development set's cases, a sensor's gain, doubled
the stack's test MSE); a convex combination only mixes them, and its MSE on any
data is at most the weighted mean of theirs. The weights solve a quadratic
program of one variable a candidate (``scipy.optimize.minimize``'s SLSQP). The
stack predicts the weighted sum of the candidates' final models.

Fitting the weights on the predictions they are then scored on would flatter
the stack. Its **validation MSE** is therefore nested: each fold is scored with
the weights fitted on the other folds' predictions, and the figure is the mean
over the folds, comparable with each candidate's. (The candidates' own
predictions still come from fits whose hyperparameters the same folds chose,
as every candidate's validation MSE does.)
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from bench.core.data import mse


def weights(predictions: list[np.ndarray], target: np.ndarray, fold: np.ndarray) -> np.ndarray:
    """The convex weights of ``predictions`` (one array per candidate, shaped as ``target``) that fit
    ``target`` best, each sample weighted by one over its ``fold``'s count."""
    _, label, counts = np.unique(fold, return_inverse=True, return_counts=True)
    scale = 1.0 / np.sqrt(counts[label]).reshape((-1,) + (1,) * (target.ndim - 1))
    design = np.stack([np.broadcast_to(scale, p.shape).ravel() * np.asarray(p, np.float64).ravel()
                       for p in predictions], axis=1)
    goal = (np.broadcast_to(scale, target.shape) * np.asarray(target, np.float64)).ravel()
    k = design.shape[1]
    gram, cross = design.T @ design, design.T @ goal
    unit = max(float(np.trace(gram)) / k, 1e-300)  # the quadratic's scale, so that the solver's tolerance is relative
    solved = minimize(lambda w: (w @ gram @ w - 2.0 * cross @ w) / unit, np.full(k, 1.0 / k),
                      jac=lambda w: 2.0 * (gram @ w - cross) / unit, method="SLSQP", bounds=[(0.0, 1.0)] * k,
                      constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1.0, "jac": lambda w: np.ones(k)}],
                      options={"ftol": 1e-15, "maxiter": 1000})
    w = np.clip(solved.x, 0.0, None)
    return w / w.sum()


def combine(predictions: list[np.ndarray], w: np.ndarray) -> np.ndarray:
    """The weighted sum of ``predictions``."""
    return sum(float(wk) * np.asarray(p, np.float64) for wk, p in zip(w, predictions))


def stack(names: list[str], predictions: list[np.ndarray], target: np.ndarray, fold: np.ndarray) -> dict:
    """The stack of the candidates ``names`` from their held-out ``predictions``: its convex ``weights`` (by name,
    fitted on every fold), its nested ``validation_mse`` (each fold scored with the weights of the others) and
    that figure's ``validation_stderr`` over the folds, each fold's nested MSE (``fold_mse``), and
    ``in_sample_mse``, the weights' own fit (which the nesting corrects)."""
    folds = np.unique(fold)
    nested = []
    for k in folds if folds.size > 1 else ():
        inside = fold == k
        w = weights([p[~inside] for p in predictions], target[~inside], fold[~inside])
        nested.append(mse(combine([p[inside] for p in predictions], w), target[inside]))
    w = weights(predictions, target, fold)
    whole = combine(predictions, w)
    in_sample = float(np.mean([mse(whole[fold == k], target[fold == k]) for k in folds]))
    finite = nested and all(math.isfinite(v) for v in nested)
    return {"weights": {n: float(v) for n, v in zip(names, w)},
            "validation_mse": float(np.mean(nested)) if finite else None,
            "validation_stderr": float(np.std(nested, ddof=1) / np.sqrt(len(nested))) if finite and len(nested) > 1
            else None,
            "fold_mse": nested, "in_sample_mse": in_sample}
