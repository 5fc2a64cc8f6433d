"""The gauge-aware exact-recovery metric."""

from __future__ import annotations

import pytest
import sympy

from bench.core import symbolic
from bench.evaluation.recovery import judge


@pytest.fixture(scope="module")
def truth(double_pendulum):
    return double_pendulum.lagrangian_sympy


def syms():
    return symbolic.coordinate_symbols(2)


def test_the_truth_is_exact_in_both_experiments(truth):
    for experiment in ("direct", "indirect"):
        v = judge(truth, truth, 2, experiment)
        assert v.exact and v.symbolic and v.numeric


def test_an_added_constant_is_accepted_in_both_experiments(truth):
    for experiment in ("direct", "indirect"):
        assert judge(truth + 12.5, truth, 2, experiment).exact


def test_an_added_total_time_derivative_is_accepted_indirectly(truth):
    (q1, q2), (qd1, qd2) = syms()
    F = sympy.sin(q1) * q2 + q1**2
    dFdt = sympy.diff(F, q1) * qd1 + sympy.diff(F, q2) * qd2
    assert judge(truth + 3 * dFdt, truth, 2, "indirect").exact
    # the values of L differ, so directly it is not the same Lagrangian
    assert not judge(truth + 3 * dFdt, truth, 2, "direct").exact


def test_an_equivalent_trigonometric_form_is_accepted(truth):
    (q1, q2), (qd1, qd2) = syms()
    rewritten = truth.subs(sympy.cos(q1 - q2), sympy.cos(q1) * sympy.cos(q2) + sympy.sin(q1) * sympy.sin(q2))
    assert rewritten != truth
    assert judge(rewritten, truth, 2, "indirect").exact and judge(rewritten, truth, 2, "direct").exact


def test_a_scaled_lagrangian_is_accepted_only_up_to_scale(truth):
    assert not judge(2.5 * truth, truth, 2, "indirect").exact  # torques fix the scale
    assert judge(2.5 * truth, truth, 2, "indirect", up_to_scale=True).exact


@pytest.mark.parametrize("miss", ["coefficient", "term", "argument"])
def test_near_misses_are_rejected(truth, miss):
    (q1, q2), (qd1, qd2) = syms()
    if miss == "coefficient":
        near = truth + 1e-3 * qd1**2
    elif miss == "term":
        near = truth + 1e-3 * qd1 * q2
    else:
        near = truth.subs(sympy.cos(q1 - q2), sympy.cos(1.001 * q1 - q2))
    for experiment in ("direct", "indirect"):
        v = judge(near, truth, 2, experiment)
        assert not v.exact, (miss, experiment)


def test_tiny_float_noise_within_the_tolerance_is_rounded_away(truth):
    (q1, q2), (qd1, qd2) = syms()
    noisy = truth + 1e-9 * qd1**2 + 1e-10 * sympy.sin(q2)
    v = judge(noisy, truth, 2, "indirect")
    assert v.exact and v.symbolic


def test_even_functions_of_absolute_values_are_recognised(truth):
    (q1, q2), _ = syms()
    rewritten = truth.subs(sympy.cos(q1), sympy.cos(sympy.Abs(q1)))
    assert rewritten != truth
    assert judge(rewritten, truth, 2, "indirect").exact
