"""Linear least squares over terms.

The Euler–Lagrange transform ``g`` is linear in ``L``, so a Lagrangian
``L = sum_k c_k f_k(q, qd)`` has torques ``tau = sum_k c_k g(f_k)``. Fitting
the coefficients of a :class:`~bench.physics.terms.TermLibrary` is therefore
linear in both experiments:

* direct: columns ``f_k`` evaluated on the data, target ``L``;
* indirect: columns ``g(f_k)`` (one row per sample and joint), target ``tau``.

:func:`least_squares` is the suite's one solver; :func:`fit_statistics` adds
the standard errors and residual sum of squares that model selection needs.
"""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np
import scipy.linalg
import sympy

from bench.core.experiment import Experiment
from bench.core.data import Dataset
from bench.core.folds import folds
from bench.physics.terms import TermLibrary
from bench.core.timeouts import Timeout


def least_squares(F: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least squares with column scaling for conditioning.

    A QR factorisation solves full-rank problems (fast for the few columns of
    a GP individual); rank-deficient ones fall back to the minimum-norm SVD
    solution.
    """
    if F.shape[1] == 0:
        return np.zeros(0)
    scale = np.sqrt(np.einsum("ij,ij->j", F, F) / F.shape[0])
    scale[scale == 0] = 1.0
    Fs = F / scale
    if F.shape[0] >= F.shape[1]:
        Q, R = np.linalg.qr(Fs)
        d = np.abs(np.diag(R))
        if d.min() > 1e-10 * d.max():
            return scipy.linalg.solve_triangular(R, Q.T @ y) / scale
    coef, *_ = np.linalg.lstsq(Fs, y, rcond=None)
    return coef / scale


class Compressed:
    """The least-squares problem ``y ~ F`` kept as the triangular factor ``R``
    of ``[F | y]`` (Householder QR, backward stable column by column), so
    that the fit of ``y`` on any subset of ``F``'s columns costs a problem of
    ``F.shape[1] + 1`` rows: ``[F | y] = Q R`` with ``Q`` orthonormal, so
    ``|y - F_S c| = |R_y - R_S c|`` for every subset ``S`` and every ``c``.

    Row blocks stack: the factor of ``[F | y]`` over several blocks of rows
    is that of their factors stacked (:meth:`stacked`), which is how the
    residual loop refits without one recording at the cost of one QR.
    """

    def __init__(self, F: np.ndarray, y: np.ndarray):
        A = np.column_stack([F, y])
        self.columns = F.shape[1]
        self.R = np.linalg.qr(A, mode="r") if A.shape[0] > A.shape[1] else A

    @classmethod
    def stacked(cls, parts: list["Compressed"]) -> "Compressed":
        R = np.vstack([p.R for p in parts])
        return cls(R[:, :-1], R[:, -1])

    def coef(self, columns=None) -> np.ndarray:
        """:func:`least_squares` on the columns ``columns`` (all by default)."""
        X = self.R[:, : self.columns] if columns is None else self.R[:, list(columns)]
        return least_squares(X, self.R[:, -1])

    def residual_norm2(self, coef: np.ndarray, columns=None) -> float:
        """``|y - F_S coef|^2`` over this problem's rows."""
        X = self.R[:, : self.columns] if columns is None else self.R[:, list(columns)]
        r = self.R[:, -1] - X @ coef
        return float(r @ r)

    def rss(self, columns=None) -> float:
        """The residual sum of squares of the least-squares fit on ``columns``."""
        if columns is not None and len(columns) == 0:
            return float(self.R[:, -1] @ self.R[:, -1])
        return self.residual_norm2(self.coef(columns), columns)


def fit_statistics(F: np.ndarray, y: np.ndarray, problem: "Compressed | None" = None
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`least_squares` coefficients, their standard errors, and the
    residual sum of squares (the errors from ``pinv(F^T F) * RSS / (rows - columns)``),
    from one QR of ``[F | y]`` (:class:`Compressed`; ``problem`` where the caller has it already)."""
    problem = problem if problem is not None else Compressed(F, y)  # one QR; the solve and F^T F = R^T R are small
    coef = problem.coef()
    rss = problem.residual_norm2(coef)
    dof = max(len(y) - F.shape[1], 1)
    try:
        R = problem.R[:, :-1]
        cov = np.linalg.pinv(R.T @ R) * (rss / dof)
        stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        stderr = np.full(F.shape[1], np.inf)
    return coef, stderr, rss


def thresholded_least_squares(
    F: np.ndarray, y: np.ndarray, threshold: float = 1e-6, max_iter: int = 10, deadline: float | None = None
) -> np.ndarray:
    """Sequentially thresholded least squares (as in SINDy).

    Repeatedly refit, dropping columns whose contribution ``|c_k| rms(F_k)``
    falls below ``threshold * rms(y)``. Columns that are zero on the data (an
    empty Euler–Lagrange image, for instance a constant) are dropped first.
    Raises :class:`~bench.core.timeouts.Timeout` before a refit that starts
    past ``deadline``.
    """
    K = F.shape[1]
    rms_f = np.sqrt(np.mean(F * F, axis=0)) if K else np.zeros(0)
    rms_y = float(np.sqrt(np.mean(y * y))) or 1.0
    active = rms_f > 1e-12 * max(rms_f.max(initial=0.0), 1e-300)
    coef = np.zeros(K)
    for _ in range(max_iter):
        if deadline is not None and time.perf_counter() > deadline:
            raise Timeout("thresholded least squares: out of time between refits")
        coef = np.zeros(K)
        coef[active] = least_squares(F[:, active], y)
        keep = active & (np.abs(coef) * rms_f >= threshold * rms_y)
        if np.array_equal(keep, active):
            break
        active = keep
    coef[~active] = 0.0
    return coef


THRESHOLDS = (1e-12, 1e-9, 1e-7, 1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 1e-1)


def fit_basis(basis: Sequence[sympy.Expr], data: Dataset, experiment: str, threshold: float | None = None,
              deadline: float | None = None):
    """Fit coefficients of the Lagrangian terms ``basis`` on ``data``; returns ``(expression, coef)``.

    With ``threshold=None`` the sparsity threshold is chosen on held-out
    data: where the data name trajectories, on the validation protocol's folds
    (:mod:`bench.core.folds`); otherwise (independent samples) the samples are
    split 3:1. Every threshold of :data:`THRESHOLDS` is fitted on each fold,
    and the largest one whose held-out MSE is within 10 % of the best is
    refitted on all samples (the sparsest model that predicts as well).
    """
    library, F = design(basis, data, experiment, deadline)
    held = folds(data).indices() if data.trajectories() else None
    coef = fit_columns(F, data.target(experiment).ravel(), len(data), threshold, deadline, held)
    return library.lagrangian(coef), coef


def design(basis: Sequence[sympy.Expr], data: Dataset, experiment: str,
           deadline: float | None = None) -> tuple[TermLibrary, np.ndarray]:
    """The term library of the Lagrangian terms ``basis`` (with a constant where a direct target may carry an
    offset) and its design matrix on ``data`` (:func:`fit_basis`)."""
    basis = list(basis)
    if not Experiment.of(experiment).learns_torque and not any(f.is_number for f in basis):
        basis.append(sympy.Integer(1))  # the direct target may carry a constant offset
    library = TermLibrary.of_lagrangian(basis)
    return library, library.design(data, experiment, deadline)


def held_out_mse(F: np.ndarray, y: np.ndarray, n_samples: int, held: list[tuple[np.ndarray, np.ndarray]],
                 deadline: float | None = None) -> float:
    """The MSE over ``held``'s scored samples of :func:`fit_columns` fitted on each fold's fitted samples
    (``(fitted, scored)`` sample indices; the threshold chosen within the fitted ones), pooled."""
    per = len(y) // max(n_samples, 1)
    total, count = 0.0, 0
    for fitted, scored in held:
        if not len(fitted) or not len(scored):
            continue
        coef = fit_columns(F[_rows(fitted, per)], y[_rows(fitted, per)], len(fitted), deadline=deadline)
        residual = F[_rows(scored, per)] @ coef - y[_rows(scored, per)]
        total, count = total + float(residual @ residual), count + len(residual)
    return total / count if count else float("inf")


def fit_columns(F: np.ndarray, y: np.ndarray, n_samples: int, threshold: float | None = None,
                deadline: float | None = None, folds: list[tuple[np.ndarray, np.ndarray]] | None = None) -> np.ndarray:
    """Sparse coefficients for a design matrix of ``n_samples`` samples (rows
    grouped by sample); the threshold is validated when not given: on
    ``folds`` where given (``(fitted, scored)`` sample indices each, the
    validation protocol's: :meth:`bench.core.folds.Folds.indices`), else on the
    last quarter of the samples. Raises :class:`~bench.core.timeouts.Timeout`
    past ``deadline``."""
    if threshold is None:
        rows = len(y) // max(n_samples, 1)
        if folds is None:
            cut = 3 * n_samples // 4
            folds = [(np.arange(cut), np.arange(cut, n_samples))] if 0 < cut < n_samples else []
        threshold = _validated_threshold(F, y, rows, folds, deadline)
    return thresholded_least_squares(F, y, threshold, deadline=deadline)


def base_columns(F: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A basis of ``F``'s column space among its columns, by QR with column
    pivoting (the standard way to find a rigid body's base parameters, Gautier 1990).

    Returns ``(independent, dependent, beta)`` with
    ``F[:, dependent] = F[:, independent] @ beta``: a model ``F @ pi`` is
    then ``F[:, independent] @ pi_base`` with ``pi_base = pi[independent] +
    beta @ pi[dependent]``, the identifiable combinations of ``pi``.
    Columns are scaled to unit RMS first, so ``tol`` is relative; a column
    whose RMS is round-off (below 1e-12 of the largest) counts as zero, since
    scaled up it would be noise, independent of everything.
    """
    scale = np.sqrt(np.einsum("ij,ij->j", F, F) / max(F.shape[0], 1))
    live = scale > 1e-12 * max(scale.max(initial=0.0), 1e-300)
    _, R, P = scipy.linalg.qr(F[:, live] / scale[live], mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    r = int(np.sum(d > tol * d[0])) if len(d) else 0
    cols = np.flatnonzero(live)
    independent, rest = cols[P[:r]], cols[P[r:]]
    beta = scipy.linalg.solve_triangular(R[:r, :r], R[:r, r:]) if r else np.zeros((0, len(rest)))
    beta = beta * scale[rest][None, :] / scale[independent][:, None]  # back to the unscaled columns
    dead = np.flatnonzero(~live)  # columns of zeros depend on nothing
    dependent = np.concatenate([rest, dead]).astype(int)
    beta = np.hstack([beta, np.zeros((r, len(dead)))])
    return independent.astype(int), dependent, beta


def independent_columns(F: np.ndarray, tol: float = 1e-8, deadline: float | None = None) -> np.ndarray:
    """Indices of a maximal set of linearly independent columns, earliest first.

    A column is kept when what remains of it, after projection on the kept
    columns, is larger than ``tol`` times its norm. Zero columns are dropped.
    Used to remove the gauge freedom from a library: terms with no
    Euler–Lagrange image, or with the image of earlier terms. The kept
    columns' orthonormal basis fills one array allocated at the start.
    Raises :class:`~bench.core.timeouts.Timeout` once ``time.perf_counter()``
    passes ``deadline``.
    """
    kept: list[int] = []
    basis = np.zeros((F.shape[0], min(F.shape)))
    for k in range(F.shape[1]):
        if deadline is not None and time.perf_counter() > deadline:
            raise Timeout(f"independent columns: {k} of {F.shape[1]} done")
        col = F[:, k]
        norm = float(np.linalg.norm(col))
        if norm == 0.0 or not np.isfinite(norm):
            continue
        Q = basis[:, :len(kept)]
        r = col - Q @ (Q.T @ col)
        r = r - Q @ (Q.T @ r)  # re-orthogonalise once for stability
        rn = float(np.linalg.norm(r))
        if rn > tol * norm:
            basis[:, len(kept)] = r / rn
            kept.append(k)
            if len(kept) == basis.shape[1]:
                break
    return np.asarray(kept, dtype=int)


def _rows(index, per_sample: int) -> np.ndarray:
    """The design's rows of the samples ``index``, each sample's ``per_sample`` rows in order."""
    return (np.asarray(index)[:, None] * per_sample + np.arange(per_sample)).ravel()


def _validated_threshold(F: np.ndarray, y: np.ndarray, rows_per_sample: int,
                         folds: list[tuple[np.ndarray, np.ndarray]], deadline: float | None = None) -> float:
    """The largest threshold whose held-out MSE over ``folds`` (sample indices)
    is within 10 % of the best (:func:`fit_basis`)."""
    folds = [(f, s) for f, s in folds if len(f) and len(s)]
    if not folds:
        return THRESHOLDS[0]

    folds = [(_rows(f, rows_per_sample), _rows(s, rows_per_sample)) for f, s in folds]
    errors = []
    for threshold in THRESHOLDS:
        total, count = 0.0, 0
        for fit, score in folds:
            coef = thresholded_least_squares(F[fit], y[fit], threshold, deadline=deadline)
            residual = F[score] @ coef - y[score]
            total, count = total + float(residual @ residual), count + len(score)
        errors.append(total / count)
    best = min(errors)
    scale = float(np.mean(y * y)) or 1.0
    ok = [t for t, e in zip(THRESHOLDS, errors) if e <= 1.1 * best + 1e-14 * scale]
    return max(ok)
