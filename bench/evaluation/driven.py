"""Driven rollouts of measured data: a model's simulation error.

How the field judges an identified model of a real robot, without a true
model to compare with: the model is forward-simulated under the *measured*
torques, from the measured state at the start of a window of a test
recording, and its motion is compared with the measured ``q`` over the
window. Short windows (:data:`WINDOWS_S`: 0.25 s and 1 s) keep a small
model error from compounding over a whole recording into a figure that says
only "it drifted".

Forward dynamics come from any model's torques, as in
:mod:`bench.evaluation.rollout`: ``tau = M(q, qd) qdd + c(q, qd)``, so
``qdd = M^-1 (tau_measured - c)``; a model with friction (the standard model,
the residual loop's) has it in ``c``. The windows of a data set are
consecutive and non-overlapping within each recording (the data's ``time``
and ``recording`` say where each sample lies) and are integrated together
by the classical fourth-order Runge–Kutta method with a fixed step, the
data's sample step divided by :data:`SUBSTEPS`, the measured torque held
linear between samples. A fixed step makes the work a function of the data
alone, so the same model gives the same figures on any machine; an adaptive
integrator takes a friction law's sign change for stiffness.

A window *diverges* where the model's mass matrix is not positive definite
(or is singular) at a state it reaches, or its motion blows up (``|qd|``
beyond :data:`BLOW_UP`, or not finite) even at a step :data:`REFINE` squared
times smaller (:func:`driven_rollout`: an explicit step is unstable on a
stiff friction law where the model is not); that window stops there and
counts as diverged, and the others go on. Each diverged window records how
far into it the model got (``diverged_after_s``: the start of the sample
step in which it stopped). The figure per window is the RMS of
``q - q_measured`` over its samples and joints (rad). An entry gives, per
window length, how many windows there were, how many diverged, and the
median over *all* windows with a diverged one counted as infinitely far
(:func:`summary`): a model that diverges in most windows has no figure,
however well it did in the few that survived.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from bench.core.data import Dataset
from bench.physics.models import FittedModel
from bench.evaluation.rollout import BLOW_UP, accelerations

#: the windows' lengths, s
WINDOWS_S = (0.25, 1.0)
#: integration steps per sample step of the data
SUBSTEPS = 4
#: at most this many samples of the test data are covered by the windows of one length, the windows evenly
#: spread over the ones there are (all of the KUKA's 2,463 test samples; a long log's are sampled so, since
#: a network's rollouts over 14,000 samples ran past the run's time for evaluating)
MAX_SAMPLES = 4096
#: a window that blows up is integrated again at a step this many times smaller ...
REFINE = 4
#: ... at most this many times (:func:`driven_rollout`)
REFINEMENTS = 2


def windows(data: Dataset, length_s: float) -> list[np.ndarray]:
    """Consecutive, non-overlapping windows of ``length_s`` within each
    recording of ``data``: index arrays of the samples each spans, first to
    last. Each recording's samples must be evenly spaced in time."""
    if data.time is None or data.recording is None:
        raise ValueError(f"{data.source}: driven rollouts need each sample's recording and time")
    out = []
    for index in data.in_time_order():
        if len(index) < 2:
            continue
        step = float(np.median(np.diff(data.time[index])))
        per = int(round(length_s / step))
        if per < 1:
            raise ValueError(f"{data.source}: a window of {length_s:g} s is shorter than the sample step {step:g} s")
        for start in range(0, len(index) - per, per):
            out.append(index[start:start + per + 1])
    return out


