"""How far a state lies from the states a model was fitted on.

A state is ``(q, qd)``, each coordinate divided by its standard deviation over
the training states, so that a radian and a radian per second weigh by how
much each varies in the data; the distance is the Euclidean one to the
nearest training state in that space (scipy's k-d tree). The same distance
gates a hybrid's residual (:mod:`methods.hybrid`) and bins a test set's
samples by how far they are from what the model saw
(:mod:`bench.evaluation.distance_bins`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from bench.core.data import Dataset


class TrainingStates:
    """The training states, scaled, with a k-d tree for the nearest of them."""

    def __init__(self, train: Dataset):
        states = np.hstack([train.q, train.qd])
        self.scale = np.maximum(states.std(axis=0), 1e-12)
        self.tree = cKDTree(states / self.scale)

    @classmethod
    def scaled(cls, states: np.ndarray, scale: np.ndarray) -> "TrainingStates":
        """The training states already divided by their ``scale`` (as a saved model holds them)."""
        out = cls.__new__(cls)
        out.scale = np.asarray(scale, dtype=np.float64)
        out.tree = cKDTree(np.asarray(states, dtype=np.float64))
        return out

    def distance(self, data: Dataset) -> np.ndarray:
        """Each state of ``data``'s distance to the nearest training state, shape ``(n,)``.

        A state repeated in consecutive rows is looked up once: the forward
        dynamics ask for each state's torque at ``dof + 1`` accelerations in a
        row (:func:`bench.physics.models.mass_and_bias`), and in 14 dimensions
        a nearest-state query costs about a millisecond on 70,000 training
        states, so a 7-joint rollout would otherwise repeat it eight times a step."""
        if not len(data):
            return np.zeros(0)
        states = np.hstack([data.q, data.qd]) / self.scale
        starts = np.ones(len(states), dtype=bool)
        starts[1:] = np.any(states[1:] != states[:-1], axis=1)
        distance, _ = self.tree.query(states[starts])
        runs = np.diff(np.append(np.flatnonzero(starts), len(states)))
        return np.repeat(np.asarray(distance, dtype=np.float64), runs)
