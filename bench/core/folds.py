"""The suite's one validation protocol: how training data are folded whenever
anything is chosen by its error on data it was not fitted on (the residual
loop's held-out checks, a hybrid's or any method's tuning, ``bench select``).

Neighbouring samples of a recording are near copies, and a robot that repeats
an excitation trajectory records a near copy of it each time; a choice tested
on either is not tested. The folds are therefore

* **trajectories** where the data name two or more
  (:meth:`~bench.core.data.Dataset.trajectories`): every recording of a
  trajectory in one fold, by scikit-learn's ``GroupKFold`` (one trajectory a
  fold unless ``max_folds`` asks for fewer);
* **spans in time** where they name one trajectory: the trajectory cut into
  up to :data:`MAX_SPANS` contiguous spans, the same span of each recording
  of it held out together; and a span is scored only where it lies at least
  the torque's integrated autocorrelation time
  (:func:`bench.core.autocorrelation.integrated_time`, the slowest joint of the
  slowest recording) from the samples the fold is fitted on: the samples
  within that *gap* of a neighbouring span are neither fitted nor scored. As
  many spans are cut as leave each span at least :data:`MIN_SCORED` of its
  samples scored; where even two spans cannot, the gap is what leaves two
  spans half scored, and the description says it is shorter than the
  autocorrelation time;
* **blocks** of independent samples (generated data, no recordings):
  up to :data:`MAX_SPANS` contiguous blocks (scikit-learn's ``KFold``), as good
  as any other split for independent draws.

A :class:`Fold` holds out ``held`` (not fitted on) and scores ``score``
(``held`` less its gap). The ``held`` masks of the folds partition the
samples, which lets a linear problem's folds be compressed once
(:mod:`bench.residual.validation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench.core.autocorrelation import integrated_time
from bench.core.data import Dataset

#: at most this many spans of one trajectory, or blocks of independent samples
MAX_SPANS = 4
#: the share of a span that must stay scored after its gaps
MIN_SCORED = 0.5


@dataclass(frozen=True)
class Fold:
    """One fold: ``held`` (boolean, one per sample) is left out of the fit,
    ``score`` (within ``held``) is where the fit is scored."""

    held: np.ndarray
    score: np.ndarray

    @property
    def fit(self) -> np.ndarray:
        """The samples the fold is fitted on."""
        return ~self.held


@dataclass(frozen=True)
class Folds:
    """The folds of one dataset (see the module docstring).

    ``kind`` is ``trajectories``, ``spans`` or ``blocks``; ``gap`` the samples
    left unscored at each end of a span next to a fitted one (0 for the other
    kinds); ``autocorrelation`` the torque's integrated autocorrelation time
    in samples, where one was measured."""

    folds: tuple[Fold, ...]
    kind: str
    gap: int = 0
    autocorrelation: float | None = None
    recordings: int = 0
    trajectories: int = 0
    #: how a protocol of :mod:`bench.core.protocols` made the folds, in words (``None``: the kinds above)
    detail: str | None = None
    #: what a protocol that chooses among fold sets tried (kNNDM's fold sets and their match)
    choices: list | None = None

    def __len__(self) -> int:
        return len(self.folds)

    def __iter__(self):
        return iter(self.folds)

    def __getitem__(self, k: int) -> Fold:
        return self.folds[k]

    @property
    def held(self) -> list[np.ndarray]:
        """Each fold's held-out mask."""
        return [f.held for f in self.folds]

    def indices(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per fold, the indices it is fitted on and those it is scored on:
        scikit-learn's ``cv`` argument."""
        return [(np.flatnonzero(f.fit), np.flatnonzero(f.score)) for f in self.folds]

    def rows(self, dof: int) -> "Folds":
        """The same folds over the rows of a torque fit (``tau.ravel()``: ``dof`` rows a sample)."""
        return Folds(tuple(Fold(np.repeat(f.held, dof), np.repeat(f.score, dof)) for f in self.folds), self.kind,
                     self.gap, self.autocorrelation, self.recordings, self.trajectories, self.detail, self.choices)

    def describe(self) -> str:
        """How the data were folded, in words."""
        if self.detail:
            return self.detail
        n = len(self.folds)
        if self.kind == "trajectories":
            extra = f" ({self.recordings} recordings)" if self.recordings != self.trajectories else ""
            if n == self.trajectories:
                return f"leave one trajectory out, over {self.trajectories} trajectories{extra}"
            return f"{n} folds of whole trajectories (GroupKFold), over {self.trajectories} trajectories{extra}"
        if self.kind == "spans":
            tau = self.autocorrelation or 0.0
            short = "" if self.gap >= tau else f", shorter than the torque's integrated autocorrelation time ({tau:.0f})"
            return (f"{n} contiguous spans in time of one trajectory, each span of its {self.recordings} recording(s) "
                    f"held out together and scored only {self.gap} samples or more from the samples fitted on{short}")
        return f"{n} contiguous blocks of samples without recordings"

    def to_json(self) -> dict:
        """What a record says of the folds."""
        return {"kind": self.kind, "folds": len(self.folds), "gap_samples": self.gap,
                "autocorrelation_samples": None if self.autocorrelation is None else round(self.autocorrelation, 1),
                "scored": [int(f.score.sum()) for f in self.folds], "description": self.describe(),
                **({"choices": self.choices} if self.choices else {})}


def folds(data: Dataset, max_folds: int | None = None, values: np.ndarray | None = None) -> Folds:
    """The validation folds of ``data`` (see the module docstring). ``max_folds``
    caps the folds of whole trajectories (all of them by default); ``values``
    (``(n, k)``, default the torque) is what the gap's autocorrelation is measured on."""
    from sklearn.model_selection import GroupKFold, KFold  # here: scikit-learn takes a second to import

    names = data.trajectories()
    n = len(data)
    if len(names) >= 2:
        labels = data.trajectory_labels()
        splits = min(len(names), max_folds or len(names))
        held = [mask(n, test) for _, test in GroupKFold(n_splits=splits).split(np.zeros(n), groups=labels)]
        held.sort(key=lambda m: int(np.argmax(m)))  # in order of first appearance
        return Folds(tuple(Fold(m, m) for m in held), "trajectories", recordings=len(data.recordings()),
                     trajectories=len(names))
    if names:
        return _spans(data, data.tau if values is None else values)
    k = min(MAX_SPANS, n)
    held = [mask(n, test) for _, test in KFold(n_splits=k).split(np.zeros(n))] if k >= 2 else [np.ones(n, bool)]
    return Folds(tuple(Fold(m, m) for m in held), "blocks")


def mask(n: int, index: np.ndarray) -> np.ndarray:
    """A boolean mask of ``n`` samples, true at ``index``."""
    mask = np.zeros(n, dtype=bool)
    mask[index] = True
    return mask


def _spans(data: Dataset, values: np.ndarray) -> Folds:
    """Spans in time of one trajectory's recordings, with their gaps (see the module docstring)."""
    from sklearn.model_selection import GroupKFold, KFold

    n = len(data)
    order = data.in_time_order()
    values = np.asarray(values, dtype=np.float64).reshape(n, -1)
    tau = max((integrated_time(values[index, c]) for index in order for c in range(values.shape[1])), default=1.0)
    shortest = min(len(index) for index in order)
    if shortest < 2:
        held = [mask(n, test) for _, test in KFold(n_splits=2).split(np.zeros(n))] if n >= 2 else [np.ones(n, bool)]
        return Folds(tuple(Fold(m, m) for m in held), "blocks")
    count = next((k for k in range(MAX_SPANS, 1, -1) if _gap_fits(math.ceil(tau), shortest, k)), 2)
    gap = math.ceil(tau)
    if not _gap_fits(gap, shortest, count):
        gap = int(shortest / count * (1.0 - MIN_SCORED))
    span = np.zeros(n, dtype=int)
    scored = np.zeros(n, dtype=bool)
    for index in order:
        length = len(index)
        position = np.arange(length)
        which = position * count // length
        start = np.searchsorted(which, which, side="left")
        end = np.searchsorted(which, which, side="right")
        inside = ((which == 0) | (position - start >= gap)) & ((which == count - 1) | (end - 1 - position >= gap))
        span[index], scored[index] = which, inside
    held = [mask(n, test) for _, test in GroupKFold(n_splits=count).split(np.zeros(n), groups=span)]
    held.sort(key=lambda m: int(span[np.argmax(m)]))
    return Folds(tuple(Fold(m, m & scored) for m in held), "spans", gap, tau, recordings=len(order), trajectories=1)


def _gap_fits(gap: int, length: int, count: int) -> bool:
    """Whether spans of a recording of ``length`` samples cut in ``count`` keep
    :data:`MIN_SCORED` of each span scored with ``gap`` samples off each inner end."""
    span = length / count
    ends = 1 if count == 2 else 2
    return span - ends * gap >= MIN_SCORED * span
