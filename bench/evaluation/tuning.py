"""A method's hyperparameters chosen on the training data alone, by the
suite's one validation protocol (:mod:`bench.core.folds`).

Each method declares a small search space (:attr:`methods.base.Method.search_space`:
values per hyperparameter, at most :data:`MAX_COMBINATIONS` combinations in
all, as SRBench allows: La Cava et al., 2021). A tuned fit

1. folds the training data (:func:`bench.core.folds.folds`, at most
   :data:`MAX_FOLDS` folds of whole trajectories, or spans in time of one
   trajectory with the torque's autocorrelation time between what a fold
   fits and what it scores);
2. fits every combination on every fold and scores it on the fold's scored
   samples: scikit-learn's ``GridSearchCV``, with the folds as its ``cv``;
3. chooses the combination with the lowest validation MSE (the mean over the
   folds; a combination that fails or predicts non-finite torques on any fold
   is not chosen), and fits it on all the training data. A method with
   nothing to search has its one configuration validated the same way, so
   that every tuned run says what validation made of it.

The fit's budget covers all of it. Under a time budget each fit of the search
has an equal part of ``1 - FINAL_SHARE`` of the seconds, no fit starts once
that share has passed (a combination left unfitted is recorded so and not
chosen), and the final fit has what is left, at least :data:`MIN_FINAL_SHARE`
of the budget; under a work budget every fit, in the search and the final
one, does the budget's steps (the work a method is compared by), so that a
tuned run is as replayable as any. What it chose, every combination's validation MSE per
fold, and the folds are the record's ``details.tuning``; its ``work`` gives the steps and
seconds of the chosen combination's fold fits beside those of the final fit, so that a
reader sees how much less trained the validated fits were than the model kept.
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from bench.core.budget import SECONDS, Budget
from bench.core.data import Dataset, mse
from bench.core.errors import ConfigError
from bench.core.folds import folds
from bench.physics.system import System

#: at most this many combinations a method's search space may hold
MAX_COMBINATIONS = 10
#: folds of whole trajectories the search uses at most
MAX_FOLDS = 4
#: the share of a time budget the final fit has; the search has the rest
FINAL_SHARE = 0.5
#: the least share of a time budget the final fit has where the search took more than its own
MIN_FINAL_SHARE = 0.25
#: why a combination was not fitted where the search's share of a time budget ended first
OUT_OF_TIME = "not fitted: the search's share of the budget ended before it"
#: what the record and the tables call a tuned run
PROTOCOL = "tuned on the training trajectories"


def combinations(method_cls) -> list[dict]:
    """The combinations of ``method_cls``'s search space, in a fixed order
    (scikit-learn's ``ParameterGrid``); ``[]`` where it declares none."""
    space = getattr(method_cls, "search_space", {}) or {}
    if not space:
        return []
    return _product({k: list(v) for k, v in space.items()})


def _product(space: dict) -> list[dict]:
    """Every combination of ``space``'s values, in scikit-learn's ``ParameterGrid``
    order (imported here, where a search needs it: it takes about a second)."""
    from sklearn.model_selection import ParameterGrid

    return [dict(c) for c in ParameterGrid(space)]


def prepare(method_cls, settings: dict, train: Dataset, experiment: str, device: str = "cpu") -> float:
    """The one-time work of every combination of the search (compiling a step
    for its shapes, once a process: :meth:`methods.base.Method.prepare`), done
    before the run's budget starts as a fit's own is; returns its seconds."""
    t0 = time.perf_counter()
    for choice in _grid(method_cls, settings)[1]:
        method_cls(**{**settings, **choice}).use_device(device).prepare(train, experiment)
    return round(time.perf_counter() - t0, 3)


def _grid(method_cls, settings: dict) -> tuple[list[str], list[dict]]:
    """The hyperparameters searched (those of the space that ``settings`` does not set)
    and their combinations; ``[{}]`` where nothing is searched."""
    space = {k: v for k, v in _space(method_cls).items() if k not in settings}
    return sorted(space), (_product(space) if space else [{}])


def check_space(method_cls) -> None:
    """A :class:`ConfigError` where ``method_cls``'s search space holds too many
    combinations or a value its ``Config`` refuses."""
    grid = combinations(method_cls)
    if len(grid) > MAX_COMBINATIONS:
        raise ConfigError(f"{method_cls.name}: its search space holds {len(grid)} combinations, at most "
                          f"{MAX_COMBINATIONS} allowed")
    for choice in grid:
        method_cls(**choice)


class _Shared:
    """What every candidate of one search shares (the data, the budget): one
    object, not copied when scikit-learn clones a candidate."""

    def __init__(self, make: Callable[[dict], object], train: Dataset, experiment: str, seed: int, budget: Budget,
                 system: System | None, deadline: float = math.inf):
        self.make, self.train, self.experiment, self.seed = make, train, experiment, seed
        self.budget, self.system, self.deadline = budget, system, deadline
        self.failures: dict[tuple, str] = {}
        #: the work each combination's fold fits did (steps, in the folds' order), and their seconds
        self.steps: dict[tuple, list] = {}
        self.seconds: dict[tuple, list] = {}

    def __deepcopy__(self, memo):
        return self


@functools.cache
def _candidate_type() -> type:
    """:class:`_Candidate`'s type, made on first use: it is a scikit-learn estimator, and
    scikit-learn takes about a second to import, which a run that does not tune never needs."""
    from sklearn.base import BaseEstimator

    class _Candidate(BaseEstimator):
        """One combination as a scikit-learn estimator: ``X`` holds sample indices."""

        def __init__(self, shared: _Shared | None = None, choice: dict | None = None):
            self.shared = shared
            self.choice = choice

        def fit(self, X, y=None):
            s = self.shared
            self.method_ = None
            if time.perf_counter() > s.deadline:
                s.failures[_key(self.choice)] = OUT_OF_TIME
                return self
            try:
                method = s.make(self.choice)
                method.fit(s.train.subset(np.asarray(X)[:, 0]), s.experiment, s.seed, s.budget, system=s.system)
                self.method_ = method
                s.steps.setdefault(_key(self.choice), []).append(method.fit_info.get("steps"))
                s.seconds.setdefault(_key(self.choice), []).append(round(method.fit_info.get("fit_seconds") or 0.0, 3))
            except Exception as exc:  # a combination that fails is not chosen; the record says why
                s.failures[_key(self.choice)] = f"{type(exc).__name__}: {exc}"[:300]
            return self

    return _Candidate


def _key(choice: dict) -> tuple:
    return tuple(sorted((k, repr(v)) for k, v in choice.items()))


def _score(candidate, X, y=None) -> float:
    """Minus the candidate's MSE on the samples ``X``; ``nan`` where it failed or predicts non-finite values."""
    if candidate.method_ is None:
        return math.nan
    s = candidate.shared
    part = s.train.subset(np.asarray(X)[:, 0])
    return -mse(candidate.method_.predict(part, s.experiment), part.target(s.experiment))


@dataclass
class Tuned:
    """A tuned fit: the method fitted on all the training data with the chosen
    hyperparameters, and the record's ``details.tuning``."""

    method: object
    details: dict


def tune(method_cls, settings: dict, train: Dataset, experiment: str, seed: int, budget: Budget,
         system: System | None = None, device: str = "cpu", report: Callable[[str], None] | None = None) -> Tuned:
    """Choose ``method_cls``'s hyperparameters from its search space on ``train``
    (see the module docstring), on top of ``settings`` (its configuration and
    the user's ``--set``; a searched hyperparameter the user set stays as set and
    is not searched), and fit the choice on all of ``train``. ``report`` is
    given a line as the search goes."""
    say = report or (lambda line: None)
    fixed = dict(settings)
    searched, grid = _grid(method_cls, fixed)  # nothing to search: the one configuration is still validated

    def make(choice: dict):
        return method_cls(**{**fixed, **choice}).use_device(device)

    from sklearn.model_selection import GridSearchCV

    t0 = time.perf_counter()
    fold_set = folds(train, max_folds=MAX_FOLDS)
    fits = len(grid) * len(fold_set)
    each = budget.scaled((1.0 - FINAL_SHARE) / fits)
    say(f"tuning {method_cls.name}: {len(grid)} combinations x {len(fold_set)} folds ({fold_set.describe()}), "
        f"{each.describe()} a fit")
    # under a time budget no fit of the search starts past its share (each fit's own work, a hybrid's prior
    # say, may take longer than its part of it)
    deadline = t0 + (1.0 - FINAL_SHARE) * budget.seconds if budget.kind == SECONDS else math.inf
    shared = _Shared(make, train, experiment, seed, each, system, deadline)
    search = GridSearchCV(_candidate_type()(shared), {"choice": grid}, scoring=_score, cv=fold_set.indices(),
                          refit=False, error_score=math.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a failed or non-finite combination is recorded, not warned about
        search.fit(np.arange(len(train))[:, None])
    results = search.cv_results_
    rows = []
    for i, choice in enumerate(results["param_choice"]):
        per_fold = [-float(results[f"split{k}_test_score"][i]) for k in range(len(fold_set))]
        finite = all(math.isfinite(v) for v in per_fold)
        row = {"hyperparameters": dict(choice), "validation_mse": float(np.mean(per_fold)) if finite else None,
               "fold_mse": [v if math.isfinite(v) else None for v in per_fold],
               "fit_seconds": round(float(results["mean_fit_time"][i]) * len(fold_set), 3),
               "fold_steps": shared.steps.get(_key(choice), []), "fold_fit_seconds": shared.seconds.get(_key(choice), [])}
        failure = shared.failures.get(_key(choice))
        if failure or not finite:
            row["failed"] = failure or "non-finite validation MSE"
        rows.append(row)
        say(f"  {_words(choice)}: validation MSE "
            + (f"failed ({row['failed']})" if row["validation_mse"] is None else format(row["validation_mse"], ".4g")))
    usable = [r for r in rows if r["validation_mse"] is not None]
    search_seconds = time.perf_counter() - t0
    if not usable:
        chosen, note = {}, "every combination failed in the search: the method's own defaults are fitted"
    else:
        chosen, note = min(usable, key=lambda r: r["validation_mse"])["hyperparameters"], None
    if budget.kind == SECONDS:  # the final fit has what is left of the budget, and at least MIN_FINAL_SHARE of it
        left = budget.seconds - (time.perf_counter() - t0)
        final = Budget(seconds=max(left, MIN_FINAL_SHARE * budget.seconds))
    else:
        final = budget.scaled(FINAL_SHARE)
    say(f"tuning {method_cls.name}: chose {_words(chosen) or 'its defaults'}; fitting it on all the training data "
        f"({final.describe()})")
    method = make(chosen)
    method.fit(train, experiment, seed, final, system=system)
    validation = next((r["validation_mse"] for r in rows if r["hyperparameters"] == chosen), None)
    chosen_row = next((r for r in rows if r["hyperparameters"] == chosen), {})
    details = {"protocol": PROTOCOL, "space": _space(method_cls), "searched": searched, "chosen": chosen,
               "validation_mse": validation, "folds": fold_set.to_json(), "fit_budget": each.to_json(),
               "final_budget": final.to_json(), "combinations": rows, "search_seconds": round(search_seconds, 3),
               "work": {"fold_steps": chosen_row.get("fold_steps", []),
                        "fold_fit_seconds": chosen_row.get("fold_fit_seconds", []),
                        "final_steps": method.fit_info.get("steps"),
                        "final_fit_seconds": round(method.fit_info.get("fit_seconds") or 0.0, 3)}}
    if len(rows) == 1 and not note:
        note = ("nothing to tune: the method declares no search space" if not _space(method_cls) else
                "nothing to tune: the hyperparameters of its search space are set") + "; its configuration is validated"
    if note:
        details["note"] = note
    return Tuned(method, details)


def _space(method_cls) -> dict:
    return {k: list(v) for k, v in (getattr(method_cls, "search_space", {}) or {}).items()}


def _words(choice: dict) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in sorted(choice.items()))
