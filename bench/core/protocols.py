"""Validation protocols in state space, beside the one of time
(:mod:`bench.core.folds`): folds whose scored samples lie as far from the
states they are fitted on as a model's use will ask.

Folds of spans in time of one trajectory score states a few hundredths of a
training standard deviation from the fitted ones: they measure
interpolation, while the next trajectory may lie a whole standard deviation
or more away (:mod:`bench.evaluation.domain`). Each protocol here is a
scikit-learn splitter (``split(X, y, groups)``, ``get_n_splits``), ``X``
being the states ``(q, q̇)`` divided by their standard deviations, so that
it serves as any ``cv`` argument, and :func:`folds` makes the suite's
:class:`~bench.core.folds.Folds` of a dataset with it:

* :class:`Regions`, **leave-region-out**: k-means clusters of the states
  (scikit-learn's ``KMeans``), then ``GroupKFold`` on the cluster labels, so
  that each fold holds out whole regions of the state space (Roberts et al.,
  Ecography 2017, call this blocking);
* :class:`KNNDM`, **k-fold nearest-neighbour distance matching** (Linnenbrink
  et al., GMD 2024, after Milà et al., MEE 2022): of the folds of time and
  those of k regions for k from the folds' count upwards, the one whose
  scored samples' distances to the nearest fitted state are distributed most
  like the target's distances to the nearest training state (the Wasserstein
  distance between the two samples, ``scipy.stats.wasserstein_distance``).
  Few regions hold out far states, many near ones, the folds of time the
  nearest; the target decides.

:func:`folds` makes the folds of a protocol named as ``--folds`` names it:
``time``, ``regions`` or ``knndm`` (its target the spread between the
training trajectories, :func:`bench.evaluation.domain.spread`'s distances) or
``knndm:LOG`` (the states of a log, its torques not read); ``auto`` is the
folds of time where the data hold several trajectories (each held out whole
reaches as far as the trajectories lie apart) or none (independent samples),
and regions where they hold one, whose spans in time only interpolate.
``pooled`` (``bench select``'s default) is ``auto`` but for two or three
trajectories (at most :data:`POOLED_UP_TO`), whose states it pools into
regions: left out whole, each of so few trajectories leaves a fold fitted on
one or two of them, far less than the final fit on all of them sees, while a
fold of regions is fitted on part of every one.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from bench.core.csv_format import read_csv
from bench.core.data import Dataset
from bench.core.distance import TrainingStates
from bench.core.errors import ConfigError
from bench.core.folds import MAX_SPANS, Fold, Folds, folds as time_folds, mask

#: the protocols ``--folds`` names
NAMES = ("time", "regions", "knndm", "auto", "pooled")
#: the most training trajectories whose states ``pooled`` folds into regions (more are left out whole)
POOLED_UP_TO = 3
#: at most this many scored samples a fold's distances are measured on, drawn with a fixed seed
DISTANCE_SAMPLES = 2000
#: the region counts kNNDM tries: the folds' count times these
REGION_FACTORS = (1, 2, 4, 8, 16, 32)


def states(data: Dataset, scale: np.ndarray | None = None) -> np.ndarray:
    """``(q, q̇)`` of ``data`` divided by ``scale`` (default: their own standard deviations)."""
    x = np.hstack([data.q, data.qd]).astype(np.float64)
    return x / (np.maximum(x.std(axis=0), 1e-12) if scale is None else scale)


def regions(x: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """Each state's region: ``count`` k-means clusters (fixed seed)."""
    from sklearn.cluster import KMeans  # here: scikit-learn takes a second to import

    count = max(1, min(count, len(x)))
    return KMeans(n_clusters=count, n_init=3, random_state=seed).fit_predict(x)


def _grouped(labels: np.ndarray, n_splits: int):
    from sklearn.model_selection import GroupKFold

    return GroupKFold(n_splits=n_splits).split(np.zeros(len(labels)), groups=labels)


class Regions:
    """Leave-region-out folds: ``n_splits`` folds of ``count`` k-means regions of the states
    (``count`` defaults to ``n_splits``: each fold one region)."""

    name = "regions"

    def __init__(self, n_splits: int = 4, count: int | None = None, seed: int = 0):
        self.n_splits, self.count, self.seed = n_splits, count or n_splits, seed

    def get_n_splits(self, X=None, y=None, groups=None) -> int:
        return self.n_splits

    def split(self, X, y=None, groups=None):
        yield from _grouped(regions(np.asarray(X), self.count, self.seed), self.n_splits)

    def describe(self) -> str:
        return (f"{self.n_splits} folds of {self.count} regions of the states (k-means in q and q̇, each in its "
                f"standard deviations; GroupKFold on the regions)")


def fold_distances(x: np.ndarray, held: list[np.ndarray], seed: int = 0) -> np.ndarray:
    """Each fold's scored samples' distances to the nearest state it is fitted on, pooled
    (at most :data:`DISTANCE_SAMPLES` a fold, drawn with ``seed``)."""
    from scipy.spatial import cKDTree  # here: the command line reads NAMES, and needs no scipy

    rng = np.random.default_rng(seed)
    out = []
    for mask in held:
        index = np.flatnonzero(mask)
        if len(index) > DISTANCE_SAMPLES:
            index = np.sort(rng.choice(index, DISTANCE_SAMPLES, replace=False))
        fitted = x[~mask]
        if not len(fitted) or not len(index):
            continue
        out.append(cKDTree(fitted).query(x[index])[0])
    return np.concatenate(out) if out else np.zeros(0)


