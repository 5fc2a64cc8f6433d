"""Driven rollouts of measured data: the true model under its own torques
retraces its motion; a model without forward dynamics diverges in every window."""

from __future__ import annotations

import numpy as np
import sympy
from scipy.integrate import solve_ivp

from bench.core.data import Dataset
from bench.physics.models import ExpressionModel, FittedModel, mass_and_bias
from bench.evaluation.driven import driven_entry, driven_rollout, summary, windows
from bench.evaluation.rollout import TrueModel, forward_dynamics
from systems import get_system

STEP = 0.01


def _recorded_motion(system, seconds: float = 2.1) -> Dataset:
    """The system's motion under a known torque, integrated by scipy to 1e-11 and sampled every STEP s."""
    model = TrueModel(system)

    def torque(t):
        return np.array([[np.sin(3 * t), 0.5 * np.cos(5 * t)]])

    def rhs(t, y):
        q, qd = y[:2][None], y[2:][None]
        M_free = forward_dynamics(model, q, qd)  # unforced accelerations: M^-1 (-c)
        M, _ = mass_and_bias(model, q, qd)
        return np.concatenate([qd[0], M_free[0] + np.linalg.solve(M[0], torque(t)[0])])

    times = np.arange(0, seconds, STEP)
    sol = solve_ivp(rhs, (0, times[-1]), [0.3, -0.2, 0.0, 0.5], t_eval=times, rtol=1e-11, atol=1e-12, method="DOP853")
    q, qd = sol.y[:2].T, sol.y[2:].T
    tau = np.concatenate([torque(t) for t in times])
    return Dataset(q, qd, np.zeros_like(q), tau, None, system.name, "motion", recording=np.full(len(times), "run1"),
                   time=times)


def test_the_true_model_retraces_its_motion_under_its_torques():
    system = get_system("double_pendulum")
    data = _recorded_motion(system)
    assert [len(w) for w in windows(data, 1.0)] == [101, 101]
    out = driven_rollout(TrueModel(system), data, 1.0)
    assert out["windows"] == 2 and out["diverged"] == 0
    assert out["median_q_rmse"] < 1e-4  # the torque is held linear between samples 10 ms apart
    entry = driven_entry(TrueModel(system), data)
    assert entry["status"] == "ok" and set(entry["windows"]) == {"0.25", "1"} and entry["windows"]["0.25"]["windows"] == 8
    # a wrong model drifts measurably
    wrong = ExpressionModel(sympy.expand(2 * system.lagrangian_sympy), 2)
    assert driven_rollout(wrong, data, 1.0)["median_q_rmse"] > 1e-3


def test_a_model_without_forward_dynamics_diverges_in_every_window():
    system = get_system("double_pendulum")
    data = _recorded_motion(system)
    q, qd = sympy.symbols("q_1 q_2", real=True), sympy.symbols("qd_1 qd_2", real=True)
    indefinite = ExpressionModel(qd[0] ** 2 / 2 - qd[1] ** 2 / 2, 2)
    out = driven_rollout(indefinite, data, 0.25)
    assert out["diverged"] == out["windows"] == 8 and out["median_q_rmse"] is None
    assert out["diverged_after_s"] == [0.0] * 8  # each window stops in its first step
    assert driven_entry(indefinite, data)["status"] == "diverged"


def test_a_window_records_when_it_diverged_and_a_diverged_window_counts_as_infinitely_far():
    system = get_system("double_pendulum")
    data = _recorded_motion(system)
    q, qd = sympy.symbols("q_1 q_2", real=True), sympy.symbols("qd_1 qd_2", real=True)
    # a mass matrix that turns indefinite once |q_1| passes 0.35 rad: windows that reach it stop there
    turns = ExpressionModel(sympy.expand(system.lagrangian_sympy) - 20 * q[0] ** 2 * qd[1] ** 2, 2)
    out = driven_rollout(turns, data, 0.25)
    late = [t for t in out["diverged_after_s"] if t is not None]
    assert late and all(0.0 <= t < 0.25 for t in late) and len(late) == out["diverged"]
    assert [t is None for t in out["diverged_after_s"]] == [r is not None for r in out["q_rmse"]]
    assert summary([0.1, 0.2, None]) == (0.2, 1, 3)
    assert summary([0.1, None, None, 0.3]) == (None, 2, 4)  # half diverged: no figure
    assert summary([0.1, 0.4, 0.2, None, 0.3]) == (0.3, 1, 5)  # not the survivors' 0.25


def test_a_window_that_blows_up_on_a_stiff_damper_is_integrated_again_at_a_finer_step(monkeypatch):
    from bench.physics.effects import EFFECTS
    from bench.evaluation import driven
    from bench.residual.model import LoopModel

    system = get_system("double_pendulum")
    data = _recorded_motion(system)
    # a damper so stiff for the joint's inertia that RK4 at a quarter of the 10 ms step is unstable
    damped = LoopModel(TrueModel(system), [EFFECTS["viscous_friction"].term(1)], np.array([1000.0]), np.zeros(1))
    out = driven_rollout(damped, data, 0.25)
    assert out["diverged"] == 0 and out["median_q_rmse"] is not None
    monkeypatch.setattr(driven, "REFINEMENTS", 0)
    assert driven_rollout(damped, data, 0.25)["diverged"] > 0


def test_a_long_test_log_is_rolled_out_over_evenly_spread_windows(monkeypatch):
    from bench.evaluation import driven
    from bench.core.data import Dataset

    n = 1000
    t = np.arange(n) * 0.01
    q = np.zeros((n, 1))
    data = Dataset(q, q, q, q, recording=np.array(["r"] * n), time=t)

    class Still(FittedModel):  # a unit mass at rest under no torque: it stays where it is
        def predict_lagrangian(self, d):
            return 0.5 * d.qd[:, 0] ** 2

        def predict_torque(self, d):
            return d.qdd.copy()

    monkeypatch.setattr(driven, "MAX_SAMPLES", 260)
    out = driven.driven_rollout(Still(), data, 0.25)
    assert out["windows_available"] == 39 and out["windows"] == 10 and out["median_q_rmse"] == 0.0
