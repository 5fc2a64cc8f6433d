"""The method base class: hyperparameters, the fit protocol, the best state, the deadline."""

from __future__ import annotations

import time

import numpy as np
import pytest

from bench.core.budget import Budget, Schedule
from bench.core.errors import ConfigError
from methods import METHODS, Method, MethodConfig, Progress

def test_hyperparameters_are_validated_without_mutating_input():
    given = {"hidden": 8, "layers": 1}
    m = METHODS["mlp"](**given)
    assert given == {"hidden": 8, "layers": 1} and m.config.hidden == 8
    with pytest.raises(ConfigError, match="unknown hyperparameter 'hiden'; did you mean 'hidden'"):
        METHODS["mlp"](hiden=8)
    with pytest.raises(ConfigError, match="must be an integer"):
        METHODS["mlp"](hidden=8.5)
    with pytest.raises(ConfigError, match="must be one of"):
        METHODS["mlp"](dtype="float16")
    assert METHODS["mlp"](lr=1).config.lr == 1.0


class _Scripted(Method):
    """A fake method whose 'loss' follows a script, to test the base protocol."""

    Config = MethodConfig

    def __init__(self, script, sleep=0.0, **kw):
        super().__init__(**kw)
        self.script, self.sleep, self.value = list(script), sleep, None

    def _fit(self, train, experiment, progress):
        i = 0
        self.value = self.script[0]
        while progress.step():
            i += 1
            self.value = self.script[min(i, len(self.script) - 1)]
            time.sleep(self.sleep)

    def _get_state(self):
        return self.value

    def _set_state(self, state):
        self.value = state

    def predict_lagrangian(self, data):
        return data.L + np.sqrt(self.value)

    def predict_torque(self, data):
        return data.tau + np.sqrt(self.value)


def test_best_state_is_kept_and_restored(small_data):
    train, _ = small_data
    # steps of 20 ms: early on, every step is evaluated (the gap is 10 % of the elapsed time)
    m = _Scripted([9.0, 4.0, 1.0, 25.0, 36.0], sleep=0.02, max_steps=4).fit(train, "direct", 0, Budget(seconds=10.0))
    assert m.value == 1.0
    assert m.fit_info["best_step"] == 2
    assert m.fit_info["curve"][-1][1] == pytest.approx(1.0)


def test_deadline_is_honoured(small_data):
    train, _ = small_data
    m = _Scripted([1.0], sleep=0.01).fit(train, "indirect", 0, Budget(seconds=0.5))
    assert m.fit_info["stop_reason"] == "budget"  # the loop has no other end


@pytest.mark.slow  # it times the machine
def test_the_deadline_ends_the_fit_within_a_step_of_its_budget(small_data):
    train, _ = small_data
    t0 = time.perf_counter()
    _Scripted([1.0], sleep=0.01).fit(train, "indirect", 0, Budget(seconds=0.5))
    assert time.perf_counter() - t0 < 1.0


def test_non_finite_loss_stops_and_keeps_the_last_good_state(small_data):
    train, _ = small_data
    m = _Scripted([4.0, 2.0, float("nan")], sleep=0.02, max_steps=50).fit(train, "direct", 0, Budget(seconds=10.0))
    assert m.value == 2.0 and m.fit_info["stop_reason"] == "non-finite training loss"


def test_measuring_a_failed_state_does_not_stop_the_loop_but_a_scheduled_evaluation_does():
    values = iter([3.0, float("nan"), 1.0, float("nan")])
    p = Progress(60.0, evaluate=lambda: next(values), snapshot=lambda: p.evaluations)
    assert p.measure() == 3.0 and p.best_mse == 3.0
    assert np.isnan(p.measure()) and p.stop_reason is None and p.best_mse == 3.0
    assert p.measure() == 1.0 and p.best_mse == 1.0 and p.best_state == 3  # a new best keeps its state (the 3rd)
    assert np.isnan(p.evaluate_now()) and p.stop_reason == "non-finite training loss"
    assert p.evaluations == 4 and not p.step()


def test_progress_fraction_counts_steps_when_limited_and_time_otherwise():
    p = Progress(60.0, evaluate=lambda: 1.0, snapshot=lambda: None, max_steps=8)
    for _ in range(3):
        p.step()
    assert p.fraction() == 2 / 8  # the first call counts no step
    timed = Progress(1000.0, evaluate=lambda: 1.0, snapshot=lambda: None)
    assert 0 <= timed.fraction() < 1e-3


