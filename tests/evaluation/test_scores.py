"""A fitted model's scores: the exact-recovery judgement under its time limit."""

from __future__ import annotations

import time

import sympy

from bench.core.data import generate
from bench.physics.models import ExpressionModel
from bench.evaluation import recovery
from bench.evaluation import scores as scores_module
from bench.runner.run import execute
from bench.runner.spec import build_specs
from systems import get_system


def test_a_judgement_that_runs_past_its_limit_is_stopped_and_recorded(monkeypatch):
    system = get_system("double_pendulum")
    data = generate(system, 64, 0, cache=False)
    model = ExpressionModel(system.lagrangian_sympy, system.dof)
    # within the limit, the true Lagrangian is judged exact
    out = scores_module.scores(model, "indirect", data, data, system)
    assert out["exact"] is True and "exact_timed_out" not in out
    # a judgement that does not end in time is stopped; the scores are kept
    monkeypatch.setattr(scores_module, "JUDGE_LIMIT_S", 0.5)
    monkeypatch.setattr(recovery, "_vanishes", lambda *a, **k: time.sleep(30))
    out = scores_module.scores(model, "indirect", data, data, system)
    assert out["exact"] is None and out["exact_timed_out"] == 0.5  # stopped, not waited for
    assert out["train_mse"] < 1e-20 and sympy.sympify(out["expression"]) is not None


def test_a_run_whose_judgement_is_stopped_keeps_its_record(monkeypatch):
    """Sparse regression recovers the single pendulum exactly; with the symbolic
    check made to hang, the run still ends ok with its scores, ``exact`` unset
    and the limit in its details."""
    spec = build_specs(["single_pendulum"], ["sparse"], ["indirect"], [0], None, steps=1, n_train=256, n_test=64)[0]  # one solve
    assert execute(spec).exact is True
    monkeypatch.setattr(scores_module, "JUDGE_LIMIT_S", 0.5)
    monkeypatch.setattr(recovery, "_vanishes", lambda *a, **k: time.sleep(30))
    record = execute(spec)
    assert record.status == "ok", record.error
    assert record.exact is None and record.details["exact_timed_out"] == 0.5
    assert record.test_mse < 1e-12 and record.expression
