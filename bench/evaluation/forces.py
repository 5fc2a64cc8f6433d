"""The force decomposition of a model's torque, against the system's own.

Every Lagrangian's torque splits into an inertial part ``M(q) qdd``, a
Coriolis and centrifugal part ``c(q, qd)`` and a gravitational part ``g(q)``
(DeLaN's paper reports each against the truth). They follow from any model's
torques, with no access to its insides:

* ``g = tau(q, 0, 0)``;
* ``c = tau(q, qd, 0) - g``;
* ``M qdd = tau(q, 0, qdd) - g``.

The system gives its true parts (:meth:`bench.physics.system.System.forces`);
a model that is no Lagrangian of ``(q, qd)`` (its torque is not affine in
``qdd``) has no such split and is not scored.
"""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset, mse
from bench.physics.models import FittedModel
from bench.physics.system import FORCES, System


def decomposition(model: FittedModel, data: Dataset) -> dict[str, np.ndarray]:
    """``{"inertial", "coriolis", "gravity"}`` of ``model``'s torque at the states of ``data``, each ``(n, dof)``."""
    zero = np.zeros_like(data.q)

    def torque(qd, qdd):
        return np.asarray(model.predict_torque(Dataset(data.q, qd, qdd, zero)), dtype=np.float64)

    gravity = torque(zero, zero)
    return {"inertial": torque(zero, data.qdd) - gravity, "coriolis": torque(data.qd, zero) - gravity,
            "gravity": gravity}


def forces_entry(model: FittedModel, system: System, data: Dataset) -> dict | None:
    """The record's ``forces`` entry: the MSE of each part against the
    system's, with the variance of the true part beside it; ``None`` where
    the system does not know its parts or the model has none."""
    truth = system.forces(data)
    if truth is None or model.not_a_lagrangian():
        return None
    learned = decomposition(model, data)
    out = {}
    for part in FORCES:
        out[f"{part}_mse"] = mse(learned[part], truth[part])
        out[f"{part}_variance"] = float(np.var(truth[part]))
    return out
