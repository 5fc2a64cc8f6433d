r"""Physically feasible inertial parameters: each body's pseudo-inertia
positive semidefinite (Wensing, Kim & Slotine 2017).

A rigid body's 10 inertial parameters, in Pinocchio's order
``m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz`` (the
rotational inertia ``I`` about the body frame's origin), give its
pseudo-inertia

.. math::

    J = \begin{pmatrix} \tfrac12 \operatorname{tr}(I)\,\mathbb 1 - I & h \\ h^\top & m \end{pmatrix},
    \qquad h = m c,

which is positive semidefinite exactly when some mass distribution has these
parameters (positive mass, positive definite inertia, and the triangle
inequalities of its principal moments). The condition is linear in the
parameters, so identification under it is a semidefinite program:
:func:`feasible_fit` minimises the squared torque error plus a small pull
toward prior values (the URDF's) under ``J_b >= margin * 1`` for every body,
with cvxpy and the Clarabel interior-point solver. The pull decides the
directions the data do not identify (a rigid body's regressor has fewer base
parameters than parameters), and only those; it is ``regularisation`` times
the mean squared column norm of the problem, so that its size is relative
to the data's.

:func:`nearest_completion` gives the full parameter set nearest the prior
with the torques of a fit of base parameters (least squares'), whose
pseudo-inertias say whether that fit is a rigid body's.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from bench.core.errors import DataError
from bench.physics.linear import torque_regressor
from bench.physics.regression import Compressed

#: parameters per rigid body
BODY = 10
#: the smallest eigenvalue the fit requires of each pseudo-inertia (kg, kg m, kg m^2): a solver's
#: tolerance then leaves every eigenvalue of the result non-negative
MARGIN = 1e-7


def pseudo_inertia(p: np.ndarray) -> np.ndarray:
    """The 4x4 pseudo-inertia of one body's 10 parameters (Pinocchio's order)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = p
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    J = np.empty((4, 4))
    J[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    J[:3, 3] = J[3, :3] = (hx, hy, hz)
    J[3, 3] = m
    return J


def smallest_eigenvalues(parameters: np.ndarray, bodies: int) -> list[float]:
    """The smallest eigenvalue of each body's pseudo-inertia (non-negative for every body: feasible)."""
    return [float(np.linalg.eigvalsh(pseudo_inertia(parameters[BODY * b:BODY * (b + 1)]))[0]) for b in range(bodies)]


#: the pseudo-inertia as a linear map of a body's 10 parameters: ``PSEUDO_INERTIA @ p`` is
#: ``pseudo_inertia(p)`` flattened column by column. The feasible fit gives each body a symmetric 4x4
#: variable equal to it and held in the cone: cvxpy then builds a few expressions a body, not one an entry
#: (about 3x faster to build; the solver meets the margin on every body, as before)
PSEUDO_INERTIA = np.column_stack([pseudo_inertia(np.eye(BODY)[k]).flatten(order="F") for k in range(BODY)])


@dataclass
class Feasibility:
    """What a record says of an identified parameter set."""

    masses: list[float]
    smallest_eigenvalues: list[float]

    @classmethod
    def of(cls, parameters: np.ndarray, bodies: int) -> "Feasibility":
        return cls([float(parameters[BODY * b]) for b in range(bodies)], smallest_eigenvalues(parameters, bodies))

    @property
    def feasible(self) -> bool:
        return min(self.smallest_eigenvalues, default=0.0) >= 0.0

    def as_dict(self) -> dict:
        return {"feasible": self.feasible, "masses": self.masses, "smallest_eigenvalues": self.smallest_eigenvalues}


def feasible_fit(problem: Compressed, bodies: int, prior: np.ndarray, regularisation: float,
                 nonnegative: Sequence[int] = ()) -> tuple[np.ndarray, dict]:
    """The coefficients of ``problem`` (its first ``BODY * bodies`` columns a
    rigid body's parameters, any further columns free but those named in
    ``nonnegative``, such as a joint's friction, which are held at 0 or
    above) with the least squared error such that every pseudo-inertia is at
    least :data:`MARGIN`; and facts of the solve.

    The program is written as a step ``d`` from the least-squares solution
    ``c0`` nearest ``prior`` (the residual of ``c0`` is orthogonal to every
    column, so the error of ``c0 + d`` is that of ``c0`` plus ``|R d|^2``):
    where ``c0`` is feasible the step is zero up to the solver's tolerance,
    and the fit is least squares'. A step along directions the data do not
    identify (the null space of the columns) costs ``regularisation`` times
    the mean squared singular value times its squared length, so they stay
    at the prior unless feasibility needs them; identified directions are
    not pulled. Variables are scaled to unit columns. What the solver
    returns within its tolerance of the cone, or of 0 for a column held
    nonnegative, is projected onto it (:func:`project`; the facts give the
    largest change)."""
    import cvxpy as cp

    n_body = BODY * bodies
    if problem.columns < n_body or len(prior) != n_body:
        raise ValueError(f"the problem has {problem.columns} columns and the prior {len(prior)} values for {bodies} bodies")
    norms = np.sqrt(np.einsum("ij,ij->j", problem.R[:, :problem.columns], problem.R[:, :problem.columns]))
    scale = np.maximum(norms, 1e-3 * norms.max())  # the program's variables have unit columns
    R = problem.R[:, :problem.columns] / scale
    _, sv, Vt = np.linalg.svd(R, full_matrices=True)
    rank = int(np.sum(sv > 1e-9 * sv[0]))
    null = Vt[rank:].T  # the directions the data do not identify (scaled)
    x0 = np.linalg.lstsq(R, problem.R[:, -1], rcond=None)[0]
    target = x0.copy()
    target[:n_body] = np.asarray(prior) * scale[:n_body]
    x0 = x0 + null @ (null.T @ (target - x0)) if null.shape[1] else x0  # least squares, nearest the prior
    pulled = null[:n_body]  # how the unidentified directions move the bodies' parameters
    step = cp.Variable(len(x0))
    objective = cp.sum_squares(R @ step)
    if null.shape[1]:
        objective = objective + regularisation * float(np.mean(sv[:rank] ** 2)) * cp.sum_squares(pulled.T @ step[:n_body])
    coef = cp.multiply(x0 + step, 1.0 / scale)
    constraints = []
    for b in range(bodies):
        J = cp.Variable((4, 4), symmetric=True)
        constraints += [cp.vec(J, order="F") == PSEUDO_INERTIA @ coef[BODY * b:BODY * (b + 1)], J >> MARGIN * np.eye(4)]
    if len(nonnegative):
        if min(nonnegative) < n_body or max(nonnegative) >= len(x0):
            raise ValueError(f"the columns held nonnegative, {list(nonnegative)}, are not among the further columns "
                             f"{n_body}..{len(x0) - 1}")
        constraints.append(coef[list(nonnegative)] >= 0)
    start = time.perf_counter()
    program = cp.Problem(cp.Minimize(objective), constraints)
    try:
        with warnings.catch_warnings():  # an inaccurate solution is named in the facts' status
            warnings.simplefilter("ignore", UserWarning)
            program.solve(solver=cp.CLARABEL)
    except cp.SolverError as exc:
        raise DataError(f"the feasible fit's solver failed: {exc}") from None
    if program.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or step.value is None:
        raise DataError(f"the feasible fit's solver ended {program.status}")
    result = (x0 + np.asarray(step.value)) / scale
    held = result.copy()
    held[list(nonnegative)] = np.maximum(held[list(nonnegative)], 0.0)  # within the solver's tolerance of 0: onto it
    projected = project(held, bodies)  # within the solver's tolerance of the cone: onto it
    return projected, {
        "solver": "CLARABEL", "status": program.status, "solve_seconds": round(time.perf_counter() - start, 3),
        "unidentified_directions": int(null.shape[1]),
        "projection": float(np.max(np.abs(projected - result), initial=0.0)),
    }


def project(parameters: np.ndarray, bodies: int) -> np.ndarray:
    """``parameters`` with each body's pseudo-inertia's eigenvalues raised to at least 0."""
    out = np.array(parameters, dtype=np.float64)
    for b in range(bodies):
        w, V = np.linalg.eigh(pseudo_inertia(out[BODY * b:BODY * (b + 1)]))
        if w[0] < 0:
            out[BODY * b:BODY * (b + 1)] = from_pseudo_inertia((V * np.maximum(w, 0.0)) @ V.T)
    return out


def from_pseudo_inertia(J: np.ndarray) -> np.ndarray:
    """The 10 parameters of a pseudo-inertia (the inverse of :func:`pseudo_inertia`)."""
    sigma = J[:3, :3]
    inertia = np.trace(sigma) * np.eye(3) - sigma
    return np.array([J[3, 3], *J[:3, 3], inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2],
                     inertia[2, 2]])


