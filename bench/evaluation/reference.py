"""The references every run on measured data is read against, in its record:
the standard model of a measured arm, and the constant of any measured system.

Each learner on a measured arm reads against what the field would identify
from the same samples: SysId's standard configuration, the rigid-body base
parameters plus Coulomb and viscous friction, the rotor's inertia and a
torque offset on each joint, by least squares (:mod:`methods.sysid`). :func:`standard_reference` fits it on the run's
training data (a solve of a few seconds, the same in every run of one data
split) and scores it as a run is scored: torque MSE on the training and test
data, the driven rollouts of the test recordings
(:mod:`bench.evaluation.driven`), and whether its mass matrix is positive
definite, without which it has no forward dynamics.

:func:`constant_reference` is the least a learner must beat: each joint's
mean training torque, predicted everywhere. A learner whose test MSE is above
it has learned nothing about the test data that a constant does not know.
"""

from __future__ import annotations

import numpy as np

from bench.core.budget import Budget
from bench.core.data import Dataset, mse
from bench.physics.system import System
from bench.evaluation.driven import driven_entry
from methods import METHODS
from methods.sysid import joint_columns

#: the method and configuration of the standard model
METHOD, CONFIGURATION = "sysid", "standard"


def applies(system: System) -> bool:
    """Whether ``system`` has a standard model to read against: a measured system linear in its parameters (an arm)."""
    return not system.simulated and system.linear_form() is not None


def standard_reference(system: System, train: Dataset, test: Dataset | None) -> dict:
    """The record's ``details.standard_model``: the standard model's train and
    test torque MSE, its driven rollouts where the test data name their
    recordings' times, and its fit's facts: the mass matrix's definiteness, and the joint columns it has
    (``joint_columns``), those the data did not identify (``dropped_joint_columns``) and those whose standard
    error exceeds their value (``joint_columns_not_significant``)."""
    model = METHODS[METHOD](**METHODS[METHOD].configuration(CONFIGURATION))
    model.fit(train, "indirect", 0, Budget(steps=1), system=system)
    facts = model.record_details()
    config = model.config
    out = {
        "method": METHOD, "configuration": CONFIGURATION,
        "joint_columns": [symbol for _, symbol in joint_columns(config.friction, config.drive)],
        "dropped_joint_columns": facts.get("dropped_joint_columns", []),
        "joint_columns_not_significant": facts.get("joint_columns_not_significant", []),
        "train_mse": mse(model.predict_torque(train), train.tau),
        "test_mse": None if test is None else mse(model.predict_torque(test), test.tau),
        "mass_matrix_positive_definite": facts.get("mass_matrix_positive_definite"),
        "mass_matrix_smallest_eigenvalue": facts.get("mass_matrix_smallest_eigenvalue"),
        "mass_matrix_states": facts.get("mass_matrix_states"),
        "mass_matrix_indefinite_states": facts.get("mass_matrix_indefinite_states"),
    }
    if test is not None and test.time is not None:
        out["rollout"] = driven_entry(model, test)
    return out


def constant_reference(train: Dataset, test: Dataset | None) -> dict:
    """The record's ``details.constant_model``: the training-mean torque of each
    joint (``tau``), and its train and test torque MSE."""
    tau = train.tau.mean(axis=0)
    return {"tau": [float(x) for x in tau], "train_mse": mse(np.broadcast_to(tau, train.tau.shape), train.tau),
            "test_mse": None if test is None else mse(np.broadcast_to(tau, test.tau.shape), test.tau)}


def against(model, reference, train: Dataset, test: Dataset | None) -> dict:
    """``model`` beside a model it is made of (a hybrid's prior), as
    ``details.references``: the reference's train and test torque MSE, the
    model's test MSE over it (``ratio``), and on the test data how often and by
    how much the model is worse than it: the share of test samples whose
    squared torque error (summed over the joints) is above the reference's
    (``worse_share``), and those samples' excess as a share of the
    reference's test MSE (``worse_by``)."""
    out = {"train_mse": mse(reference.predict_torque(train), train.tau), "test_mse": None}
    if test is not None and len(test):
        mine = np.sum((model.predict_torque(test) - test.tau) ** 2, axis=1)
        theirs = np.sum((reference.predict_torque(test) - test.tau) ** 2, axis=1)
        worse = mine > theirs
        out.update(test_mse=float(np.mean(theirs)) / test.dof, ratio=float(np.mean(mine) / max(np.mean(theirs), 1e-300)),
                   worse_share=float(np.mean(worse)),
                   worse_by=float(np.sum(mine[worse] - theirs[worse]) / max(np.sum(theirs), 1e-300)))
    return out
