"""Tuning on the training data alone: every combination scored by the one
validation protocol, the best validated one chosen and fitted on all the
training data, a user's own setting left alone, a tuned run's record, table
column and replay."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
import pytest

from bench.core.budget import Budget
from bench.core.data import Dataset, mse
from bench.core.errors import ConfigError
from bench.core.folds import folds
from bench.evaluation.tuning import FAR_RULE, MAX_COMBINATIONS, MAX_FOLDS, PROTOCOL, check_space, combinations, prepare, tune
from bench.evaluation.tuning import rungs as tuning_rungs
from bench.runner.records import Record
from bench.runner.spec import RunSpec, parse_run_id, run_id
from methods import METHODS
from methods.base import Method
from methods.config import MethodConfig, Range
from tests.commandline import cli


@dataclass(frozen=True)
class PolyConfig(MethodConfig):
    degree: Annotated[int, Range(0)] = 0
    ridge: Annotated[float, Range(0)] = 0.0


class Poly(Method):
    """Each joint's torque as a polynomial of its own q, by least squares: one solve."""

    name = "toy_poly"
    Config = PolyConfig
    experiments: ClassVar[tuple[str, ...]] = ("indirect",)
    has_lagrangian: ClassVar[bool] = False
    search_space = {"degree": (0, 1, 3, 9), "ridge": (0.0, 1e3)}

    def _columns(self, data):
        return [np.vander(data.q[:, j], self.config.degree + 1) for j in range(data.dof)]

    def _fit(self, train, experiment, progress):
        self.coef = [np.zeros(self.config.degree + 1) for _ in range(train.dof)]
        while progress.step():
            self.coef = [np.linalg.solve(X.T @ X + self.config.ridge * np.eye(X.shape[1]), X.T @ train.tau[:, j])
                         for j, X in enumerate(self._columns(train))]
            progress.stop("solved")

    def _get_state(self):
        return self.coef

    def _set_state(self, state):
        self.coef = state

    def predict_torque(self, data):
        return np.stack([X @ c for X, c in zip(self._columns(data), self.coef)], axis=1)

    def predict_lagrangian(self, data):
        return np.full(len(data), np.nan)


def _trajectories(seed: int = 0) -> Dataset:
    """Three trajectories of a cubic torque law, with noise."""
    rng = np.random.default_rng(seed)
    n = 300
    q = np.concatenate([np.sin(np.linspace(0, 6, n) + k)[:, None] * [1.0, 0.7] for k in range(3)])
    tau = q ** 3 - 0.5 * q + 0.05 * rng.normal(size=q.shape)
    labels = np.repeat(["a", "b", "c"], n)
    return Dataset(q, q, q, tau, recording=labels, time=np.tile(np.arange(n) * 0.01, 3))


def _by_hand(train: Dataset, choice: dict, farther: bool = False) -> float:
    """The mean validation MSE over the folds; ``farther``: on each fold's scored samples at least its median
    distance (in q and q̇, scaled by the fitted states' deviations) from the nearest state it is fitted on."""
    out = []
    for fold in folds(train, max_folds=MAX_FOLDS):
        fitted, part = train.subset(fold.fit), train.subset(fold.score)
        m = Poly(**choice).fit(fitted, "indirect", 0, budget=Budget(steps=1))
        keep = np.ones(len(part), dtype=bool)
        if farther:
            scale = np.hstack([fitted.q, fitted.qd]).std(axis=0)
            x, y = np.hstack([part.q, part.qd]) / scale, np.hstack([fitted.q, fitted.qd]) / scale
            d = np.sqrt(((x[:, None, :] - y[None, :, :]) ** 2).sum(axis=2)).min(axis=1)
            keep = d >= np.median(d)
        out.append(mse(m.predict_torque(part)[keep], part.tau[keep]))
    return float(np.mean(out))