def nearest_completion(W: np.ndarray, columns: np.ndarray, coef: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """The full parameter set nearest ``prior`` that gives the same torques
    as ``coef`` on the columns ``columns`` of the regressor ``W`` (rows of
    samples and joints): a fit of base parameters completed. The directions
    ``W`` does not see are the prior's. ``W`` may be the regressor's
    triangular factor (:class:`~bench.physics.regression.Compressed`'s ``R``
    without its last column): ``W = Q R`` with ``Q`` orthonormal gives the
    same solution from a problem of as many rows as columns."""
    step, *_ = np.linalg.lstsq(W, W[:, columns] @ coef - W @ prior, rcond=None)
    return prior + step


def feasibility_of(model, data) -> dict | None:
    """Whether a :class:`~bench.physics.linear.LinearParametricModel` of rigid
    bodies is a rigid body's (:meth:`Feasibility.as_dict`): its parameters
    where it holds all of them, else the full set nearest its form's prior
    that gives the same torques at the states of ``data``
    (:func:`nearest_completion`); ``None`` for a form without bodies or prior."""
    form = model.form
    if not form.bodies or form.prior is None:
        return None
    prior = form.full_prior()
    if len(model.columns) == len(prior):
        full = np.zeros(len(prior))
        full[model.columns] = model.coef
        return Feasibility.of(full, form.bodies).as_dict()
    W = torque_regressor(form, data)
    full = nearest_completion(W.reshape(-1, W.shape[-1]), model.columns, model.coef, prior)
    return Feasibility.of(full, form.bodies).as_dict()
