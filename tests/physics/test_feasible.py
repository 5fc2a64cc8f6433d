"""Physically feasible identification: the pseudo-inertia, and the fit on a noisy arm."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.core.data import add_noise, generate, mse
from bench.physics.feasible import (PSEUDO_INERTIA, Feasibility, feasible_fit, from_pseudo_inertia, nearest_completion,
                                    project, pseudo_inertia, smallest_eigenvalues)
from bench.physics.regression import Compressed, base_columns, least_squares
from methods import METHODS
from systems import get_system
from systems.urdf_arm import physically_consistent
from bench.core.budget import Budget

finite = st.floats(-10, 10, allow_nan=False)


@settings(max_examples=50, deadline=None)
@given(st.lists(finite, min_size=10, max_size=10))
def test_the_pseudo_inertia_and_its_inverse_agree(p):
    np.testing.assert_allclose(from_pseudo_inertia(pseudo_inertia(np.array(p))), p, atol=1e-9)
    # the linear map the feasible fit's program is written with gives the same matrix
    np.testing.assert_allclose((PSEUDO_INERTIA @ np.array(p)).reshape(4, 4, order="F"), pseudo_inertia(np.array(p)),
                               atol=1e-12)


def test_feasible_bodies_and_infeasible_ones():
    # a point mass of 2 kg at c: J = m [c; 1][c; 1]^T, positive semidefinite of rank one
    c, m = np.array([0.1, -0.2, 0.3]), 2.0
    point = np.array([m, *(m * c), m * (c[1] ** 2 + c[2] ** 2), -m * c[0] * c[1], m * (c[0] ** 2 + c[2] ** 2),
                      -m * c[0] * c[2], -m * c[1] * c[2], m * (c[0] ** 2 + c[1] ** 2)])
    assert abs(smallest_eigenvalues(point, 1)[0]) < 1e-12
    box = np.array([1.0, 0, 0, 0, 0.02, 0, 0.03, 0, 0, 0.04])  # a box's inertia about its centre
    assert Feasibility.of(box, 1).feasible
    negative_mass = box * np.array([-1, 1, 1, 1, 1, 1, 1, 1, 1, 1])
    triangle = box.copy()
    triangle[4] = 0.08  # Ixx > Iyy + Izz: no mass distribution has it
    for bad in (negative_mass, triangle):
        assert not Feasibility.of(bad, 1).feasible
        assert smallest_eigenvalues(project(bad, 1), 1)[0] >= 0.0


@pytest.fixture(scope="module")
def panda():
    return get_system("panda")


def test_on_noise_free_data_the_feasible_fit_is_least_squares(panda):
    train, test = generate(panda, 768, 0), generate(panda, 256, 1000)
    ls = METHODS["sysid"](feasible=False).fit(train, "indirect", 0, budget=Budget(steps=1))
    feasible = METHODS["sysid"]().fit(train, "indirect", 0, budget=Budget(steps=1))  # the default on an arm
    facts = feasible.record_details()["feasibility"]
    assert "feasible" not in ls.record_details()["feasibility"]
    assert facts["least_squares"]["feasible"] and facts["feasible"]["feasible"]
    assert mse(feasible.predict(test), test.tau) < 1e-12 * np.var(test.tau)
    assert mse(ls.predict(test), test.tau) < 1e-20 * np.var(test.tau)


def test_on_noisy_data_least_squares_is_infeasible_and_the_feasible_fit_is_not(panda):
    train = add_noise(generate(panda, 768, 0), "indirect", 0.05, 0)
    test = generate(panda, 512, 1000)
    ls = METHODS["sysid"](feasible=False).fit(train, "indirect", 0, budget=Budget(steps=1))
    feasible = METHODS["sysid"](feasible=True).fit(train, "indirect", 0, budget=Budget(steps=1))
    facts = feasible.record_details()["feasibility"]
    assert not facts["least_squares"]["feasible"]  # some body's pseudo-inertia has a negative eigenvalue
    assert facts["feasible"]["feasible"] and min(facts["feasible"]["smallest_eigenvalues"]) >= 0.0
    assert 1.0 <= facts["feasible"]["training_error_ratio"] < 1.05
    # Pinocchio's own reading of the parameters agrees: a positive mass, and an inertia about the
    # centre of mass that is positive definite and keeps the triangle inequalities, on every link
    assert physically_consistent(feasible.linear.coef) == []
    assert mse(feasible.predict(test), test.tau) < 1.05 * mse(ls.predict(test), test.tau)


def test_the_completion_from_the_regressors_factor_is_the_one_from_the_regressor(panda):
    data = add_noise(generate(panda, 256, 0), "indirect", 0.05, 0)
    form = panda.linear_form()
    W, y = form.torque_regressor(data.q, data.qd, data.qdd).reshape(-1, len(form.names)), data.tau.ravel()
    independent, _, _ = base_columns(W)
    coef, prior = least_squares(W[:, independent], y), np.asarray(form.prior)
    full = nearest_completion(W, independent, coef, prior)
    np.testing.assert_allclose(W @ full, W[:, independent] @ coef, rtol=1e-8, atol=1e-8 * np.abs(y).max())
    problem = Compressed(W, y)
    from_factor = nearest_completion(problem.R[:, : problem.columns], independent, coef, prior)
    np.testing.assert_allclose(from_factor, full, rtol=1e-8, atol=1e-10 * np.abs(full).max())


def test_free_columns_beside_the_bodies_are_fitted_without_constraint(panda):
    form = panda.linear_form()
    data = generate(panda, 256, 0)
    W = form.torque_regressor(data.q, data.qd, data.qdd).reshape(-1, len(form.names))
    offset = np.tile(np.eye(7), (len(data), 1))  # a constant torque per joint
    y = data.tau.ravel() + offset @ np.arange(1.0, 8.0)
    coef, facts = feasible_fit(Compressed(np.hstack([W, offset]), y), 7, np.asarray(form.prior), 1e-6)
    np.testing.assert_allclose(coef[-7:], np.arange(1.0, 8.0), atol=1e-6)
    assert min(smallest_eigenvalues(coef[:70], 7)) >= 0.0 and facts["status"].startswith("optimal")


def test_columns_held_nonnegative_stay_at_zero_or_above_and_the_rest_are_free(panda):
    form = panda.linear_form()
    data = generate(panda, 256, 0)
    W = form.torque_regressor(data.q, data.qd, data.qdd).reshape(-1, len(form.names))
    offset = np.tile(np.eye(7), (len(data), 1))
    truth = np.array([1.0, -2.0, 3.0, -4.0, 5.0, -6.0, 7.0])
    y = data.tau.ravel() + offset @ truth
    held = [70 + j for j in range(7) if truth[j] < 0]
    coef, facts = feasible_fit(Compressed(np.hstack([W, offset]), y), 7, np.asarray(form.prior), 1e-6, held)
    free = [j for j in range(7) if truth[j] > 0]
    assert np.all(coef[held] >= 0.0) and np.all(coef[held] <= 1e-6)  # held at the bound they cross
    assert np.all(np.abs(coef[70:][free] - truth[free]) < 0.5)  # the free ones fitted, not pinned
    with pytest.raises(ValueError, match="nonnegative"):
        feasible_fit(Compressed(np.hstack([W, offset]), y), 7, np.asarray(form.prior), 1e-6, [3])


def test_the_feasible_configuration_holds_friction_and_rotor_inertia_nonnegative_and_a_body_feasible(panda):
    from bench.physics.effects import EFFECTS

    data = generate(panda, 512, 0)
    b, fc = np.linspace(0.2, 0.8, 7), np.linspace(0.3, 1.2, 7)
    rotor, offset = np.linspace(0.0, 0.6, 7), np.linspace(-1.0, 1.0, 7)  # joint 1's rotor acts as link 1's ZZ does
    drive = b * data.qd + fc * np.sign(data.qd) + rotor * data.qdd + offset
    train = data.replace(tau=data.tau + drive)
    model = METHODS["sysid"](**METHODS["sysid"].configuration("feasible")).fit(train, "indirect", 0, budget=Budget(steps=1))
    values = model.identified_parameters()
    fitted = {name: np.array([values[f"{name}_{j}"] for j in range(1, 8)]) for name in ("b", "F_c", "I_a", "tau_0")}
    np.testing.assert_allclose(fitted["b"], b, atol=0.05)
    np.testing.assert_allclose(fitted["F_c"], fc, atol=0.05)
    np.testing.assert_allclose(fitted["I_a"][1:], rotor[1:], atol=0.05)
    np.testing.assert_allclose(fitted["tau_0"], offset, atol=0.05)  # an offset may be negative
    # b, F_c and I_a of each joint held at 0 or above; tau_0 free
    assert model.linear.feasible.nonnegative == tuple(70 + 4 * j + k for j in range(7) for k in range(3))
    assert min(smallest_eigenvalues(model.linear.coef[:70], 7)) >= 0.0
    assert all(EFFECTS[e].nonnegative for e in ("viscous_friction", "coulomb_friction", "armature"))
    assert not EFFECTS["offset"].nonnegative


def test_the_residual_loop_refits_a_feasible_fit_under_its_constraints(panda):
    from bench.residual.library import loop_library
    from bench.residual.model import LoopModel
    from bench.residual.strategies import Feasible, Linear, strategy_for

    train = add_noise(generate(panda, 512, 0), "indirect", 0.05, 0)
    feasible = METHODS["sysid"]().fit(train, "indirect", 0, budget=Budget(steps=1))
    ls = METHODS["sysid"](feasible=False).fit(train, "indirect", 0, budget=Budget(steps=1))
    assert type(strategy_for(ls)) is Linear and type(strategy_for(feasible)) is Feasible
    strategy = strategy_for(feasible)
    offsets = [t for t in loop_library(train.dof) if t.name == "offset"]
    assert len(offsets) == 7
    refitted = strategy.refit(LoopModel.bare(feasible.linear), train, offsets)
    after = strategy.feasibility(refitted, train)
    assert after["feasible"] and min(after["smallest_eigenvalues"]) >= 0.0
    before = Linear().feasibility(LoopModel.bare(ls.linear), train)
    assert not before["feasible"]