def test_the_best_validated_combination_is_chosen_and_fitted_on_all_the_training_data():
    train = _trajectories()
    tuned = tune(Poly, {}, train, "indirect", 0, Budget(steps=1))
    d = tuned.details
    assert d["protocol"] == PROTOCOL and d["folds"]["kind"] == "trajectories" and d["folds"]["folds"] == 3
    assert len(d["combinations"]) == len(combinations(Poly)) == 8
    for row in d["combinations"]:
        assert row["validation_mse"] == pytest.approx(_by_hand(train, row["hyperparameters"]), rel=1e-9)
        assert len(row["fold_mse"]) == len(row["fold_far_mse"]) == 3
        # beside it, the farther half of each fold's samples, measured by brute force here
        assert row["validation_far_mse"] == pytest.approx(_by_hand(train, row["hyperparameters"], True), rel=1e-9)
    best = min(d["combinations"], key=lambda r: r["validation_mse"])
    assert d["chosen"] == best["hyperparameters"] == {"degree": 3, "ridge": 0.0}
    assert d["validation_far_mse"] == best["validation_far_mse"] and d["far"] == FAR_RULE
    again = Poly(**d["chosen"]).fit(train, "indirect", 0, budget=Budget(steps=1))
    np.testing.assert_array_equal(tuned.method.predict_torque(train), again.predict_torque(train))
    assert tuned.method.hyperparameters()["degree"] == 3


def test_the_record_gives_the_work_of_the_fold_fits_beside_the_final_fits():
    # the survivor's fold fits and the final fit do the same steps, and the record says so beside their seconds
    train = _trajectories()
    by_work = tune(METHODS["mlp"], {"hidden": 8, "layers": 1, "eval_samples": 64}, train,
                   "indirect", 0, Budget(steps=7)).details["work"]
    assert by_work["fold_steps"] == [7] * 3 and by_work["final_steps"] == 7
    assert len(by_work["fold_fit_seconds"]) == 3 and by_work["final_fit_seconds"] > 0
    poly = tune(Poly, {}, train, "indirect", 0, Budget(steps=1)).details
    chosen = next(r for r in poly["combinations"] if r["hyperparameters"] == poly["chosen"])
    assert poly["work"]["fold_steps"] == chosen["fold_steps"] == [1, 1, 1] and poly["work"]["final_steps"] == 1


def test_a_hyperparameter_the_user_set_is_not_searched():
    tuned = tune(Poly, {"degree": 1}, _trajectories(), "indirect", 0, Budget(steps=1))
    assert tuned.details["searched"] == ["ridge"] and len(tuned.details["combinations"]) == 2
    assert tuned.method.config.degree == 1
    alone = tune(Poly, {"degree": 1, "ridge": 0.0}, _trajectories(), "indirect", 0, Budget(steps=1))
    assert "nothing to tune" in alone.details["note"] and alone.method.config.ridge == 0.0


def test_a_combination_that_fails_is_recorded_and_not_chosen():
    class Fragile(Poly):
        name = "toy_fragile"

        def _fit(self, train, experiment, progress):
            if self.config.degree == 3:
                raise RuntimeError("the toy fell over")
            super()._fit(train, experiment, progress)

    d = tune(Fragile, {}, _trajectories(), "indirect", 0, Budget(steps=1)).details
    failed = [r for r in d["combinations"] if "failed" in r]
    assert len(failed) == 2 and all("the toy fell over" in r["failed"] for r in failed)
    assert d["chosen"]["degree"] != 3


def test_every_method_and_hybrid_declares_a_small_search_space_its_config_accepts():
    names = [n for n in METHODS.names() if METHODS.entry(n).available]
    for name in names + ["feasible+gp", "standard+mlp", "feasible+delan", "standard+sparse_torque"]:
        check_space(METHODS[name])
        assert len(combinations(METHODS[name])) <= MAX_COMBINATIONS
    assert "gate_length" in METHODS["standard+mlp"].search_space
    assert "gate_length" not in METHODS["feasible+gp"].search_space  # the GP falls back to zero by itself

    class Wide(Poly):
        search_space = {"degree": tuple(range(11))}

    with pytest.raises(ConfigError, match="11 combinations"):
        check_space(Wide)

    class Wrong(Poly):
        search_space = {"degree": (-1, 1)}

    with pytest.raises(ConfigError, match="degree"):
        check_space(Wrong)


