"""Stacking the candidates on their held-out predictions: Breiman's weights
against a general solver's optimum of the same objective, the nested
validation that keeps a fold's own predictions out of its weights, and the
weights the tuning's held-out predictions and a model file carry."""

from __future__ import annotations

import numpy as np
import pytest
import cvxpy as cp

from bench.core.budget import Budget
from bench.core.data import mse
from bench.evaluation.stacking import stack, weights
from bench.evaluation.tuning import tune
from tests.evaluation.test_tuning import Poly, _trajectories


def _candidates(seed: int = 0, n: int = 240):
    rng = np.random.default_rng(seed)
    target = rng.normal(size=(n, 2))
    fold = np.repeat(np.arange(3), [60, 80, 100])
    good = target + 0.1 * rng.normal(size=target.shape)
    biased = 0.5 * target + 0.3
    noise = rng.normal(size=target.shape)
    return target, fold, [good, biased, noise]


def _objective(predictions, target, fold):
    def objective(w):
        combined = sum(wk * p for wk, p in zip(w, predictions))
        return np.mean([mse(combined[fold == k], target[fold == k]) for k in np.unique(fold)])
    return objective


def test_the_weights_minimise_the_mean_fold_mse_over_the_convex_combinations():
    target, fold, predictions = _candidates()
    objective = _objective(predictions, target, fold)
    w = weights(predictions, target, fold)
    assert (w >= 0).all() and w.sum() == pytest.approx(1.0, abs=1e-12)
    # against cvxpy's solution of the same program, and against every point of a fine grid of the simplex
    x = cp.Variable(3, nonneg=True)
    cp.Problem(cp.Minimize(sum(cp.sum_squares(sum(x[j] * predictions[j][fold == k] for j in range(3))
                                              - target[fold == k]) / target[fold == k].size for k in range(3)) / 3),
               [cp.sum(x) == 1]).solve()
    np.testing.assert_allclose(w, x.value, atol=1e-5)
    grid = [(a, b, 1 - a - b) for a in np.linspace(0, 1, 101) for b in np.linspace(0, 1 - a, max(1, round((1 - a) * 100)) + 1)]
    assert objective(w) <= min(objective(np.array(g)) for g in grid) + 1e-12
    assert w[0] > 0.8 and w[2] < 0.05  # the good candidate carries the stack, noise gets next to nothing


def test_the_stack_mixes_and_never_rescales():
    # two candidates each off by a gain the other way: a convex stack mixes them back to the target; a third that
    # is the target scaled by 1.04 cannot be scaled back, and the stack is never worse than its best candidate
    target, fold, _ = _candidates()
    w = weights([0.9 * target, 1.1 * target], target, fold)
    np.testing.assert_allclose(w, [0.5, 0.5], atol=1e-7)
    scaled = [1.04 * target, 1.5 * target]
    w = weights(scaled, target, fold)
    np.testing.assert_allclose(w, [1.0, 0.0], atol=1e-7)


def test_the_nested_validation_scores_each_fold_with_the_weights_of_the_others():
    target, fold, predictions = _candidates()
    s = stack(["good", "biased", "noise"], predictions, target, fold)
    for k in range(3):
        others = fold != k
        w = weights([p[others] for p in predictions], target[others], fold[others])
        assert s["fold_mse"][k] == pytest.approx(mse(sum(wk * p[fold == k] for wk, p in zip(w, predictions)),
                                                     target[fold == k]), rel=1e-12)
    assert s["validation_mse"] == pytest.approx(np.mean(s["fold_mse"]))
    assert s["validation_mse"] >= s["in_sample_mse"]  # the nesting takes back what the weights' own fit flatters
    assert set(s["weights"]) == {"good", "biased", "noise"}
    # a candidate that is the target exactly takes the whole stack
    exact = stack(["exact", "noise"], [target, predictions[2]], target, fold)
    assert exact["weights"]["exact"] == pytest.approx(1.0) and exact["weights"]["noise"] == pytest.approx(0.0, abs=1e-9)
    assert exact["validation_mse"] == pytest.approx(0.0, abs=1e-20)


def test_the_tunings_held_out_predictions_are_the_kept_combinations_on_each_fold():
    train = _trajectories()
    tuned = tune(Poly, {}, train, "indirect", 0, Budget(steps=1))
    held = tuned.held_out
    chosen = next(r for r in tuned.details["combinations"] if r["hyperparameters"] == tuned.details["chosen"])
    assert len(held["index"]) == len(held["fold"]) == len(held["prediction"])
    for k, fold_mse in enumerate(chosen["fold_mse"]):
        inside = held["fold"] == k
        assert fold_mse == pytest.approx(mse(held["prediction"][inside], train.tau[held["index"][inside]]), rel=1e-5)
    assert len(np.unique(held["index"])) == len(held["index"])  # each sample scored once
