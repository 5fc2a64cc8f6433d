"""Rollout error: integrate a learned model's forward dynamics and compare
with the true system's.

Every Lagrangian's torque is affine in the accelerations,
``tau = M(q, qd) qdd + c(q, qd)`` with ``M = d2L/dqd2`` and
``c = d2L/dqd dq . qd - dL/dq``, so the forward dynamics
``qdd = M^-1 (tau - c)`` follow from any model's :meth:`predict_torque` (the
suite's one Euler–Lagrange transform): one call on a batch holding
``qdd = 0`` and each unit vector gives ``c`` and the columns of ``M``. No
method has to expose more than its torques.

The motion is unforced (``tau = 0``) from held-out initial states ``(q, qd)``
of the test set, integrated with scipy's ``solve_ivp`` (RK45, rtol 1e-6,
atol 1e-8) over :data:`HORIZON_S`; the error is the RMS of ``q`` against the
true system's rollout over :data:`N_POINTS` evenly spaced times. A true system
with non-conservative forces moves under them too; the model only knows its
Lagrangian.

A model whose mass matrix ``M`` is indefinite (not a kinetic energy) or
singular at a state it reaches has no forward dynamics there; the rollout
reports that as its status, a finding rather than a failure. So are a motion
that blows up (``|qd|`` beyond :data:`BLOW_UP`) and one that needs more than
:data:`MAX_EVALUATIONS` right-hand sides.
"""

from __future__ import annotations

import time

import numpy as np

from bench.core.data import Dataset
from bench.physics.models import FittedModel, mass_and_bias

HORIZON_S = 1.0
N_INITIAL = 8
N_POINTS = 51
MAX_EVALUATIONS = 20000
BLOW_UP = 1e3
#: ``M`` counts as singular past this condition number
MAX_CONDITION = 1e10


class NoDynamics(Exception):
    """The model's forward dynamics do not exist at a state (``status`` says why)."""

    def __init__(self, status: str, message: str):
        super().__init__(message)
        self.status = status


def definiteness(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues of each (symmetrised) ``M`` of shape ``(n, dof, dof)``,
    and each one's smallest over its largest magnitude: negative where ``M``
    is indefinite, below ``1 / MAX_CONDITION`` where it is singular."""
    eig = np.linalg.eigvalsh(0.5 * (M + np.transpose(M, (0, 2, 1))))
    scale = np.maximum(np.max(np.abs(eig), axis=1), np.finfo(float).tiny)
    return eig, eig[:, 0] / scale


def accelerations(model, q: np.ndarray, qd: np.ndarray, tau: np.ndarray | None = None):
    """The model's forward dynamics, ``M^-1 (tau - c)`` at each row (``tau``
    ``None``: unforced), and each row's status: ``"ok"``, ``"diverged"``
    (``M`` or ``c`` not finite), ``"indefinite"`` or ``"singular"``
    (condition above :data:`MAX_CONDITION`); with the mass matrix's
    eigenvalues. Rows without dynamics get an identity mass matrix and no
    bias, so their values are finite and meaningless. Returns
    ``(qdd, status, eigenvalues)``."""
    M, c = mass_and_bias(model, q, qd)
    finite = np.all(np.isfinite(M), axis=(1, 2)) & np.all(np.isfinite(c), axis=1)
    M = np.where(finite[:, None, None], M, np.eye(q.shape[1]))
    c = np.where(finite[:, None], c, 0.0)
    eig, low = definiteness(M)
    status = np.where(~finite, "diverged", np.where(low < -1e-12, "indefinite",
                                                    np.where(low < 1.0 / MAX_CONDITION, "singular", "ok")))
    M = np.where((status == "ok")[:, None, None], M, np.eye(q.shape[1]))
    rhs = -c if tau is None else tau - c
    return np.linalg.solve(M, rhs[..., None])[..., 0], status, eig


def forward_dynamics(model, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Unforced accelerations ``M^-1 (-c)`` (:func:`accelerations`); raises
    :class:`NoDynamics` where any row has none."""
    qdd, status, eig = accelerations(model, q, qd)
    if np.any(status == "diverged"):
        raise NoDynamics("diverged", "the model's torques are not finite")
    i = int(np.argmin(eig[:, 0] / np.maximum(np.max(np.abs(eig), axis=1), np.finfo(float).tiny)))
    where = f"at q = {np.round(q[i], 3).tolist()}, qd = {np.round(qd[i], 3).tolist()} (eigenvalues {eig[i].tolist()})"
    if status[i] == "indefinite":
        raise NoDynamics("indefinite", f"d2L/dqd2 is not positive definite {where}")
    if status[i] == "singular":
        raise NoDynamics("singular", f"d2L/dqd2 is singular (condition above {MAX_CONDITION:g}) {where}")
    return qdd