def test_a_tuned_run_id_round_trips_and_its_missing_record_stays_tuned():
    rid = run_id("kuka_lwr4", "mlp", "indirect", 3, 0.0, tuned=True)
    assert rid.endswith("__tuned") and parse_run_id(rid)["tuned"] and not parse_run_id(rid[: -len("__tuned")])["tuned"]
    assert parse_run_id(run_id("p", "mlp", "indirect", 3, 0.01, tuned=True)) == {
        "system": "p", "method": "mlp", "experiment": "indirect", "seed": 3, "noise": 0.01, "profile": "default", "tuned": True}
    assert Record.missing(rid, "corrupt").tuned
    hybrid = run_id("kuka_lwr4", "feasible+gp", "indirect", 0, 0.0, tuned=True)  # a hybrid's id parses too
    assert parse_run_id(hybrid)["method"] == "feasible+gp" and Record.missing(hybrid, "corrupt").method == "feasible+gp"
    assert RunSpec("kuka_lwr4", "mlp", "indirect", 3, None, steps=5, tune=True).run_id == rid
    # two configurations of one method are two runs, whose records do not share a name
    feasible = RunSpec("kuka_lwr4", "sysid", "indirect", 0, None, steps=1, profile="feasible", tune=True).run_id
    assert feasible == "kuka_lwr4__sysid__indirect__seed0__profile-feasible__tuned"
    assert parse_run_id(feasible)["profile"] == "feasible" and parse_run_id(feasible)["tuned"]
    assert Record.missing(feasible, "corrupt").spec["profile"] == "feasible"


def test_a_tuned_matrix_sits_beside_the_default_one_and_replays(tmp_path):
    out = tmp_path / "m"
    common = ["run", "--systems", "double_pendulum", "--methods", "sysid", "--experiments", "indirect", "--smoke",
              "--steps", "5", "--n-seeds", "1", "--n-train", "200", "--n-test", "64", "--no-rollout", "--out", out]
    assert cli(*common).returncode == 0
    r = cli(*common, "--tune")
    assert r.returncode == 0, r.stderr
    text = (out / "tables.md").read_text()
    assert "| sysid | sysid tuned |" in text and f"*tuned* are {PROTOCOL}" in text
    path = out / "records" / "double_pendulum__sysid__indirect__seed0__tuned.json"
    record = json.loads(path.read_text())
    tuning = record["details"]["tuning"]
    assert len(tuning["combinations"]) == 4 and tuning["folds"]["kind"] == "blocks"
    assert record["hyperparameters"]["feasible"] == tuning["chosen"]["feasible"]
    again = cli("rerun", path)
    assert again.returncode == 0 and "the same up to a relative 1e-09" in again.stdout
    refused = cli(*common, "--tune", "--stack-seeds")
    assert refused.returncode == 2 and "--stack-seeds" in refused.stderr and len(refused.stderr.splitlines()) == 1


def test_no_fit_starts_past_the_searchs_share_of_a_time_budget(monkeypatch):
    from bench.evaluation import tuning

    class Clock:  # one second passes each time the search looks at the clock
        def __init__(self):
            self.now = 0.0

        def perf_counter(self):
            self.now += 1.0
            return self.now

    monkeypatch.setattr(tuning, "time", Clock())
    d = tune(Poly, {}, _trajectories(), "indirect", 0, Budget(seconds=40.0)).details
    skipped = [r for r in d["combinations"] if r.get("failed") == tuning.OUT_OF_TIME]
    fitted = [r for r in d["combinations"] if r["validation_mse"] is not None]
    assert skipped and fitted and len(skipped) + len(fitted) == 8
    assert d["chosen"] in [r["hyperparameters"] for r in fitted] and d["final_budget"]["kind"] == "steps"


def test_successive_halving_scores_the_survivor_at_the_final_fits_steps():
    # a rung keeps the best third with three times the steps; the last holds one combination fitted on every fold
    # with exactly the steps of the final fit, and that is the method's score, not the least over the search
    assert tuning_rungs(8) == [(8, 1 / 9), (3, 1 / 3), (1, 1.0)] and tuning_rungs(1) == [(1, 1.0)]
    train = _trajectories()
    d = tune(METHODS["mlp"], {"hidden": 8, "layers": 1, "eval_samples": 64}, train, "indirect", 0,
             Budget(steps=9)).details
    assert [r["steps"] for r in d["rungs"]] == [3, 9] and [r["combinations"] for r in d["rungs"]] == [2, 1]
    top = [r for r in d["combinations"] if r["rung"] == 1]
    assert len(top) == 1 and top[0]["hyperparameters"] == d["chosen"] and d["validation_mse"] == top[0]["validation_mse"]
    assert d["work"]["fold_steps"] == [9, 9, 9] and d["work"]["final_steps"] == 9
    dropped = next(r for r in d["combinations"] if r["rung"] == 0)
    assert dropped["steps"] == 3 and len(dropped["fold_steps"]) == 3


