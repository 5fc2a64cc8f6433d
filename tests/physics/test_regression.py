"""Least squares over term libraries, direct and indirect."""

from __future__ import annotations

import numpy as np
import pytest
import sympy

from bench.core import symbolic
from bench.physics import regression
from bench.core.data import generate
from bench.physics.terms import TermLibrary


def _basis():
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    return [qd1**2, qd2**2, qd1 * qd2 * sympy.cos(q1 - q2), sympy.cos(q1), sympy.cos(q2), q1 * qd2, sympy.sin(q2)]


def test_indirect_weights_equal_a_direct_solve_on_a_planted_case(double_pendulum):
    data = generate(double_pendulum, 400, 3)
    basis = _basis()
    F = TermLibrary.of_lagrangian(basis).design(data, "indirect")
    assert F.shape == (800, len(basis))
    planted = np.array([1.5, -0.7, 2.0, 30.0, -4.0, 0.25, 1.1])
    y = F @ planted
    np.testing.assert_allclose(regression.least_squares(F, y), planted, rtol=1e-10)
    np.testing.assert_allclose(regression.least_squares(F, y), np.linalg.solve(F.T @ F, F.T @ y), rtol=1e-8)


def test_fit_basis_recovers_the_double_pendulum_in_both_experiments(double_pendulum):
    data = generate(double_pendulum, 500, 4)
    truth = symbolic.to_numpy(double_pendulum.lagrangian_sympy, 2)
    for experiment in ("direct", "indirect"):
        expr, coef = regression.fit_basis(_basis(), data, experiment)
        # the spurious terms are thresholded away; the true ones are exact
        assert np.count_nonzero(coef) == 5
        if experiment == "direct":
            np.testing.assert_allclose(symbolic.to_numpy(expr, 2)(data.q, data.qd), truth(data.q, data.qd), rtol=1e-12)
        np.testing.assert_allclose(sorted(np.abs(coef[coef != 0])), sorted([7.1289, 0.4648166666666667, 2.22945, 65.48175, 8.19135]),
                                   rtol=1e-10)


def test_columns_with_no_euler_lagrange_image_are_dropped(double_pendulum):
    data = generate(double_pendulum, 100, 5)
    (q1, _), (qd1, _) = symbolic.coordinate_symbols(2)
    # a constant and a total time derivative d/dt(q1^2 / 2) = q1 qd1 have no torque
    F = TermLibrary.of_lagrangian([sympy.Integer(1), q1 * qd1, qd1**2]).design(data, "indirect")
    assert np.abs(F[:, :2]).max() < 1e-12
    coef = regression.thresholded_least_squares(F, F[:, 2] * 3.0)
    np.testing.assert_allclose(coef, [0.0, 0.0, 3.0], atol=1e-12)


def test_independent_columns_drop_gauge_duplicates(double_pendulum):
    data = generate(double_pendulum, 300, 6)
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    basis = [qd1**2, sympy.Integer(1), qd1 * sympy.cos(q1), 2 * qd1**2, sympy.cos(q2), qd2**2]
    F = TermLibrary.of_lagrangian(basis).design(data, "indirect")
    # the constant and d/dt sin(q1) have no torque; 2 qd1^2 repeats qd1^2
    assert regression.independent_columns(F).tolist() == [0, 4, 5]


def test_a_compressed_problem_fits_any_subset_of_columns_and_stacks_by_rows():
    from hypothesis import given, settings, strategies as st

    from bench.physics.regression import Compressed, least_squares

    @settings(max_examples=40, deadline=None)
    @given(seed=st.integers(0, 10_000), n=st.integers(3, 60), k=st.integers(1, 6), dependent=st.booleans())
    def check(seed, n, k, dependent):
        rng = np.random.default_rng(seed)
        F = rng.normal(size=(n, k)) * np.logspace(-3, 3, k)
        if dependent and k > 1:
            F[:, -1] = 2 * F[:, 0]  # a rank-deficient design takes the same minimum-norm fit
        y = rng.normal(size=n)
        problem = Compressed(F, y)
        for columns in ([0], list(range(k)), list(range(0, k, 2))):
            c = least_squares(F[:, columns], y)
            direct = float(np.sum((y - F[:, columns] @ c) ** 2))
            assert problem.rss(columns) == pytest.approx(direct, rel=1e-8, abs=1e-10)
        half = n // 2
        if half >= 1 and n - half >= 1:
            stacked = Compressed.stacked([Compressed(F[:half], y[:half]), Compressed(F[half:], y[half:])])
            np.testing.assert_allclose(stacked.coef(), least_squares(F, y), rtol=1e-7, atol=1e-9)

    check()
