"""Orthonormal bases of design columns and projections off them: how the
residual loop fits a term beside the columns already in its design
(Frisch–Waugh–Lovell) without refitting the whole design."""

from __future__ import annotations

import numpy as np
import scipy.linalg


def orthonormal_basis(D: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the columns of ``D`` (pivoted QR of the
    column-scaled matrix; columns dependent to 1e-10 left out)."""
    if D.shape[1] == 0:
        return np.zeros((D.shape[0], 0))
    scale = np.sqrt(np.einsum("ij,ij->j", D, D))
    scale[scale == 0] = 1.0
    Q, R, _ = scipy.linalg.qr(D / scale, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    return Q[:, d > 1e-10 * d[0]] if d[0] > 0 else Q[:, :0]


def extend_basis(Q: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``Q`` (orthonormal columns) with an orthonormal basis of what the
    columns ``G`` add to it: their parts off ``Q`` (projected twice) that keep
    more than 1e-10 of their norm, by pivoted QR. The span is that of
    :func:`orthonormal_basis` of ``[Q | G]``, at the cost of a projection."""
    scale = np.sqrt(np.einsum("ij,ij->j", G, G))
    G = project_off(Q, G[:, scale > 0] / scale[scale > 0])
    kept = np.sqrt(np.einsum("ij,ij->j", G, G)) > 1e-10
    if not kept.any():
        return Q
    P, R, _ = scipy.linalg.qr(G[:, kept], mode="economic", pivoting=True)
    P = P[:, np.abs(np.diag(R)) > 1e-10]
    P = project_off(Q, P)  # orthogonal to Q to round-off again
    P /= np.sqrt(np.einsum("ij,ij->j", P, P))
    return np.hstack([Q, P])


def project_off(Q: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``G`` less its projection on the orthonormal columns ``Q`` (twice, for accuracy)."""
    G = G - Q @ (Q.T @ G)
    return G - Q @ (Q.T @ G)
