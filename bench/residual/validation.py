"""Held-out validation for the residual loop, by the protocol :data:`PROTOCOL`
(:mod:`bench.core.protocols`): whole trajectories where the data name several,
regions of the state space where they name one (spans in time of one
trajectory score states next to those fitted, so that a law that only
interpolates better would pass), or blocks of independent samples.

:func:`cv_mse` refits a linear problem without each fold and scores it on the
fold's scored samples; the mean over all scored rows is the figure the loop
compares.
"""

from __future__ import annotations

import numpy as np

from bench.core.autocorrelation import integrated_time
from bench.core.data import Dataset
from bench.core.folds import Fold, Folds
from bench.core.protocols import folds as protocol_folds
from bench.physics.regression import Compressed, least_squares

#: the loop's validation protocol (:func:`bench.core.protocols.folds`)
PROTOCOL = "auto"


def folds(data: Dataset) -> Folds:
    """The loop's folds of ``data``, by :data:`PROTOCOL`."""
    return protocol_folds(data, PROTOCOL, None)


def describe(data: Dataset) -> str:
    """How :func:`folds` folds ``data``, in words."""
    return folds(data).describe()


def row_folds(data: Dataset) -> Folds:
    """The folds of ``data`` over the rows of a torque fit (``tau.ravel()``: ``dof`` rows a sample)."""
    return folds(data).rows(data.dof)


def as_folds(held: "Folds | list[np.ndarray]") -> Folds:
    """``held`` as :class:`~bench.core.folds.Folds`: held-out row masks, each scored whole, as they are."""
    if isinstance(held, Folds):
        return held
    return Folds(tuple(Fold(m, m) for m in held), "given")


def cv_fold_mse(F: np.ndarray, y: np.ndarray, held: "Folds | list[np.ndarray]") -> np.ndarray:
    """The held-out mean squared residual of ``y ~ F`` in each fold of
    ``held`` (:class:`~bench.core.folds.Folds` over rows, or row masks each
    scored whole), scored on the fold's scored rows by a fit on the rows it
    does not hold out. No columns: the mean of ``y**2`` on each fold's scored rows.

    Where the folds' held-out rows split the rows (each row in one fold, as
    :func:`~bench.core.folds.folds` gives them), each fold's rows are
    compressed once (:class:`~bench.physics.regression.Compressed`) and the fit
    without a fold is that of the others' factors stacked: one QR of the
    whole problem in all, not one per fold, with the same fits."""
    fold_list = as_folds(held)
    sizes = np.asarray([max(int(f.score.sum()), 1) for f in fold_list], dtype=np.float64)
    if F.shape[1] == 0:
        return np.asarray([float(y[f.score] @ y[f.score]) for f in fold_list]) / sizes
    if not _splits(fold_list, len(y)):
        out = []
        for f in fold_list:
            r = y[f.score] - F[f.score] @ least_squares(F[f.fit], y[f.fit])
            out.append(float(r @ r))
        return np.asarray(out) / sizes
    fits = [Compressed(F[f.held], y[f.held]) for f in fold_list]
    scored = [fit if _whole(f) else Compressed(F[f.score], y[f.score]) for f, fit in zip(fold_list, fits)]
    return _held_out_rss(fits, scored) / sizes


def _splits(fold_list: Folds, rows: int) -> bool:
    """Whether the folds' held-out rows split the rows: each row in exactly one."""
    return np.array_equal(np.sum(fold_list.held, axis=0), np.ones(rows))


def _whole(fold) -> bool:
    """Whether a fold scores every row it holds out."""
    return bool(np.array_equal(fold.held, fold.score))


def _held_out_rss(fits: list[Compressed], scored: list[Compressed]) -> np.ndarray:
    """Each fold's residual sum of squares on its scored rows (``scored``) under
    the fit to the other folds' held-out rows (``fits``), from their compressed
    problems stacked."""
    return np.asarray([score.residual_norm2(Compressed.stacked(fits[:i] + fits[i + 1:]).coef())
                       for i, score in enumerate(scored)])


def cv_mse(F: np.ndarray, y: np.ndarray, held: "Folds | list[np.ndarray]") -> float:
    """The held-out mean squared residual of ``y ~ F`` over the folds ``held``
    (:func:`cv_fold_mse`, weighted by the folds' scored rows)."""
    fold_list = as_folds(held)
    sizes = np.asarray([int(f.score.sum()) for f in fold_list], dtype=np.float64)
    return float(cv_fold_mse(F, y, fold_list) @ sizes / max(sizes.sum(), 1.0))


