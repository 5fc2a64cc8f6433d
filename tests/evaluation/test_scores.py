"""A fitted model's scores: the exact-recovery judgement under its time limit."""

from __future__ import annotations

import time

import sympy

from bench.core.data import generate
from bench.core.models import ExpressionModel
from bench.evaluation import recovery
from bench.evaluation import scores as scores_module
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
    start = time.perf_counter()
    out = scores_module.scores(model, "indirect", data, data, system)
    assert time.perf_counter() - start < 10
    assert out["exact"] is None and out["exact_timed_out"] == 0.5
    assert out["train_mse"] < 1e-20 and sympy.sympify(out["expression"]) is not None