class KNNDM:
    """kNNDM (see the module docstring): the folds of time or of ``k`` regions whose held-out distances
    match ``target`` (distances to the nearest training state, in the training states' standard deviations)
    best. ``time`` is the folds of time of the same data as ``X`` (held masks, of any count), where they are
    among the fold sets tried."""

    name = "knndm"

    def __init__(self, target: np.ndarray, n_splits: int = 4, seed: int = 0, time: list[np.ndarray] | None = None):
        self.target = np.asarray(target, dtype=np.float64)
        if not len(self.target):
            raise ConfigError("kNNDM needs a target: distances of the states a model will be asked")
        self.n_splits, self.seed, self.time = n_splits, seed, time
        self.tried: list[dict] = []
        self.chosen: dict | None = None

    def get_n_splits(self, X=None, y=None, groups=None) -> int:
        return self.n_splits

    def _fold_sets(self, x: np.ndarray):
        if self.time is not None:
            yield "time", self.time
        for factor in REGION_FACTORS:
            k = self.n_splits * factor
            if k > len(x) // 10 and factor > 1:
                break
            labels = regions(x, k, self.seed)
            yield f"{k} regions", [mask(len(x), test) for _, test in _grouped(labels, self.n_splits)]

    def held(self, X) -> list[np.ndarray]:
        """The chosen fold set's held-out masks (and :attr:`tried`, :attr:`chosen`)."""
        from scipy.stats import wasserstein_distance

        x = np.asarray(X, dtype=np.float64)
        best, self.tried = None, []
        for label, held in self._fold_sets(x):
            d = fold_distances(x, held, self.seed)
            w = float(wasserstein_distance(d, self.target)) if len(d) else math.inf
            self.tried.append({"folds": label, "wasserstein": w, "median_distance": float(np.median(d)) if len(d) else None})
            if best is None or w < best[0]:
                best = (w, label, held)
        self.chosen = next(t for t in self.tried if t["folds"] == best[1])
        return best[2]

    def split(self, X, y=None, groups=None):
        for mask in self.held(X):
            yield np.flatnonzero(~mask), np.flatnonzero(mask)

    def describe(self) -> str:
        chosen = self.chosen or {}
        return (f"kNNDM: of the folds of time and of k-means regions of the states, the {chosen.get('folds')} "
                f"whose held-out distances match the target's best (Wasserstein {chosen.get('wasserstein', math.nan):.3g}; "
                f"median held-out distance {chosen.get('median_distance') or math.nan:.3g} against the target's "
                f"{float(np.median(self.target)):.3g})")


def parse(name: str | None) -> tuple[str, str | None]:
    """``(protocol, target log)`` of a ``--folds`` value (``knndm:LOG`` names its target's log)."""
    kind, _, path = (name or "time").partition(":")
    if kind not in NAMES or (path and kind != "knndm"):
        raise ConfigError(f"--folds: unknown protocol {name!r}; they are {', '.join(NAMES)} and knndm:LOG")
    return kind, path or None


def resolve(kind: str, trajectories: int) -> str:
    """The folds ``auto`` stands for on training data of ``trajectories`` trajectories: whole trajectories
    (``time``) where there are several, ``regions`` where there is one; ``pooled`` is ``regions`` up to
    :data:`POOLED_UP_TO` trajectories too; any other kind is itself."""
    if kind == "pooled":
        return "regions" if 1 <= trajectories <= POOLED_UP_TO else "time"
    if kind != "auto":
        return kind
    return "regions" if trajectories == 1 else "time"


def folds(data: Dataset, name: str | None, max_folds: int | None, target: Dataset | None = None) -> Folds:
    """The folds of ``data`` by the protocol ``name`` (:data:`NAMES`, or ``knndm:LOG``; ``None``: ``time``), at
    most ``max_folds`` of them; ``target`` is kNNDM's states (default: ``LOG``'s positions and velocities, else
    the spread between the training trajectories)."""
    kind, path = parse(name)
    if path is not None and target is None:
        target = read_csv(path, dof=data.dof, states_only=True)
    kind = resolve(kind, len(data.trajectories()))
    if kind == "time":
        return time_folds(data, max_folds=max_folds)
    x = states(data)
    n_splits = min(max_folds or MAX_SPANS, len(data))
    counts = {"recordings": len(data.recordings()), "trajectories": len(data.trajectories())}
    if kind == "regions":
        splitter = Regions(n_splits)
        held = [mask(len(data), test) for _, test in splitter.split(x)]
        return Folds(tuple(Fold(m, m) for m in _ordered(held)), "regions", detail=splitter.describe(), **counts)
    distances = target_distances(data, target)
    if distances is None:
        raise ConfigError("--folds knndm: the training data hold one trajectory and no target was named "
                          "(--target-states LOG): nothing to match the folds' distances to")
    by_time = time_folds(data, max_folds=max_folds)
    splitter = KNNDM(distances, n_splits, time=[f.held for f in by_time])
    held = splitter.held(x)
    if splitter.chosen["folds"] == "time":
        return dataclasses.replace(by_time, detail=splitter.describe() + f": {by_time.describe()}",
                                   choices=splitter.tried)
    return Folds(tuple(Fold(m, m) for m in _ordered(held)), "knndm", detail=splitter.describe(),
                 choices=splitter.tried, **counts)


def target_distances(data: Dataset, target: Dataset | None) -> np.ndarray | None:
    """The target's distances to the nearest training state, in the training states' standard deviations:
    ``target``'s states, else each training trajectory's from the others' (``None`` for one trajectory)."""
    from scipy.spatial import cKDTree

    if target is not None:
        return TrainingStates(data).distance(target)
    names = data.trajectories()
    if not names or len(names) < 2:
        return None
    x, labels = states(data), data.trajectory_labels()
    return np.concatenate([cKDTree(x[labels != name]).query(x[labels == name])[0] for name in names])


def _ordered(held: list[np.ndarray]) -> list[np.ndarray]:
    return sorted(held, key=lambda m: int(np.argmax(m)))
