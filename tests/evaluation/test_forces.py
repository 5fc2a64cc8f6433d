"""The force decomposition: the systems' true parts against independent sources."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.core.data import generate
from bench.evaluation.forces import decomposition, forces_entry
from bench.evaluation.rollout import TrueModel
from systems import get_system
from bench.core.scoring import opened


def test_an_arms_parts_are_pinocchios_own():
    pin = pytest.importorskip("pinocchio")
    arm = get_system("panda")
    data = generate(arm, 40, 3)
    parts = arm.forces(data)
    model, pdata = arm.model, arm.model.createData()
    gravity = np.stack([pin.computeGeneralizedGravity(model, pdata, q) for q in data.q])
    coriolis = np.stack([pin.computeCoriolisMatrix(model, pdata, q, v) @ v for q, v in zip(data.q, data.qd)])
    M = np.stack([pin.crba(model, pdata, q) for q in data.q])
    M = np.triu(M) + np.transpose(np.triu(M, 1), (0, 2, 1))  # crba fills the upper triangle
    np.testing.assert_allclose(parts["gravity"], gravity, atol=1e-10)
    np.testing.assert_allclose(parts["coriolis"], coriolis, atol=1e-10)
    np.testing.assert_allclose(parts["inertial"], np.einsum("bij,bj->bi", M, data.qdd), atol=1e-10)


def test_the_true_model_scores_zero_and_a_wrong_one_does_not(double_pendulum):
    data = generate(double_pendulum, 64, 1)
    exact = forces_entry(TrueModel(double_pendulum), double_pendulum, data)
    assert exact["inertial_mse"] < 1e-20 and exact["coriolis_mse"] < 1e-20 and exact["gravity_mse"] < 1e-20
    assert exact["gravity_variance"] > 1.0
    heavier = get_system("double_pendulum", params=dataclasses.replace(double_pendulum.params,
                                                                       m2=2 * double_pendulum.params.m2))
    wrong = forces_entry(TrueModel(heavier), double_pendulum, data)
    assert wrong["inertial_mse"] > 1e-3 and wrong["gravity_mse"] > 1e-3


def test_delans_characters_ship_parts_that_add_up_to_their_torque():
    chars = get_system("delan_characters")
    test = opened(chars.load("test"))
    parts = chars.forces(test)
    np.testing.assert_allclose(sum(parts.values()), test.tau, atol=1e-6)
    assert chars.forces(test.replace(q=test.q + 1.0)) is None  # not rows of the file: not known


def test_a_models_parts_add_up_to_its_torque(double_pendulum):
    data = generate(double_pendulum, 32, 2)
    parts = decomposition(TrueModel(double_pendulum), data)
    np.testing.assert_allclose(sum(parts.values()), TrueModel(double_pendulum).predict_torque(data), atol=1e-9)