def test_progress_evaluations_are_spaced():
    calls = []
    p = Progress(0.3, evaluate=lambda: calls.append(1) or 1.0, snapshot=lambda: None)
    steps = 0
    while p.step():
        steps += 1
    assert steps > 100 and p.evaluations < 60  # evaluation is not done every step
    assert p.stop_reason == "budget"


@pytest.mark.parametrize("max_steps", [3, 20, 500])
def test_a_step_limited_run_evaluates_the_same_steps_at_any_speed(monkeypatch, max_steps):
    """Which states are compared must not depend on how fast the machine is,
    or a seed's result changes with the load (seen on a busy machine)."""
    import bench.core.budget

    def evaluated_steps(step_seconds):
        clock = iter(np.cumsum(step_seconds)).__next__
        monkeypatch.setattr(bench.core.budget, "_clock", clock)
        seen = []
        p = Progress(1e9, evaluate=lambda: seen.append(p.steps) or 1.0 / (1 + p.steps), snapshot=lambda: None,
                     max_steps=max_steps)
        while p.step():
            pass
        p.finish()
        return seen, p.best_step

    rng = np.random.default_rng(0)
    fast = evaluated_steps(np.full(10_000, 1e-4))
    loaded = evaluated_steps(rng.exponential(0.05, 10_000))
    assert fast == loaded
    assert fast[0][-1] == max_steps and fast[1] == max_steps
    assert len(fast[0]) < 60  # still spaced: geometric after the tenth step


def _timed_loop(monkeypatch, step_seconds, budget_s=None, schedule=None):
    """A loop under a scripted clock that reads the fraction of its budget at every step, as a
    cosine schedule or a multi-start selection does; returns what it read, evaluated and did."""
    import bench.core.budget

    clock = iter(np.cumsum(step_seconds)).__next__
    monkeypatch.setattr(bench.core.budget, "_clock", clock)
    evaluated, read = [], []
    p = Progress(np.inf if budget_s is None else budget_s, evaluate=lambda: evaluated.append(p.steps) or 1.0,
                 snapshot=lambda: None, schedule=schedule)
    read.append(p.fraction())  # before the first step, as a schedule's start reads it
    while p.step():
        read.append(p.fraction())
    p.finish()
    return evaluated, read, p


def test_a_time_budgeted_loop_replays_step_for_step_from_its_schedule(monkeypatch):
    """The clock decides when a time-budgeted loop stops, evaluates, and how far its schedule is;
    its recorded schedule repeats all three on a machine of another speed, without a clock."""
    rng = np.random.default_rng(0)
    evaluated, read, live = _timed_loop(monkeypatch, rng.exponential(0.01, 100_000), budget_s=30.0)
    assert live.stop_reason == "budget" and live.steps > 1000
    assert 10 < len(evaluated) < 200 and read[0] == 0.0 and 0.9 < read[-1] <= 1.05
    schedule = live.schedule()
    assert schedule.steps == live.steps and schedule.evaluations == tuple(live.scheduled) and schedule.clock
    # a replay on a slower and a faster machine: the same steps, evaluations and fractions
    for seconds in (rng.exponential(0.05, 100_000), np.full(100_000, 1e-5)):
        again = _timed_loop(monkeypatch, seconds, schedule=Schedule.from_json(schedule.to_json()))
        assert again[0] == evaluated and again[1] == read
        assert again[2].steps == live.steps and again[2].stop_reason == "max_steps"


def test_a_time_budgeted_syrenets_fit_with_a_cosine_schedule_and_four_starts_replays_exactly(small_data):
    # its learning rate and its choice between networks follow the fraction of the budget spent
    train, test = small_data
    hp = {"layers": 2, "heads": 3, "latent": 4, "ae_hidden": 8, "head_hidden": 8, "eval_samples": 64, "refine": False,
          "lr_schedule": "cosine", "starts": 4}
    live = METHODS["syrenets"](**hp).fit(train, "indirect", 0, Budget(seconds=2.0))
    assert live.fit_info["stop_reason"] == "budget" and live.record_details()["starts"]["networks"] == 4
    replayed = METHODS["syrenets"](**hp).fit(train, "indirect", 0, Budget.replaying(Schedule.from_json(live.fit_info["schedule"])))
    np.testing.assert_array_equal(replayed.predict(test), live.predict(test))
    assert replayed.record_details()["starts"] == live.record_details()["starts"]


