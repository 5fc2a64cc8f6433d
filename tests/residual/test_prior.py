"""The residual loop's model as a method (``loop``) and as a hybrid's prior
(``loop+RESIDUAL``), fitted within one budget and kept in a model file."""

from __future__ import annotations

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from bench.residual.loop import not_started, residual_loop
from bench.residual.prior import rounds_run
from methods import METHODS
from methods.hybrid import PRIORS
from methods.saving import TOLERANCE, load_model, save_model
from systems import SYSTEMS
from bench.core.scoring import opened
from bench.core.budget import Budget


@pytest.fixture(scope="module")
def arm():
    system = SYSTEMS["kuka_lwr4"]()
    train = system.load("train")
    part = train.subset(np.sort(np.concatenate([index[:200] for index in train.in_time_order()])))
    return system, part, opened(system.load("test")).subset(slice(0, 400))


@pytest.mark.long
def test_the_loop_method_is_the_loops_final_model_a_round_its_step(arm, capsys):
    system, train, test = arm
    for steps in (1, 2):
        fitted = METHODS["loop"]().fit(train, "indirect", 0, budget=Budget(steps=steps), system=system)
        result = residual_loop("sysid", train, None, budget=Budget(steps=steps), seed=0, max_rounds=steps, report=lambda line: None)
        np.testing.assert_array_equal(fitted.predict_torque(test), result.models[1].predict_torque(test))
        ran = [r for r in result.rounds if r["round"] > 0]
        assert fitted.fit_info["steps"] == len(ran) <= steps
    assert "prior: round 0" in capsys.readouterr().out  # the loop's progress, line by line


@pytest.mark.long
def test_a_loop_hybrid_fits_its_residual_to_what_the_loop_leaves_and_saves(arm, tmp_path):
    system, train, test = arm
    hybrid = METHODS["loop+sparse_torque"]().fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    # the prior is the loop run to its end by work (a round that accepts nothing, or MAX_ROUNDS), whatever the
    # hybrid's budget: two rounds or more, where the residual's budget is one step
    loop = residual_loop("sysid", train, None, budget=Budget(steps=1), seed=0, report=lambda line: None)
    assert len([r for r in loop.rounds if r["round"] > 0]) >= 2
    np.testing.assert_allclose(hybrid.prior.predict_torque(test), loop.models[1].predict_torque(test),
                               rtol=1e-12, atol=1e-12)
    assert np.mean((hybrid.predict_torque(train) - train.tau) ** 2) < np.mean((hybrid.prior.predict_torque(train) - train.tau) ** 2)
    assert hybrid.record_details()["prior"].startswith("the residual loop's model")
    save_model(hybrid, tmp_path / "h.npz", {"system": system.name}, train, system)
    loaded, header = load_model(tmp_path / "h.npz")
    expected = hybrid.predict_torque(test)
    assert np.max(np.abs(loaded.predict_torque(test) - expected)) <= TOLERANCE * np.max(np.abs(expected))
    assert header["kind"] == "hybrid"
    # under a time budget the prior is the same whole loop, identified before the budget starts (as a run's prepare
    # phase does), and the budget is the residual's alone (2 s: ample for its one solve on a busy machine)
    timed = METHODS["loop+sparse_torque"]()
    assert timed.prepare_samples(train, "indirect", 0, system) >= 0.0
    timed.fit(train, "indirect", 0, Budget(seconds=2.0), system=system)
    np.testing.assert_array_equal(timed.prior.predict_torque(test), hybrid.prior.predict_torque(test))


def test_the_loop_from_the_feasible_body_starts_from_selects_feasible_model_and_is_not_the_hybrids_prior(arm, monkeypatch):
    from bench.residual import prior

    system, train, test = arm
    config = METHODS["loop"].configuration("feasible")
    assert config == {"friction": True}
    fitted = METHODS["loop"](**config).fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    result = residual_loop("sysid", train, None, budget=Budget(steps=1), seed=0, max_rounds=1,
                           hyperparameters=METHODS["sysid"].configuration("feasible"), report=lambda line: None)
    assert METHODS["sysid"].configuration("feasible") == {"feasible": True, "friction": True, "drive": True}
    np.testing.assert_array_equal(fitted.predict_torque(test), result.models[1].predict_torque(test))
    plain = residual_loop("sysid", train, None, budget=Budget(steps=1), seed=0, max_rounds=1, report=lambda line: None)
    # round 0's model holds the rigid body alone among its fits (each joint's laws at 0): it fits the training data
    # closer
    assert result.rounds[0]["mse"]["train"] < plain.rounds[0]["mse"]["train"]
    # only the loop from the rigid body alone, at its full rounds, is kept as the hybrids' prior ``loop``
    kept = []
    monkeypatch.setattr(prior, "MAX_ROUNDS", 1)
    monkeypatch.setattr(prior, "keep_shared", lambda name, *rest: kept.append(rest[-1]))
    feasible = METHODS["loop"](**config).fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    assert kept == []
    alone = METHODS["loop"]().fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    assert kept == [alone.model] and feasible.model is not alone.model


def test_the_registry_finds_the_loop_without_being_told_to_import_it():
    """A fresh process that imports only the method registry lists the loop and composes its hybrids: the module
    that registers them is declared as an entry point, not imported as a side effect of the command line."""
    code = ("import sys; from methods import METHODS; assert 'bench.residual.prior' not in sys.modules; "
            "print('loop' in METHODS.names(), METHODS['loop+gp'].prior_name)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "loop"]
    assert PRIORS["loop"].name == "loop"
    assert "loop" in METHODS["loop"].not_applicable_reason("indirect", SYSTEMS["double_pendulum"]())


def test_the_loops_steps_count_the_rounds_it_ran_and_not_one_it_did_not_start():
    rounds = [{"round": 0}, {"round": 1}, {"round": 2, "stop": "stopped: the budget of 60 s ran out in round 2"},
              {"round": 3, "stop": not_started(60.0)}]
    assert rounds_run(SimpleNamespace(budget_s=60.0, rounds=rounds)) == 2  # the undone round 2 ran
    assert rounds_run(SimpleNamespace(budget_s=None, rounds=rounds[:3])) == 2  # a work budget starts every round
