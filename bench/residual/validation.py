"""Held-out validation for the residual loop: by whole recordings.

On a measured trajectory, neighbouring samples are near copies, so a choice
tested on rows interleaved with (or next to) the rows it was fitted on is not
tested at all. Every choice the loop makes is therefore judged by
cross-validation over folds that are

* **one recording each** (leave one recording out) where the data name two
  or more recordings (the ``trajectory`` column of the data format);
* otherwise :data:`BLOCKS` contiguous blocks of the samples: the only honest
  split of a single recording, and, for generated data, whose samples are
  independent draws, as good as any other split.

:func:`cv_mse` refits a linear problem without each fold and scores it on
that fold; the mean over all held-out rows is the figure the loop compares.
"""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset
from bench.core.regression import Compressed, least_squares

#: contiguous blocks where the data name fewer than two recordings
BLOCKS = 4


def folds(data: Dataset) -> list[np.ndarray]:
    """Boolean masks over the samples, one per fold; every sample is held out once."""
    names = data.recordings()
    if len(names) >= 2:
        return [data.recording == name for name in names]
    block = np.arange(len(data)) * BLOCKS // max(len(data), 1)
    return [block == k for k in range(min(BLOCKS, len(data)))]


def describe(data: Dataset) -> str:
    """How :func:`folds` splits ``data``, in words."""
    names = data.recordings()
    if len(names) >= 2:
        return f"leave one recording out, over {len(names)} recordings"
    what = "one recording" if names else "samples without recordings"
    return f"{BLOCKS} contiguous blocks of {what}"


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
    if F.shape[1] == 0:
        return np.asarray([float(y[m] @ y[m]) / max(int(m.sum()), 1) for m in held])
    if not np.array_equal(np.sum(held, axis=0), np.ones(len(y))):
        out = []
        for mask in held:
            r = y[mask] - F[mask] @ least_squares(F[~mask], y[~mask])
            out.append(float(r @ r) / max(int(mask.sum()), 1))
        return np.asarray(out)
    blocks = [Compressed(F[m], y[m]) for m in held]
    out = []
    for i, mask in enumerate(held):
        fit = Compressed.stacked([b for j, b in enumerate(blocks) if j != i]).coef()
        out.append(blocks[i].residual_norm2(fit) / max(int(mask.sum()), 1))
    return np.asarray(out)


def cv_mse(F: np.ndarray, y: np.ndarray, held: list[np.ndarray]) -> float:
    """The held-out mean squared residual of ``y ~ F`` over the folds ``held``
    (:func:`cv_fold_mse`, weighted by the folds' sizes)."""
    sizes = np.asarray([int(m.sum()) for m in held], dtype=np.float64)
    return float(cv_fold_mse(F, y, held) @ sizes / max(sizes.sum(), 1.0))