class _Part:
    """The QR of ``[D | y]`` over some rows, to which added columns ``G`` cost
    their projection: ``[D G y] = [Q Q_G] [[R_D, Q^T G, R_y], [0, R_G, 0]]``."""

    def __init__(self, D: np.ndarray, y: np.ndarray, rows: np.ndarray):
        self.rows, self.k = rows, D.shape[1]
        self.Q, self.R = np.linalg.qr(np.column_stack([D[rows], y[rows]]))

    def compressed(self, G: np.ndarray | None) -> Compressed:
        R = self.R
        if G is None or G.shape[1] == 0:
            return Compressed(R[:, :-1], R[:, -1])
        g = G.shape[1]
        Gm = G[self.rows]
        C = self.Q.T @ Gm
        rest = Gm - self.Q @ C
        RG = np.linalg.qr(rest, mode="r") if rest.shape[0] > g else rest
        top = np.hstack([R[:, :-1], C, R[:, -1:]])
        bottom = np.hstack([np.zeros((RG.shape[0], self.k)), RG, np.zeros((RG.shape[0], 1))])
        M = np.vstack([top, bottom])
        return Compressed(M[:, :-1], M[:, -1])


class FoldFits:
    """:func:`cv_mse` of ``y ~ [D | G]`` for one design ``D`` and any added
    columns ``G``, where the folds' held-out rows split the rows: each fold's
    QR of ``[D | y]`` (and of its scored rows, where it does not score them
    all) is kept, and added columns cost their projection on it (:class:`_Part`),
    rather than a QR of the whole design (:class:`~bench.physics.regression.Compressed`
    then stacks the folds' factors)."""

    def __init__(self, D: np.ndarray, y: np.ndarray, held: "Folds | list[np.ndarray]"):
        self.y, self.held, self.k = y, as_folds(held), D.shape[1]
        self.D = D
        self.split = _splits(self.held, len(y))
        self.parts = None
        if self.split:
            self.parts = [(_Part(D, y, f.held), None if _whole(f) else _Part(D, y, f.score)) for f in self.held]

    def cv(self, G: np.ndarray | None = None) -> float:
        """The held-out mean squared residual of ``y ~ [D | G]`` over the folds."""
        g = 0 if G is None else G.shape[1]
        if not self.split or self.k + g == 0:
            return cv_mse(self.D if G is None else np.hstack([self.D, G]), self.y, self.held)
        fits = [fit.compressed(G) for fit, _ in self.parts]
        scored = [fit if score is None else score.compressed(G) for fit, (_, score) in zip(fits, self.parts)]
        rows = sum(int(f.score.sum()) for f in self.held)
        return float(_held_out_rss(fits, scored).sum() / max(rows, 1))

    def residuals(self, G: np.ndarray | None = None) -> np.ndarray:
        """The held-out residual of ``y ~ [D | G]`` on each row a fold scores
        (by the fit without that fold), ``nan`` on the rows no fold scores; the
        mean of its squares is :meth:`cv`."""
        g = 0 if G is None else G.shape[1]
        out = np.full(len(self.y), np.nan)
        if self.k + g == 0:
            for f in self.held:
                out[f.score] = self.y[f.score]
            return out
        if not self.split:
            F = self.D if G is None else np.hstack([self.D, G])
            for f in self.held:
                out[f.score] = self.y[f.score] - F[f.score] @ least_squares(F[f.fit], self.y[f.fit])
            return out
        fits = [fit.compressed(G) for fit, _ in self.parts]
        for i, f in enumerate(self.held):
            coef = Compressed.stacked(fits[:i] + fits[i + 1:]).coef()
            # the prediction on every row from the two blocks, rather than a copy of the design's scored rows
            predicted = self.D @ coef[:self.k] + (G @ coef[self.k:] if g else 0.0)
            out[f.score] = (self.y - predicted)[f.score]
        return out



def paired_difference(data: Dataset, a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """The difference of two held-out mean squared errors, ``mean(a**2) - mean(b**2)``
    over the rows both score (:meth:`FoldFits.residuals` of two designs on the same
    folds), and its standard error: the spread of the per-sample differences (each
    sample's rows summed) over the square root of the independent samples they hold
    (:func:`~bench.core.autocorrelation.effective_samples` within each recording:
    neighbouring samples of a trajectory are near copies). Paired, it sees a difference
    far smaller than either error's own spread."""
    per_sample = (a**2 - b**2).reshape(len(data), -1)
    scored = ~np.isnan(per_sample).any(axis=1)
    if not scored.any():
        return 0.0, float("inf")
    d = per_sample.sum(axis=1)
    dof = per_sample.shape[1]
    mean = float(d[scored].mean()) / dof
    if scored.sum() < 2:
        return mean, float("inf")
    if data.recording is None:
        independent = float(scored.sum())
    else:
        independent = 0.0
        for index in data.in_time_order():
            kept = index[scored[index]]
            if len(kept):
                independent += len(kept) / integrated_time(d[kept])
    return mean, float(np.std(d[scored], ddof=1) / np.sqrt(max(independent, 1.0))) / dof
