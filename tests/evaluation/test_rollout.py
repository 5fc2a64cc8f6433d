"""Rollouts: the forward dynamics from any model's torques, and the error
against the true motion."""

from __future__ import annotations

import numpy as np
import sympy

from bench.core import symbolic
from bench.runner.run import execute
from bench.runner.spec import RunSpec, build_specs
from bench.core.data import generate
from bench.physics.models import mass_and_bias
from bench.evaluation.rollout import TrueModel, forward_dynamics, rollout, rollout_error
from bench.physics.models import ExpressionModel
from systems import get_system

#: sparse regression's work: one solve (a work budget, so that a busy machine cannot cut the fit short)
SOLVED = 1


def test_mass_matrix_and_bias_match_the_closed_form():
    system = get_system("double_pendulum")
    data = generate(system, 64, 3, cache=False)
    M, c = mass_and_bias(TrueModel(system), data.q, data.qd)
    (q1, q2), (v1, v2) = symbolic.coordinate_symbols(2)
    L = system.lagrangian_sympy
    hessian = sympy.lambdify((q1, q2, v1, v2), sympy.hessian(L, (v1, v2)), "numpy")
    for i in range(5):
        np.testing.assert_allclose(M[i], hessian(*data.q[i], *data.qd[i]), rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", M, data.qdd) + c, data.tau, rtol=1e-9, atol=1e-9)


def test_true_rollout_conserves_energy():
    system = get_system("double_pendulum")
    data = generate(system, 16, 4, cache=False)
    q = rollout(TrueModel(system), data.q[:4], data.qd[:4], horizon=1.0, n_points=3)
    assert q.shape == (3, 4, 2)
    # energy E = qd . dL/dqd - L, with qd recovered by a second, finer rollout's finite differences
    fine = rollout(TrueModel(system), data.q[:4], data.qd[:4], horizon=1.0, n_points=2001)
    dt = 1.0 / 2000
    qd = np.gradient(fine, dt, axis=0)
    (q1, q2), (v1, v2) = symbolic.coordinate_symbols(2)
    L = system.lagrangian_sympy
    energy = sympy.lambdify((q1, q2, v1, v2), v1 * L.diff(v1) + v2 * L.diff(v2) - L, "numpy")
    E = energy(fine[..., 0], fine[..., 1], qd[..., 0], qd[..., 1])
    drift = np.abs(E[100:-100] - E[100]).max() / np.abs(E).max()
    assert drift < 1e-3


def test_error_is_zero_for_the_truth_and_grows_with_the_models_error():
    system = get_system("single_pendulum")
    test = generate(system, 32, 1000, cache=False)
    (q,), (v,) = symbolic.coordinate_symbols(1)
    L = system.lagrangian_sympy
    assert rollout_error(ExpressionModel(L, 1), system, test)["q_rmse"] < 1e-12
    errors = []
    for wrong in (1.01, 1.1, 1.5):  # gravity too strong by 1 %, 10 %, 50 %
        model = ExpressionModel(L.subs(sympy.cos(q), wrong * sympy.cos(q)), 1)
        result = rollout_error(model, system, test)
        assert result["status"] == "ok"
        errors.append(result["q_rmse"])
    assert 0 < errors[0] < errors[1] < errors[2]


def test_indefinite_and_singular_mass_matrices_are_findings_not_crashes():
    system = get_system("double_pendulum")
    test = generate(system, 16, 1000, cache=False)
    negative = rollout_error(ExpressionModel(-system.lagrangian_sympy, 2), system, test)
    assert negative["status"] == "indefinite" and "not positive definite" in negative["detail"]
    (q1, q2), (v1, v2) = symbolic.coordinate_symbols(2)
    flat = rollout_error(ExpressionModel(v1**2 / 2 + sympy.cos(q1) + sympy.cos(q2), 2), system, test)
    assert flat["status"] == "singular" and flat["q_rmse"] is None
    try:
        forward_dynamics(ExpressionModel(-system.lagrangian_sympy, 2), test.q, test.qd)
    except Exception as exc:
        assert exc.status == "indefinite"
    else:
        raise AssertionError("an indefinite mass matrix went unnoticed")


def test_records_of_simulated_systems_carry_a_rollout(tmp_path):
    spec = build_specs(["single_pendulum"], ["sparse"], ["indirect"], [0], None, steps=SOLVED, n_train=256, n_test=64)[0]
    record = execute(spec)
    assert record.status == "ok", record.error
    assert record.rollout["status"] == "ok" and record.rollout["q_rmse"] < 1e-6
    skipped = execute(RunSpec(**{**spec.to_dict(), "rollout": False, "plugins": ()}))
    assert skipped.rollout is None
    # a measured system's recordings carry their time: its records get rollouts driven by the measured torques
    measured = build_specs(["delan_characters"], ["sparse"], ["indirect"], [0], None, steps=SOLVED)[0]
    assert execute(measured).rollout["kind"] == "driven"