def rollout(model, q0: np.ndarray, qd0: np.ndarray, horizon: float = HORIZON_S, n_points: int = N_POINTS,
            deadline: float | None = None, accelerations=None) -> np.ndarray:
    """``q`` at ``n_points`` times in ``[0, horizon]``: shape ``(n_points, n, dof)``.

    All initial states are integrated together as one system. Raises
    :class:`NoDynamics` if the dynamics stop existing, blow up, or take too
    long (past ``deadline`` of ``time.perf_counter()``). ``accelerations(q,
    qd)``, where given, replaces :func:`forward_dynamics` (an engine's own
    forward dynamics for the true system).
    """
    from scipy.integrate import solve_ivp

    n, dof = q0.shape
    evaluations = 0

    def rhs(_t, y):
        nonlocal evaluations
        evaluations += 1
        if evaluations > MAX_EVALUATIONS or (deadline is not None and time.perf_counter() > deadline):
            raise NoDynamics("too_slow", f"the integration needed more than {evaluations - 1} evaluations")
        q, qd = y[: n * dof].reshape(n, dof), y[n * dof:].reshape(n, dof)
        if not np.all(np.isfinite(qd)) or np.max(np.abs(qd)) > BLOW_UP:
            raise NoDynamics("diverged", f"the motion blew up (|qd| > {BLOW_UP:g})")
        qdd = forward_dynamics(model, q, qd) if accelerations is None else accelerations(q, qd)
        return np.concatenate([qd.ravel(), qdd.ravel()])

    times = np.linspace(0.0, horizon, n_points)
    sol = solve_ivp(rhs, (0.0, horizon), np.concatenate([q0.ravel(), qd0.ravel()]), method="RK45",
                    t_eval=times, rtol=1e-6, atol=1e-8)
    if not sol.success:
        raise NoDynamics("diverged", f"the integrator stopped: {sol.message}")
    return sol.y[: n * dof].T.reshape(n_points, n, dof)


class TrueModel(FittedModel):
    """A system's own torques: ``g(L)`` plus its non-conservative forces."""

    def __init__(self, system):
        self.system = system

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        t = data.tensors()
        return self.system.lagrangian(t["q"], t["qd"]).numpy()

    def expression(self):
        return self.system.lagrangian_sympy

    def predict_torque(self, data: Dataset) -> np.ndarray:
        t = data.tensors()
        return self.system.torque(t["q"], t["qd"], t["qdd"])[0].numpy()


def rollout_error(model, system, test: Dataset, horizon: float = HORIZON_S, n_initial: int = N_INITIAL,
                  time_limit_s: float | None = 120.0) -> dict:
    """The record's ``rollout`` entry: status, horizon and the RMS error of ``q``.
    The integration stops after :data:`MAX_EVALUATIONS` right-hand sides, or
    after ``time_limit_s`` seconds (``None``: no time limit)."""
    q0, qd0 = test.q[:n_initial], test.qd[:n_initial]
    out = {"horizon_s": horizon, "n_initial": len(q0), "status": "ok", "q_rmse": None, "detail": None}
    start = time.perf_counter()
    engine = None if system.symbolic else system.forward_dynamics  # an engine's own forward dynamics
    truth = rollout(TrueModel(system), q0, qd0, horizon, accelerations=engine)
    try:
        learned = rollout(model, q0, qd0, horizon, deadline=None if time_limit_s is None else start + time_limit_s)
    except NoDynamics as exc:
        out.update(status=exc.status, detail=str(exc))
        return out
    out["q_rmse"] = float(np.sqrt(np.mean((learned - truth) ** 2)))
    out["seconds"] = round(time.perf_counter() - start, 3)
    return out