def test_the_plan_gives_the_steps_that_fit_the_time_left_by_the_line_through_the_fits():
    from bench.evaluation import tuning

    train = _trajectories()
    search = tuning._Search(lambda choice: Poly(), train, "indirect", 0, None, folds(train, max_folds=MAX_FOLDS))
    assert search.plan([(1, 1.0)], 20.0) == 1  # nothing measured yet: one step
    search.observed = [(1.0, 1.1), (11.0, 2.1)]  # a second of overhead a fit, a tenth of a second a unit of work
    # the last rung on 3 folds fitted on 2/3 of the samples each, and the final fit on all: 4 fits, 3 units a step
    assert search.plan([(1, 1.0)], 20.0) == int((20.0 - 4 * 1.0) / (0.1 * 3.0))
    search.observed = [(1.0, 2.0), (11.0, 1.0)]  # a line that falls: seconds per unit over all the fits, no overhead
    assert search.plan([(1, 1.0)], 20.0) == int(20.0 / (3.0 / 12.0 * 3.0))


@pytest.mark.slow  # the steps planned depend on the machine's speed: on a loaded machine the one-step probe takes its
# whole share of 6 s, and the plan, one point to go by, counts all of it as work (one step)
def test_under_a_time_budget_the_fold_fits_do_the_steps_the_final_fit_does():
    train = _trajectories()
    d = tune(METHODS["mlp"], {"hidden": 8, "layers": 1, "eval_samples": 64, "lr": 1e-3}, train, "indirect", 0,
             Budget(seconds=6.0)).details
    assert d["probe"]["steps"] > 0 and d["final_budget"]["kind"] == "steps"
    steps = d["final_budget"]["steps"]
    assert d["work"]["fold_steps"] == [steps] * 3 and d["work"]["final_steps"] == steps > 1


def test_a_time_budget_that_affords_no_more_steps_ends_the_search_at_equal_work(monkeypatch):
    # the plan before the second rung finds the time left too short for more steps than the first rung's: the
    # search ends there, and the final fit does the steps the chosen combination's fold fits did
    from bench.evaluation import tuning

    plans = iter([27, 2])
    monkeypatch.setattr(tuning._Search, "plan", lambda self, schedule, seconds: next(plans))
    d = tune(METHODS["mlp"], {"hidden": 8, "layers": 1, "eval_samples": 64}, _trajectories(), "indirect", 0,
             Budget(seconds=30.0)).details
    assert [r["steps"] for r in d["rungs"]] == [9] and d["final_budget"] == {"kind": "steps", "steps": 9,
                                                                             "ceiling_s": None}
    assert d["work"]["fold_steps"] == [9, 9, 9] and d["work"]["final_steps"] == 9
    assert "ended the search at rung 1 of 2" in d["note"]


def test_work_on_the_samples_that_no_budget_bounds_is_done_for_every_fold_before_the_search():
    """A method's work on its samples that does not depend on the budget (a hybrid's prior) is done, in a run's
    prepare phase, for each fold's fitted samples and for all the training data, before the search fits
    anything; the search does not repeat it (each fit's own call finds it kept, as a hybrid keeps its priors)."""
    events = []

    class Primed(Poly):
        name = "toy_primed"
        search_space = {"degree": (0, 1)}

        def _prepare_samples(self, train, experiment, seed, system):
            events.append(("samples", len(train)))

        def _fit(self, train, experiment, progress):
            events.append(("fit", len(train)))
            super()._fit(train, experiment, progress)

    train = _trajectories()
    fold_set = folds(train, max_folds=MAX_FOLDS)
    prepare(Primed, {}, train, "indirect")
    tune(Primed, {}, train, "indirect", 0, Budget(steps=1))
    first_fit = next(k for k, (kind, _) in enumerate(events) if kind == "fit")
    before = [n for kind, n in events[:first_fit]]
    expected = sorted([len(train.subset(f.fit)) for f in fold_set] + [len(train)])
    # each combination's, then the first fit's own call (the prior kept, it costs a hybrid nothing)
    assert sorted(before[:2 * len(expected)]) == sorted(expected * 2) and before[2 * len(expected):] == [before[-1]]
