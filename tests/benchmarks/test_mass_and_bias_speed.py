"""An arm's linear model's ``M`` and ``c`` at a driven rollout's batch of
states (98 windows of the KUKA's test trajectory, one step each): from
Pinocchio's CRBA and RNEA at the model's parameters (``ours``,
:meth:`systems.urdf_arm.UrdfArm.mass_and_bias_at`), against Pinocchio's
torque regressor at ``dof + 1`` accelerations a state (the rule of every
other model, :meth:`bench.physics.models.FittedModel.mass_and_bias`). The
model is the KUKA's least-squares fit at random base parameters; both give
the same ``M`` and ``c`` (tests/systems/test_urdf.py). A second group does
the same for DeLaN's network (tests/methods/test_delan.py checks the two
agree). Run with ``make benchmark``; the table after it gives each time
relative to ours."""

from __future__ import annotations

import numpy as np
import pytest

from bench.physics.linear import LinearParametricModel
from bench.physics.models import FittedModel

pytestmark = pytest.mark.benchmark

N_STATES = 98


@pytest.fixture(scope="module")
def setup():
    from systems import get_system

    system = get_system("kuka_lwr4")
    form = system.linear_form()
    rng = np.random.default_rng(0)
    columns = np.sort(rng.choice(len(form.names), 40, replace=False))
    model = LinearParametricModel(form, columns, rng.normal(size=len(columns)))
    q, qd = rng.uniform(-1, 1, (N_STATES, system.dof)), rng.uniform(-1, 1, (N_STATES, system.dof))
    model.mass_and_bias(q, qd)  # the engine's two models, built once a parameter vector
    return model, q, qd


def _time(benchmark, group: str, setup, own: bool) -> None:
    """The model's own ``M`` and ``c`` (``own``), or the rule of every other model, at the setup's states."""
    model, q, qd = setup
    benchmark.group = group
    fn = model.mass_and_bias if own else (lambda q, qd: FittedModel.mass_and_bias(model, q, qd))
    benchmark.pedantic(fn, args=(q, qd), rounds=20, iterations=1)


def test_mass_and_bias_from_the_engine_ours(benchmark, setup):
    _time(benchmark, "mass-and-bias", setup, own=True)


def test_mass_and_bias_from_the_regressor(benchmark, setup):
    _time(benchmark, "mass-and-bias", setup, own=False)


@pytest.fixture(scope="module")
def delan_setup():
    """A DeLaN of the KUKA's seven joints in its default size, a few steps into its fit, evaluated in float64
    as after any fit, at the same states."""
    from bench.core.budget import Budget
    from methods import METHODS
    from systems import get_system

    train = get_system("kuka_lwr4").load("train")
    model = METHODS["delan"](compile=False).fit(train, "indirect", 0, budget=Budget(steps=2))
    rng = np.random.default_rng(0)
    return model, rng.uniform(-1, 1, (N_STATES, train.dof)), rng.uniform(-1, 1, (N_STATES, train.dof))


def test_delan_mass_and_bias_from_one_pass_ours(benchmark, delan_setup):
    """DeLaN's ``H(q)`` and its torque at ``qdd = 0`` from one pass of its own derivatives
    (:meth:`methods.delan.DeLaN.mass_and_bias`), against the torque at ``dof + 1`` accelerations a state."""
    _time(benchmark, "delan-mass-and-bias", delan_setup, own=True)


def test_delan_mass_and_bias_from_the_torque(benchmark, delan_setup):
    _time(benchmark, "delan-mass-and-bias", delan_setup, own=False)
