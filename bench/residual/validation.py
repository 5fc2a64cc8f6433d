"""Held-out validation for the residual loop: by whole trajectories.

On a measured trajectory, neighbouring samples are near copies, so a choice
tested on rows interleaved with (or next to) the rows it was fitted on is not
tested at all; and a robot that repeats an excitation trajectory records a
near copy of it each time, so a choice tested on a repeat of the trajectory
it was fitted on is not tested either. Every choice the loop makes is
therefore judged by cross-validation over folds that are

* **one trajectory each** (leave one trajectory out, every recording of it
  together) where the data name two or more trajectories
  (:meth:`~bench.core.data.Dataset.trajectories`);
* where they name one trajectory, :data:`BLOCKS` contiguous spans of it in
  time, each span of every recording of it in one fold: the held-out span's
  repeats are held out with it, so what is tested is a part of the motion the
  fit has not seen (a weaker test than another trajectory, which such data
  cannot give);
* otherwise :data:`BLOCKS` contiguous blocks of the samples: for generated
  data, whose samples are independent draws, as good as any other split.

:func:`cv_mse` refits a linear problem without each fold and scores it on
that fold; the mean over all held-out rows is the figure the loop compares.
"""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset
from bench.core.regression import Compressed, least_squares

#: contiguous spans of one trajectory, or blocks of independent samples, where the data name fewer than two trajectories
BLOCKS = 4


def folds(data: Dataset) -> list[np.ndarray]:
    """Boolean masks over the samples, one per fold; every sample is held out once."""
    names = data.trajectories()
    if len(names) >= 2:
        labels = data.trajectory_labels()
        return [labels == name for name in names]
    if names:  # one trajectory: spans of it in time, aligned across its recordings
        block = np.zeros(len(data), dtype=int)
        for index in data.in_time_order():
            block[index] = np.arange(len(index)) * BLOCKS // max(len(index), 1)
        return [block == k for k in range(min(BLOCKS, len(data)))]
    block = np.arange(len(data)) * BLOCKS // max(len(data), 1)
    return [block == k for k in range(min(BLOCKS, len(data)))]


def describe(data: Dataset) -> str:
    """How :func:`folds` splits ``data``, in words."""
    names = data.trajectories()
    if len(names) >= 2:
        recordings = len(data.recordings())
        extra = f" ({recordings} recordings)" if recordings != len(names) else ""
        return f"leave one trajectory out, over {len(names)} trajectories{extra}"
    if names:
        recordings = len(data.recordings())
        return (f"{BLOCKS} contiguous spans in time of one trajectory, each span of its {recordings} recording(s) "
                f"held out together")
    return f"{BLOCKS} contiguous blocks of samples without recordings"


def row_folds(data: Dataset) -> list[np.ndarray]:
    """:func:`folds` over the rows of a torque fit (``tau.ravel()``: ``dof`` rows a sample)."""
    return [np.repeat(mask, data.dof) for mask in folds(data)]


def cv_fold_mse(F: np.ndarray, y: np.ndarray, held: list[np.ndarray]) -> np.ndarray:
    """The held-out mean squared residual of ``y ~ F`` in each fold of
    ``held`` (row masks), scored by a fit on the other rows. No columns:
    the mean of ``y**2`` in each fold.

    Where the folds split the rows (each row in one fold, as :func:`folds`
    gives them), each fold's rows are compressed once
    (:class:`~bench.core.regression.Compressed`) and the fit without a fold
    is that of the others' factors stacked: one QR of the whole problem in
    all, not one per fold, with the same fits."""
    sizes = np.asarray([max(int(m.sum()), 1) for m in held], dtype=np.float64)
    if F.shape[1] == 0:
        return np.asarray([float(y[m] @ y[m]) for m in held]) / sizes
    if not _splits(held, len(y)):
        out = []
        for mask in held:
            r = y[mask] - F[mask] @ least_squares(F[~mask], y[~mask])
            out.append(float(r @ r))
        return np.asarray(out) / sizes
    return _held_out_rss([Compressed(F[m], y[m]) for m in held]) / sizes


def _splits(held: list[np.ndarray], rows: int) -> bool:
    """Whether the folds ``held`` split the rows: each row in exactly one."""
    return np.array_equal(np.sum(held, axis=0), np.ones(rows))


def _held_out_rss(blocks: list[Compressed]) -> np.ndarray:
    """Each fold's residual sum of squares under the fit to the other folds,
    from their compressed problems stacked."""
    return np.asarray([block.residual_norm2(Compressed.stacked(blocks[:i] + blocks[i + 1:]).coef())
                       for i, block in enumerate(blocks)])


def cv_mse(F: np.ndarray, y: np.ndarray, held: list[np.ndarray]) -> float:
    """The held-out mean squared residual of ``y ~ F`` over the folds ``held``
    (:func:`cv_fold_mse`, weighted by the folds' sizes)."""
    sizes = np.asarray([int(m.sum()) for m in held], dtype=np.float64)
    return float(cv_fold_mse(F, y, held) @ sizes / max(sizes.sum(), 1.0))


class FoldFits:
    """:func:`cv_mse` of ``y ~ [D | G]`` for one design ``D`` and any added
    columns ``G``, where the folds split the rows: each fold's QR of
    ``[D | y]`` is kept, and added columns cost their projection on it,
    ``[D G y] = [Q Q_G] [[R_D, Q^T G, R_y], [0, R_G, 0]]``, rather than a QR of
    the whole design (:class:`~bench.core.regression.Compressed` then stacks
    the folds' factors)."""

    def __init__(self, D: np.ndarray, y: np.ndarray, held: list[np.ndarray]):
        self.y, self.held, self.k = y, held, D.shape[1]
        self.D = D
        self.split = _splits(held, len(y))
        self.folds = [np.linalg.qr(np.column_stack([D[m], y[m]])) for m in held] if self.split else None

    def cv(self, G: np.ndarray | None = None) -> float:
        """The held-out mean squared residual of ``y ~ [D | G]`` over the folds."""
        g = 0 if G is None else G.shape[1]
        if not self.split or self.k + g == 0:
            return cv_mse(self.D if G is None else np.hstack([self.D, G]), self.y, self.held)
        blocks = []
        for m, (Q, R) in zip(self.held, self.folds):
            if g == 0:
                blocks.append(Compressed(R[:, :-1], R[:, -1]))
                continue
            Gm = G[m]
            C = Q.T @ Gm
            rest = Gm - Q @ C
            RG = np.linalg.qr(rest, mode="r") if rest.shape[0] > g else rest
            top = np.hstack([R[:, :-1], C, R[:, -1:]])
            bottom = np.hstack([np.zeros((RG.shape[0], self.k)), RG, np.zeros((RG.shape[0], 1))])
            M = np.vstack([top, bottom])
            blocks.append(Compressed(M[:, :-1], M[:, -1]))
        rows = sum(int(m.sum()) for m in self.held)
        return float(_held_out_rss(blocks).sum() / max(rows, 1))