def test_a_fit_whose_time_ran_out_before_its_first_step_replays(small_data):
    # on a loaded machine a short budget can end at the first evaluation
    train, _ = small_data
    m = _Scripted([4.0, 2.0]).fit(train, "direct", 0, Budget.replaying(Schedule(0, (0,), ((-1, 0.0, 0.0),))))
    assert m.fit_info["steps"] == 0 and m.value == 4.0
    with pytest.raises(ConfigError, match=">= 1, got 0"):
        Budget(steps=0)


def test_a_work_budget_has_no_deadline_and_is_counted_in_steps(small_data):
    train, _ = small_data
    m = _Scripted([4.0, 2.0, 1.0]).fit(train, "direct", 0, budget=Budget(steps=7))
    assert m.fit_info["steps"] == 7 and m.fit_info["stop_reason"] == "max_steps"
    assert m.budget == Budget(steps=7) and m.fit_info["schedule"]["steps"] == 7
    with pytest.raises(ConfigError, match="a fit's budget is a Budget"):
        m.fit(train, "direct", 0, 5.0)


def test_fit_rejects_bad_calls(small_data):
    train, _ = small_data
    m = METHODS["mlp"](**METHODS["mlp"].smoke_config())
    with pytest.raises(ConfigError, match="unknown experiment"):
        m.fit(train, "sideways", 0, Budget(seconds=1.0))
    with pytest.raises(ConfigError, match="seconds must be positive"):
        m.fit(train, "direct", 0, Budget(seconds=0.0))


def test_sysid_needs_a_system(small_data):
    from bench.core.data import Dataset
    from bench.core.errors import DataError

    train, _ = small_data
    anonymous = Dataset(train.q, train.qd, train.qdd, train.tau, train.L, system=None, source="anon.csv")
    with pytest.raises(DataError, match="anon.csv: sysid needs to know the data's system"):
        METHODS["sysid"](max_steps=2).fit(anonymous, "indirect", 0, Budget(seconds=5.0))


@pytest.mark.parametrize("typed, value", [("false", False), ("FALSE", False), ("No", False), ("0", False), (0, False),
                                          ("true", True), ("Yes", True), ("1", True), (1, True), (True, True)])
def test_booleans_are_accepted_as_users_type_them(typed, value):
    assert METHODS["syrenets"](refine=typed).config.refine is value


@pytest.mark.parametrize("typed", ["maybe", 2, 0.5, None])
def test_other_booleans_are_refused(typed):
    with pytest.raises(ConfigError, match="refine must be true or false"):
        METHODS["syrenets"](refine=typed)


@pytest.mark.parametrize(
    "method, given, message",
    [
        ("mlp", {"batch_size": 0}, "batch_size must be at least 1, got 0"),
        ("mlp", {"hidden": 0}, "hidden must be at least 1, got 0"),
        ("mlp", {"max_steps": -5}, "max_steps must be at least 1, got -5"),
        ("mlp", {"eval_samples": 0}, "eval_samples must be at least 1, got 0"),
        ("mlp", {"lr": 0.0}, "lr must be greater than 0, got 0.0"),
        ("mlp", {"lr": float("inf")}, "lr must be a finite number"),
        ("mlp", {"lr_factor": 1.0}, r"lr_factor must be in \(0, 1\), got 1.0"),
        ("syrenets", {"post_fraction": 1.0}, r"post_fraction must be in \[0, 1\), got 1.0"),
        ("syrenets", {"betas": (0.9, 1.0)}, r"betas must be in \[0, 1\) \(each item\)"),
        ("mggp", {"p_erc": 1.5}, r"p_erc must be in \[0, 1\], got 1.5"),
        ("sparse", {"threshold": -1e-3}, "threshold must be at least 0"),
    ],
)
def test_hyperparameters_outside_their_declared_range_are_refused_at_construction(method, given, message):
    with pytest.raises(ConfigError, match=message):
        METHODS[method](**given)


def test_every_methods_defaults_and_smoke_configuration_lie_in_their_ranges():
    for name in METHODS:
        cls = METHODS[name]
        cls()  # the defaults are checked too
        cls(**cls.smoke_config())
    assert METHODS["sparse"](threshold=None).config.threshold is None  # an optional range admits None


def test_the_garbage_collector_skips_older_objects_only_during_the_loop(small_data):
    import gc

    class _Watching(_Scripted):
        def _fit(self, train, experiment, progress):
            self.frozen_inside = gc.get_freeze_count()
            super()._fit(train, experiment, progress)

    m = _Watching([1.0], max_steps=2).fit(small_data[0], "direct", 0, Budget(seconds=10.0))
    assert m.frozen_inside > 1000  # the objects that existed on entry
    assert gc.get_freeze_count() == 0