def _accelerations(model: FittedModel, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``M^-1 (tau - c)`` at each row, and which rows have forward dynamics
    (:func:`bench.evaluation.rollout.accelerations`)."""
    qdd, status, _ = accelerations(model, q, qd, tau)
    return qdd, status == "ok"


def _bounded(qd: np.ndarray) -> np.ndarray:
    """Which rows of ``qd`` are finite and within :data:`BLOW_UP`."""
    return np.all(np.isfinite(qd), axis=1) & (np.max(np.abs(qd), axis=1) <= BLOW_UP)


def summary(q_rmse: list) -> tuple[float | None, int, int]:
    """``(median, diverged, windows)`` of windows' figures (``None``: the window
    diverged): the median over every window with a diverged one infinitely
    far, so ``None`` where half of them or more diverged."""
    values = np.array([np.inf if x is None else float(x) for x in q_rmse])
    diverged = int(np.isinf(values).sum())
    if not len(values) or 2 * diverged >= len(values):
        return None, diverged, len(values)
    return float(np.median(values)), diverged, len(values)


def pooled(entries: list[dict]) -> tuple[float | None, int, int]:
    """:func:`summary` over the windows of several entries of one window length
    (each a :func:`driven_rollout` result: the seeds of a table's cell)."""
    return summary([x for e in entries for x in e.get("q_rmse", [])])


def describe(median: float | None, diverged: int, windows: int, fmt: Callable[[float], str]) -> str:
    """A summary as the tables and reports show it: ``0.349 (3/980 windows
    diverged)``, or ``diverged (972/980 windows)`` where half or more did."""
    if median is None:
        return f"diverged ({diverged}/{windows} windows)" if windows else "—"
    return f"{fmt(median)} ({diverged}/{windows} windows diverged)"


def _integrate(model: FittedModel, data: Dataset, spans: np.ndarray, substeps: int):
    """Integrate the windows ``spans`` (``(W, steps + 1)`` sample indices) at
    ``substeps`` steps a sample step: each window's summed squared ``q`` error,
    whether it ran to its end, whether it stopped on an indefinite (or
    singular) mass matrix rather than a blow-up, and the sample step in which
    it stopped (``steps`` for one that ran to its end)."""
    steps = spans.shape[1] - 1
    h = float(np.median(np.diff(data.time[spans], axis=1))) / substeps
    q, qd = data.q[spans[:, 0]].copy(), data.qd[spans[:, 0]].copy()
    alive, indefinite = np.ones(len(spans), dtype=bool), np.zeros(len(spans), dtype=bool)
    left = np.full(len(spans), steps)
    sq = np.zeros(len(spans))
    for k in range(steps):
        tau0, tau1 = data.tau[spans[:, k]], data.tau[spans[:, k + 1]]
        for s in range(substeps):
            idx = np.flatnonzero(alive)
            if not len(idx):
                break
            a, b = s / substeps, (s + 0.5) / substeps
            t0, tm, t1 = ((1 - w) * tau0[idx] + w * tau1[idx] for w in (a, b, (s + 1) / substeps))
            x, v = q[idx], qd[idx]
            k1v, ok1 = _accelerations(model, x, v, t0)
            v2 = v + 0.5 * h * k1v
            k2v, ok2 = _accelerations(model, x + 0.5 * h * v, v2, tm)
            v3 = v + 0.5 * h * k2v
            k3v, ok3 = _accelerations(model, x + 0.5 * h * v2, v3, tm)
            v4 = v + h * k3v
            k4v, ok4 = _accelerations(model, x + h * v3, v4, t1)
            x_new = x + h * v + h * h / 6 * (k1v + k2v + k3v)
            v_new = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            dynamics = ok1 & ok2 & ok3 & ok4
            bounded = _bounded(v) & _bounded(v2) & _bounded(v3) & _bounded(v4) & _bounded(v_new)
            ok = dynamics & bounded
            q[idx[ok]], qd[idx[ok]] = x_new[ok], v_new[ok]
            alive[idx[~ok]] = False
            left[idx[~ok]] = k
            indefinite[idx[~dynamics]] = True
        err = q - data.q[spans[:, k + 1]]
        sq += np.where(alive, np.sum(err * err, axis=1), 0.0)
    return sq, alive, indefinite, left


def driven_rollout(model: FittedModel, data: Dataset, length_s: float, substeps: int = SUBSTEPS,
                   report: Callable[[str], None] | None = None) -> dict:
    """The driven rollouts of ``model`` over every window of ``length_s`` in
    ``data`` (evenly spread ones covering at most :data:`MAX_SAMPLES` samples,
    where there are more: ``windows_available`` then says how many there were):
    ``{"window_s", "windows", "diverged", "median_q_rmse", "q_rmse",
    "diverged_after_s"}`` (``q_rmse``: each window's, ``None`` for a diverged
    one; ``diverged_after_s``: for each diverged window the seconds into it
    at which it stopped, ``None`` for the others; ``median_q_rmse``:
    :func:`summary`'s). A window that blows up (with a positive definite mass
    matrix all along) is integrated again at a step :data:`REFINE` times
    smaller, up to :data:`REFINEMENTS` times: a stiff friction law (a Coulomb
    level rounded over a small velocity, on a light joint) makes the explicit
    step unstable where the model is not. The step each window needed is a
    function of the data and the model alone, so the figures stay the same on
    any machine. ``report``, where given, hears each pass over the windows."""
    spans = windows(data, length_s)
    available = len(spans)
    if spans and available * len(spans[0]) > MAX_SAMPLES:  # evenly spread over the windows there are
        keep = max(1, MAX_SAMPLES // len(spans[0]))
        spans = [spans[i] for i in np.unique(np.linspace(0, available - 1, keep).round().astype(int))]
    out = {"window_s": length_s, "windows": len(spans), "diverged": 0, "median_q_rmse": None, "q_rmse": [],
           "diverged_after_s": []}
    if len(spans) < available:
        out["windows_available"] = available
    if not spans:
        return out
    steps = min(len(s) for s in spans) - 1
    spans = np.stack([s[: steps + 1] for s in spans])  # (W, steps + 1): windows of one recording rate have one length
    say = report or (lambda line: None)
    say(f"{length_s:g} s windows: {len(spans)} at {substeps} steps a sample")
    sq, alive, indefinite, left = _integrate(model, data, spans, substeps)
    for _ in range(REFINEMENTS):
        again = np.flatnonzero(~alive & ~indefinite)
        if not len(again):
            break
        substeps *= REFINE
        say(f"{length_s:g} s windows: {len(again)} blew up, again at {substeps} steps a sample")
        sq[again], alive[again], indefinite[again], left[again] = _integrate(model, data, spans[again], substeps)
    rmse = np.sqrt(sq / (steps * data.dof))
    sample_step = float(np.median(np.diff(data.time[spans], axis=1)))
    out["q_rmse"] = [float(r) if a else None for r, a in zip(rmse, alive)]
    out["diverged_after_s"] = [None if a else round(float(k * sample_step), 6) for k, a in zip(left, alive)]
    out["median_q_rmse"], out["diverged"], _ = summary(out["q_rmse"])
    return out


def driven_entry(model: FittedModel, data: Dataset, report: Callable[[str], None] | None = None) -> dict:
    """A run's ``rollout`` entry on measured data: the driven rollouts of every
    window length in :data:`WINDOWS_S`, the longest's median as the entry's
    ``q_rmse`` and its status ``diverged`` where half its windows or more
    diverged; a model that is no Lagrangian of ``(q, qd)`` has none.
    ``report`` hears the progress (:func:`driven_rollout`)."""
    reason = model.not_a_lagrangian()
    if reason:
        return {"kind": "driven", "status": "not_applicable", "q_rmse": None, "detail": reason}
    by_length = {f"{s:g}": driven_rollout(model, data, s, report=report) for s in WINDOWS_S}
    longest = by_length[f"{WINDOWS_S[-1]:g}"]
    status = "ok" if longest["median_q_rmse"] is not None else "diverged"
    return {"kind": "driven", "status": status, "q_rmse": longest["median_q_rmse"], "windows": by_length}
