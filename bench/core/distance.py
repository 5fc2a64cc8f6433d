"""How far a state lies from the states a model was fitted on.

A state is ``(q, qd)``, each coordinate divided by its standard deviation over
the training states, so that a radian and a radian per second weigh by how
much each varies in the data; the distance is the Euclidean one to the
nearest training state in that space (:class:`NearestStates`). The same distance
gates a hybrid's residual (:mod:`methods.hybrid`) and bins a test set's
samples by how far they are from what the model saw
(:mod:`bench.evaluation.distance_bins`).
"""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset
from bench.core.kept import Kept, digest, read_only


#: a log of more states than this is searched through a coarse tree of about :data:`KEPT` of them first
THINNED_ABOVE = 20000
#: the coarse tree's states: every ``ceil(n / KEPT)``-th
KEPT = 5000
#: ... where no state lies farther than this from the nearest kept one (else the plain tree)
REACH_MAX = 0.5
#: the indexes a process keeps (:meth:`NearestStates.of`), and the queries each keeps the answers to
KEPT_INDEXES, KEPT_QUERIES = 6, 8


class NearestStates:
    """Each query point's exact Euclidean distance to the nearest of ``states``.

    Below :data:`THINNED_ABOVE` states this is scipy's k-d tree. A longer log
    is searched in two stages: a k-d tree of every k-th state (about
    :data:`KEPT`) gives each query's distance ``d`` to the nearest kept state,
    and every state has a kept one within ``reach`` of it; so the nearest
    state of all is owned by a kept state within ``d + reach``, and only the
    states those kept ones own (each state is owned by its nearest kept one)
    are measured. The answer is the same as the plain tree's (to rounding);
    in 14 dimensions a k-d tree examines much of a large set of states lying
    along curves, and the two stages are about six times quicker on 70,000
    states of a 7-joint arm (``make benchmark``, group ``gate-query``). Where
    the states are not samples of smooth motion (a state farther than
    :data:`REACH_MAX` from every kept one), the balls would hold most states,
    and the plain tree is used.

    :meth:`of` gives the index of states a process has indexed before, and an
    index answers a query it was asked before from what it measured then. A
    tuned hybrid's fold fits (:mod:`bench.evaluation.tuning`) are gated by
    their fold's training states and scored on its held-out states, one fit
    for each combination and rung, so the same index and the same queries
    recur; held-out trajectories lie far from the fitted states, where the
    balls hold many states and a query is slow."""

    #: the indexes built in this process, by their states' :func:`~bench.core.kept.digest`
    _built = Kept(KEPT_INDEXES)

    @classmethod
    def of(cls, states: np.ndarray) -> "NearestStates":
        """The index of ``states``: the one built before in this process for the same states (at most
        :data:`KEPT_INDEXES` are kept), else a new one."""
        states = np.ascontiguousarray(states, dtype=np.float64)
        return cls._built.get(digest(states), lambda: cls(states))

    def __init__(self, states: np.ndarray):
        from scipy.spatial import cKDTree  # here: the command line reads modules that use this one, not scipy

        self.states = np.ascontiguousarray(states, dtype=np.float64)
        self._answers = Kept(KEPT_QUERIES)
        n = len(self.states)
        self.coarse: cKDTree | None = None
        if n > THINNED_ABOVE:
            coarse = cKDTree(self.states[:: -(-n // KEPT)])
            near, owner = coarse.query(self.states)
            reach = float(near.max())
            if reach <= REACH_MAX:
                self.coarse, self.reach = coarse, reach
                self.owned = np.argsort(owner, kind="stable")
                self.first = np.searchsorted(owner[self.owned], np.arange(coarse.n + 1))
        self.tree = cKDTree(self.states) if self.coarse is None else None

    def query(self, x: np.ndarray) -> np.ndarray:
        """The distances, shape ``(len(x),)``; the answer to a query asked before (the last
        :data:`KEPT_QUERIES`) is given again, not measured."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        if not len(x):
            return np.zeros(0)
        return self._answers.get(digest(x), lambda: read_only(self._measure(x)))

    def _measure(self, x: np.ndarray) -> np.ndarray:
        if self.coarse is None:
            return np.asarray(self.tree.query(x)[0], dtype=np.float64)
        d, _ = self.coarse.query(x)
        balls = self.coarse.query_ball_point(x, (d + self.reach) * (1 + 1e-9) + 1e-12)
        kept = np.concatenate([np.asarray(b, dtype=np.intp) for b in balls])
        owned = self.first[kept + 1] - self.first[kept]
        rows = self.owned[np.arange(owned.sum()) + np.repeat(self.first[kept] - np.cumsum(owned) + owned, owned)]
        per_query = np.add.reduceat(owned, np.cumsum([0] + [len(b) for b in balls[:-1]]))
        diff = self.states[rows] - np.repeat(x, per_query, axis=0)
        return np.sqrt(np.minimum.reduceat(np.einsum("ij,ij->i", diff, diff), np.cumsum(per_query) - per_query))


class TrainingStates:
    """The training states, scaled, and the nearest of them (:class:`NearestStates`)."""

    def __init__(self, train: Dataset):
        states = np.hstack([train.q, train.qd])
        self.scale = np.maximum(states.std(axis=0), 1e-12)
        self.index = NearestStates.of(states / self.scale)

    @classmethod
    def scaled(cls, states: np.ndarray, scale: np.ndarray) -> "TrainingStates":
        """The training states already divided by their ``scale`` (as a saved model holds them)."""
        out = cls.__new__(cls)
        out.scale = np.asarray(scale, dtype=np.float64)
        out.index = NearestStates.of(states)
        return out

    @property
    def states(self) -> np.ndarray:
        """The training states, divided by :attr:`scale`."""
        return self.index.states

    def distance(self, data: Dataset) -> np.ndarray:
        """Each state of ``data``'s distance to the nearest training state, shape ``(n,)``.

        A state repeated in consecutive rows is looked up once: the forward
        dynamics ask for each state's torque at ``dof + 1`` accelerations in a
        row (:func:`bench.physics.models.mass_and_bias`), and in 14 dimensions
        a nearest-state query costs about a millisecond on 70,000 training
        states (a sixth of that through :class:`NearestStates`' two stages),
        so a 7-joint rollout would otherwise repeat it eight times a step."""
        if not len(data):
            return np.zeros(0)
        states = np.hstack([data.q, data.qd]) / self.scale
        starts = np.ones(len(states), dtype=bool)
        starts[1:] = np.any(states[1:] != states[:-1], axis=1)
        runs = np.diff(np.append(np.flatnonzero(starts), len(states)))
        return np.repeat(self.index.query(states[starts]), runs)
