"""Laws that claim beyond the data: found, and kept only where a held-out trajectory confirms them; a law of
the sensor on one trajectory judged on held-out regions of its states."""

from __future__ import annotations

import numpy as np

from bench.core.budget import Budget
from bench.core.data import add_noise, generate
from bench.physics.effects import EFFECTS
from bench.physics.terms import Term
from bench.residual.model import LoopModel
from bench.residual.beyond_data import beyond_data, earns_place, held_out_verdict, not_identified
from bench.residual.strategies import strategy_for
from bench.physics.models import ExpressionModel
from bench.residual import residual_loop
from bench.tools.robot_log import simulate
from systems import get_system


def _model(coef, stderr):
    system = get_system("double_pendulum")
    rigid = ExpressionModel(system.lagrangian_sympy, system.dof)
    effects = [EFFECTS["spring"].term(0), EFFECTS["offset"].term(0), Term.dissipation(abs_cube(), "Abs(qd_2)**3/3", 1)]
    return LoopModel(rigid, effects, coef, stderr)


def abs_cube():
    import sympy

    return sympy.Abs(sympy.Symbol("qd_2", real=True)) ** 3 / 3


def _data():
    return generate(get_system("double_pendulum"), 400, 0)


def test_an_open_ended_term_and_a_rest_angle_outside_the_recorded_range_claim_beyond_the_data():
    data = _data()
    low, high = data.q[:, 0].min(), data.q[:, 0].max()
    inside = _model([2.0, -2.0 * 0.5 * high, 0.1], [0.01, 0.01, 0.01])  # rest angle at half the largest angle
    assert [i for i, _ in beyond_data(inside, data)] == [2]
    outside = _model([2.0, -2.0 * (high + 1.0), 0.1], [0.01, 0.01, 0.01])
    found = dict(beyond_data(outside, data))
    assert set(found) == {0, 2} and "outside joint 1's recorded range" in found[0] and f"{low:.3g}" in found[0]
    assert not_identified(_model([2.0, 0.3, 0.1], [0.01, 0.5, 0.01])) == [(1, "not identified: its standard error "
                                                                              "0.5 is at least its value 0.3")]


def test_one_trajectory_cannot_confirm_a_law_and_two_can_judge_it():
    data = _data()
    model = _model([0.0, 0.0, 0.0], [0.01, 0.01, 0.01])
    strategy = strategy_for(model.rigid)
    assert strategy.name == "expression"
    keep, why = earns_place(strategy, model, data.replace(recording=np.full(len(data), "run1")), 0)
    assert not keep and "one trajectory" in why
    noisy = add_noise(data, "indirect", 0.05, 0)
    two = noisy.replace(recording=np.where(np.arange(len(data)) < 200, "a", "b"))
    keep, why = earns_place(strategy, model, two, 0)  # a zero spring on data without one saves nothing
    assert not keep and "held-out MSE" in why


def test_on_one_trajectory_only_a_law_of_a_fixed_form_is_judged_on_held_out_regions():
    one = _data().replace(recording=np.full(400, "run1"), trajectory=np.full(400, "A"))
    asked = []

    def errors(kept, without):
        return lambda: asked.append(1) or (kept, without)

    # an effect that claims beyond the data: refused without asking the held-out errors
    verdict, figures = held_out_verdict(one, errors(1.0, 2.0))
    assert "one trajectory" in verdict and figures is None and not asked
    # a sensor's law: the held-out regions' errors decide, by MIN_GAIN, either way
    assert held_out_verdict(one, errors(1.0, 1.02), regions=True) == (None, (1.0, 1.02))
    verdict, figures = held_out_verdict(one, errors(1.0, 1.005), regions=True)
    assert "held-out regions of its one trajectory's states" in verdict and figures == (1.0, 1.005)
    assert len(asked) == 2
    # independent samples: nothing to overfit, it stays unasked
    assert held_out_verdict(_data(), errors(1.0, 1.0), regions=True) == (None, None) and len(asked) == 2


def test_a_round_whose_every_law_is_a_finding_leaves_the_model_as_it_was_and_the_loop_goes_on():
    # a cogging torque on one trajectory: round 1 finds its periodic parts, which one trajectory cannot confirm;
    # they are findings, not offered again, and the loop traces on without them instead of ending undone
    time, d = simulate("double_pendulum", 8.0, 100.0, 0.2, ["periodic_torque=1:0.8,6,0.5"], 0.01, 0)
    one = d.replace(recording=np.full(len(d), "r0"), trajectory=np.full(len(d), "A"), time=time)
    out = residual_loop("sysid", one, None, budget=Budget(steps=1000), max_rounds=2, report=lambda line: None)
    first, second = out.rounds[1], out.rounds[2]
    assert first["accepted"] and set(first["accepted"]) <= set(first["removed"]) and "stop" not in first
    assert first["heldout_mse"] == out.rounds[0]["heldout_mse"]
    assert all(e["kind"] == "beyond_data" for e in out.effects if e["name"].startswith("periodic"))
    assert second["round"] == 2 and not (out.ending["reason"] == "undone" and out.ending["round"] == 1)
