"""A method's hyperparameters chosen on the training data alone, by the
suite's one validation protocol (:mod:`bench.core.folds`), each combination
validated at the work its final fit gets.

Each method declares a small search space (:attr:`methods.base.Method.search_space`:
values per hyperparameter, at most :data:`MAX_COMBINATIONS` combinations in
all, as SRBench allows: La Cava et al., 2021). A tuned fit

1. folds the training data (:func:`bench.core.folds.folds`, or a protocol in
   state space of :mod:`bench.core.protocols`; at most :data:`MAX_FOLDS` folds);
2. searches by **successive halving over work** (Jamieson & Talwalkar, 2016;
   Li et al., 2018): every combination is fitted on every fold with a third
   of a third … of the final fit's steps, the best third (by the mean
   validation MSE over the folds) go on with three times the steps, and so
   on until **one** is left, fitted on every fold with exactly the steps its
   final fit will do. A method with nothing to search has that one rung only;
3. scores the method by that survivor's mean validation MSE at the final
   fit's work (:data:`SCORE_RULE`): not the least score over the search, and
   not the score of a fit less trained than the model kept. The lower rungs
   that kept the survivor scored the same folds, so a little of the search's
   optimism remains; ``bench study selection`` measures it against the test;
4. fits the survivor on all the training data with the same steps.

Beside each fold's validation MSE the search keeps its MSE on the **farther
half** of the fold's scored samples (:data:`FAR_RULE`): those at least the
fold's median distance from the states it is fitted on
(:func:`bench.evaluation.domain.held_out_distances`, as the domain report measures its reach). It chooses nothing; it shows
whether a ranking holds as validation moves away from the fit
(``bench select``'s page).

The final fit's steps are the work budget's, under ``--steps``. Under a time
budget they are measured: a probe fits the first combination on the first
fold for one step (kept as that fold's fit where a rung asks for one step)
and, where that was quicker, for :data:`PROBE_SHARE` of the seconds; a straight line (seconds against
steps × the share of the samples fitted) is drawn through the probe and every
fit since, and before each rung the steps are planned so that what is left of
the search and the final fit end within :data:`PLANNED_SHARE` of the budget.
No fit of the search starts once ``1 - MIN_FINAL_SHARE`` of it has passed (a
combination left unfitted is recorded so and not chosen).

scikit-learn's ``HalvingGridSearchCV`` ends with ``factor`` combinations at a
rung of ``min_resources × factor^k`` and cannot re-plan the steps from the
fits it measured, so the rungs are counted here; each rung's fits are plain
fits of the method on the folds' samples. A fit of one combination, fold and
step count is done once and reused where two rungs ask for the same steps.

What it chose, every combination's validation MSE per fold at the highest rung
it reached, the rungs and the folds are the record's ``details.tuning``; its
``work`` gives the steps and seconds of the chosen combination's fold fits
beside those of the final fit.

The chosen combination's predictions on each fold's scored samples (its
held-out predictions: :attr:`Tuned.held_out`) are kept for the model file, from
which ``bench select`` stacks its candidates (:mod:`bench.evaluation.stacking`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from bench.core.budget import SECONDS, Budget
from bench.core.data import Dataset, mse
from bench.core.errors import ConfigError
from bench.core.folds import Folds
from bench.core.protocols import folds
from bench.evaluation.domain import held_out_distances
from bench.physics.system import System

#: at most this many combinations a method's search space may hold
MAX_COMBINATIONS = 10
#: folds the search uses at most
MAX_FOLDS = 4
#: successive halving's factor: a rung keeps the best third of its combinations, with three times the steps
ETA = 3
#: the share of a time budget the probe that measures a fit's pace has
PROBE_SHARE = 0.05
#: the share of a time budget the search and the final fit are planned to end within
PLANNED_SHARE = 0.8
#: the least share of a time budget left to the final fit: no fit of the search starts past the rest
MIN_FINAL_SHARE = 0.25
#: why a combination was not fitted where the search's share of a time budget ended first
OUT_OF_TIME = "not fitted: the search's share of the budget ended before it"
#: what a fold's second figure scores
FAR_RULE = ("the mean over the folds of the MSE on the farther half of each fold's scored samples (those at least "
            "the fold's median distance, in q and q̇, from the states it is fitted on)")
#: what the record and the tables call a tuned run
PROTOCOL = "tuned on the training trajectories"
#: how a tuned method is scored
SCORE_RULE = ("the mean validation MSE over the folds of the one combination successive halving kept, each fold fit "
              "doing the final fit's steps (not the least score over the search; the rungs that kept it scored the "
              "same folds)")


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


def prepare(method_cls, settings: dict, train: Dataset, experiment: str, device: str = "cpu", *, seed: int = 0,
            system: System | None = None, protocol: str | None = None) -> float:
    """The one-time work of every combination of the search, done before the
    run's budget starts as a fit's own is: compiling a step for its shapes
    (once a process: :meth:`methods.base.Method.prepare`), and the work on each
    fold's fitted samples and on all the training data that does not depend
    on the budget (a hybrid's prior: :meth:`methods.base.Method.prepare_samples`,
    kept for the search's fits); returns its seconds. :func:`tune` does not
    repeat it: a run's prepare phase calls this first."""
    t0 = time.perf_counter()
    samples = [train.subset(fold.fit) for fold in folds(train, protocol, MAX_FOLDS)] + [train]
    for choice in _grid(method_cls, settings)[1]:
        method = method_cls(**{**settings, **choice}).use_device(device)
        method.prepare(train, experiment)
        for part in samples:
            method.prepare_samples(part, experiment, seed, system)
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


def rungs(combinations: int) -> list[tuple[int, float]]:
    """Successive halving's rungs for ``combinations``: ``(combinations fitted, share of the final fit's steps)``,
    the last rung one combination at the whole steps (``[(8, 1/9), (3, 1/3), (1, 1)]`` for 8)."""
    counts = [combinations]
    while counts[-1] > 1:
        counts.append(math.ceil(counts[-1] / ETA))
    top = len(counts) - 1
    return [(n, 1.0 / ETA ** (top - k)) for k, n in enumerate(counts)]


@dataclass
class _Fit:
    """A combination's fits on every fold at one step count."""

    mse: list = field(default_factory=list)
    far: list = field(default_factory=list)
    steps: list = field(default_factory=list)
    seconds: list = field(default_factory=list)
    #: each fold's predictions on its scored samples
    predictions: list = field(default_factory=list)
    failed: str | None = None

    @property
    def score(self) -> float | None:
        """The mean validation MSE over the folds; ``None`` where a fold failed or was not finite."""
        if self.failed or not self.mse or not all(math.isfinite(v) for v in self.mse):
            return None
        return float(np.mean(self.mse))

    @property
    def far_score(self) -> float | None:
        """The mean over the folds of the MSE on each fold's farther half (:data:`FAR_RULE`)."""
        if self.score is None or len(self.far) != len(self.mse) or not all(math.isfinite(v) for v in self.far):
            return None
        return float(np.mean(self.far))


def farther_half(train: Dataset, fold) -> np.ndarray:
    """Which of ``fold``'s scored samples lie at least the fold's median distance from the states it is fitted
    on (a mask over ``train.subset(fold.score)``)."""
    distance = held_out_distances(train, fold)
    return distance >= np.median(distance) if len(distance) else np.zeros(0, dtype=bool)


class _Search:
    """The fits of one search: each combination fitted and scored on each fold at a step count, once, and the
    seconds they took, from which the steps a time budget allows are planned."""

    def __init__(self, make: Callable[[dict], object], train: Dataset, experiment: str, seed: int,
                 system: System | None, fold_set: Folds):
        self.make, self.train, self.experiment, self.seed, self.system = make, train, experiment, seed, system
        self.folds = fold_set
        self.fits: dict[tuple, _Fit] = {}
        #: (steps x share of the samples fitted, seconds) of every fit so far
        self.observed: list[tuple[float, float]] = []
        self.shares = [float(np.mean(f.fit)) for f in fold_set]
        #: fits done before the rungs (the probe's), by (combination, steps, fold), for the rung that asks for them
        self.kept: dict[tuple, tuple] = {}
        self._far: dict[int, np.ndarray] = {}

    def far(self, k: int) -> np.ndarray:
        """:func:`farther_half` of fold ``k``, measured once."""
        if k not in self._far:
            self._far[k] = farther_half(self.train, self.folds[k])
        return self._far[k]

    def _one(self, choice: dict, fold: int, budget: Budget):
        t0 = time.perf_counter()
        method = self.make(choice)
        fold_ = self.folds[fold]
        method.fit(self.train.subset(fold_.fit), self.experiment, self.seed, budget, system=self.system)
        seconds = time.perf_counter() - t0
        steps = method.fit_info.get("steps")
        self.observed.append(((steps or 0) * self.shares[fold], seconds))
        return method, steps, seconds

    def probe(self, choice: dict, seconds: float) -> dict:
        """Fits of ``choice`` on the first fold for the plan's line: one step (what a fit costs however short,
        kept as that fold's fit where a rung asks for one step), then, where that took less than ``seconds``, as
        many steps as ``seconds`` allow."""
        try:
            method, done, once = self._one(choice, 0, Budget(steps=1))
            self.kept[(_key(choice), 1, 0)] = (method, done, once)
            if once >= seconds:  # a step costs the probe's time already (a round of the loop): one point it is
                return {"one_step_seconds": round(once, 3), "seconds": round(once, 3), "steps": done}
            _, steps, took = self._one(choice, 0, Budget(seconds=seconds))
        except Exception as exc:  # the search records the combination's failure when it fits it
            return {"seconds": round(seconds, 3), "failed": f"{type(exc).__name__}: {exc}"[:300]}
        return {"one_step_seconds": round(once, 3), "seconds": round(took, 3), "steps": steps}

    def score(self, choice: dict, steps: int, deadline: float) -> _Fit:
        key = (_key(choice), steps)
        if key in self.fits:
            return self.fits[key]
        out = self.fits[key] = _Fit()
        for k, fold in enumerate(self.folds):
            if time.perf_counter() > deadline:
                out.failed = OUT_OF_TIME
                break
            try:
                kept = self.kept.pop((_key(choice), steps, k), None)
                method, done, seconds = kept or self._one(choice, k, Budget(steps=steps))
                part = self.train.subset(fold.score)
                prediction = np.asarray(method.predict(part, self.experiment), dtype=np.float64)
                target = np.asarray(part.target(self.experiment), dtype=np.float64)
                out.mse.append(float(mse(prediction, target)))
                far = self.far(k)
                out.far.append(float(mse(prediction[far], target[far])) if far.any() else math.nan)
                out.steps.append(done)
                out.seconds.append(round(seconds, 3))
                out.predictions.append(prediction.astype(np.float32))
            except Exception as exc:  # a combination that fails is not chosen; the record says why
                out.failed = f"{type(exc).__name__}: {exc}"[:300]
                break
        return out

    def plan(self, schedule: list[tuple[int, float]], seconds: float) -> int:
        """The final fit's steps that let ``schedule``'s rungs (on every fold) and the final fit (on all the
        samples) end within ``seconds``, by the line through the fits observed so far (at least one step)."""
        units = np.array([u for u, _ in self.observed])
        took = np.array([s for _, s in self.observed])
        if not len(units) or not (units > 0).any():
            return 1
        if len(set(units.tolist())) >= 2:
            slope, overhead = np.polyfit(units, took, 1)
        else:
            slope, overhead = 0.0, 0.0
        if not (slope > 0) or overhead < 0:  # a line that does not describe the fits: seconds per unit, no overhead
            slope, overhead = float(took.sum() / units.sum()), 0.0
        fits = sum(n for n, _ in schedule) * len(self.folds) + 1
        work = sum(n * share for n, share in schedule) * sum(self.shares) + 1.0
        return max(1, int((seconds - fits * overhead) / (slope * work)))


@dataclass
class Tuned:
    """A tuned fit: the method fitted on all the training data with the chosen
    hyperparameters, and the record's ``details.tuning``."""

    method: object
    details: dict
    #: the kept combination's held-out predictions (:func:`held_out`); ``None`` where a fold has none
    held_out: dict | None = None


def tune(method_cls, settings: dict, train: Dataset, experiment: str, seed: int, budget: Budget,
         system: System | None = None, device: str = "cpu", report: Callable[[str], None] | None = None,
         protocol: str | None = None) -> Tuned:
    """Choose ``method_cls``'s hyperparameters from its search space on ``train``
    (see the module docstring), on top of ``settings`` (its configuration and
    the user's ``--set``; a searched hyperparameter the user set stays as set and
    is not searched), and fit the choice on all of ``train`` at the steps it was
    validated at. ``protocol`` names the folds (:func:`bench.core.protocols.folds`; default those of
    time). ``report`` is given a line as the search goes."""
    say = report or (lambda line: None)
    fixed = dict(settings)
    searched, grid = _grid(method_cls, fixed)  # nothing to search: the one configuration is still validated

    def make(choice: dict):
        return method_cls(**{**fixed, **choice}).use_device(device)

    t0 = time.perf_counter()
    timed = budget.kind == SECONDS
    fold_set = folds(train, protocol, MAX_FOLDS)
    search = _Search(make, train, experiment, seed, system, fold_set)
    schedule = rungs(len(grid))
    deadline = t0 + (1.0 - MIN_FINAL_SHARE) * budget.seconds if timed else math.inf
    end = t0 + PLANNED_SHARE * budget.seconds if timed else math.inf
    probe = search.probe(grid[0], PROBE_SHARE * budget.seconds) if timed else None
    say(f"tuning {method_cls.name}: {len(grid)} combinations x {len(fold_set)} folds ({fold_set.describe()}), "
        f"by successive halving over {len(schedule)} rung(s) of work"
        + (f"; a probe did {probe.get('steps')} steps in {probe['seconds']:g} s" if probe else ""))
    survivors, reached, table = list(grid), {}, []
    final_steps, top, done = budget.steps, len(schedule) - 1, 0
    for k, (count, share) in enumerate(schedule):
        if timed:  # re-planned from every fit so far, so that the last rung and the final fit end in time
            final_steps = search.plan(schedule[k:], end - time.perf_counter())
            if k and round(final_steps * share) <= done:
                # the time left affords no rung with more steps than the last: the search ends there, and the
                # final fit does that rung's steps
                final_steps, top = done, k - 1
                say(f"  the time left affords no rung of more than {done} steps: the search ends at rung {k}")
                break
        steps = max(1, round(final_steps * share))
        done = steps
        fits = {_key(c): search.score(c, steps, deadline) for c in survivors}
        for c in survivors:
            reached[_key(c)] = (k, steps)
        ranked = sorted((c for c in survivors if fits[_key(c)].score is not None),
                        key=lambda c: fits[_key(c)].score)
        table.append({"steps": steps, "combinations": len(survivors), "scored": len(ranked)})
        say(f"  rung {k + 1} of {len(schedule)}, {steps} steps a fold fit: "
            + "; ".join(f"{_words(c) or 'its configuration'} "
                        + (format(fits[_key(c)].score, '.4g') if fits[_key(c)].score is not None
                           else f"failed ({fits[_key(c)].failed or 'non-finite validation MSE'})") for c in survivors))
        if not ranked:
            break
        survivors = ranked[:schedule[k + 1][0]] if k + 1 < len(schedule) else ranked[:1]
    rows = [_row(c, *reached[_key(c)], search.fits[(_key(c), reached[_key(c)][1])]) for c in grid]
    whole = sorted((r for r in rows if r["rung"] == top and r["validation_mse"] is not None),
                   key=lambda r: r["validation_mse"])
    search_seconds = time.perf_counter() - t0
    note = None
    if whole:
        chosen_row = whole[0]
        if len(whole) > 1:
            note = (f"the time budget ended the search at rung {top + 1} of {len(schedule)}: the best of its "
                    f"{len(whole)} combinations is chosen, its score the least of theirs, at the final fit's steps")
    else:
        usable = [r for r in rows if r["validation_mse"] is not None]
        chosen_row = max(usable, key=lambda r: (r["rung"], -r["validation_mse"])) if usable else None
        note = ("every combination failed in the search: the method's own defaults are fitted" if chosen_row is None
                else f"no combination was scored at the last rung reached (the search's share of the budget "
                     f"ended): the best at {chosen_row['steps']} steps is chosen, and the final fit does those steps")
    chosen = chosen_row["hyperparameters"] if chosen_row else {}
    final = Budget(seconds=budget.seconds, steps=budget.steps) if not timed else \
        Budget(steps=chosen_row["steps"] if chosen_row else final_steps)
    say(f"tuning {method_cls.name}: chose {_words(chosen) or 'its defaults'}; fitting it on all the training data "
        f"({final.describe()})")
    method = make(chosen)
    method.fit(train, experiment, seed, final, system=system)
    details = {"protocol": PROTOCOL, "space": _space(method_cls), "searched": searched, "chosen": chosen,
               "validation_mse": chosen_row["validation_mse"] if chosen_row else None, "score": SCORE_RULE,
               "validation_far_mse": chosen_row["validation_far_mse"] if chosen_row else None, "far": FAR_RULE,
               "folds": fold_set.to_json(), "rungs": table, "final_budget": final.to_json(), "combinations": rows,
               "search_seconds": round(search_seconds, 3),
               "work": {"fold_steps": chosen_row["fold_steps"] if chosen_row else [],
                        "fold_fit_seconds": chosen_row["fold_fit_seconds"] if chosen_row else [],
                        "final_steps": method.fit_info.get("steps"),
                        "final_fit_seconds": round(method.fit_info.get("fit_seconds") or 0.0, 3)}}
    if probe:
        details["probe"] = probe
    if len(rows) == 1 and not note:
        note = ("nothing to tune: the method declares no search space" if not _space(method_cls) else
                "nothing to tune: the hyperparameters of its search space are set") + "; its configuration is validated"
    if note:
        details["note"] = note
    kept = search.fits.get((_key(chosen), chosen_row["steps"])) if chosen_row else None
    return Tuned(method, details, held_out(fold_set, kept))


def held_out(fold_set: Folds, fit: _Fit | None) -> dict | None:
    """A combination's predictions on every fold's scored samples, in the folds' order: ``index`` (each
    prediction's sample in the training data), ``fold`` (its fold) and ``prediction``; ``None`` where the
    combination was not scored on every fold."""
    if fit is None or fit.score is None or len(fit.predictions) != len(fold_set):
        return None
    index = [np.flatnonzero(f.score) for f in fold_set]
    return {"index": np.concatenate(index).astype(np.int64),
            "fold": np.concatenate([np.full(len(i), k, dtype=np.int64) for k, i in enumerate(index)]),
            "prediction": np.concatenate(fit.predictions).astype(np.float32)}


def _row(choice: dict, rung: int, steps: int, fit: _Fit) -> dict:
    """A combination's line of the record: its figures at the highest rung it reached."""
    row = {"hyperparameters": dict(choice), "validation_mse": fit.score, "fold_mse": [
        v if math.isfinite(v) else None for v in fit.mse], "validation_far_mse": fit.far_score,
           "fold_far_mse": [v if math.isfinite(v) else None for v in fit.far], "rung": rung, "steps": steps,
        "fold_steps": fit.steps, "fold_fit_seconds": fit.seconds}
    if fit.score is None:
        row["failed"] = fit.failed or "non-finite validation MSE"
    return row


def _key(choice: dict) -> tuple:
    return tuple(sorted((k, repr(v)) for k, v in choice.items()))


def _space(method_cls) -> dict:
    return {k: list(v) for k, v in (getattr(method_cls, "search_space", {}) or {}).items()}


def _words(choice: dict) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in sorted(choice.items()))
