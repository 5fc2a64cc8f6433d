"""The test error per joint and per test trajectory, as papers on real arms report it.

For each test trajectory and each joint: the MSE of the predicted torque,
and the nMSE, that MSE over the variance of the torque it is scored against
on that trajectory (a fraction; tables print it in %). Both are given
against the torque the model was scored on (for a measured arm, low-passed
with the recordings' filter) and, where the system can give it, against
the logged torque, unfiltered; the filter's noise floor is the MSE between
the two torques (and its nMSE against the logged torque's variance). A
model that predicted the filtered torque exactly would score the noise
floor against the logged one.
"""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset


def _groups(data: Dataset) -> dict[str, np.ndarray]:
    """Each test trajectory's samples (or each recording's, or all of them)."""
    labels = data.trajectory if data.trajectory is not None else data.recording
    if labels is None:
        return {"all": np.ones(len(data), dtype=bool)}
    return {str(name): labels == name for name in dict.fromkeys(labels.tolist())}


def _round(values: np.ndarray) -> list[float]:
    return [float(f"{v:.6g}") for v in np.asarray(values, dtype=np.float64)]


def per_joint(predicted: np.ndarray, data: Dataset, logged: np.ndarray | None = None) -> dict:
    """``{"trajectories": {name: {"n", "mse", "nmse"[, "mse_logged", "nmse_logged",
    "noise_floor", "noise_floor_nmse"]}}}`` of torque predictions
    ``predicted`` (``(n, dof)``) on ``data``, each list one value per joint;
    ``logged`` is the unfiltered torque at the same samples, where there is one."""
    predicted = np.asarray(predicted, dtype=np.float64).reshape(data.tau.shape)
    out = {}
    for name, rows in _groups(data).items():
        tau, guess = data.tau[rows], predicted[rows]
        entry = {"n": int(rows.sum()), "mse": _round(np.mean((guess - tau) ** 2, axis=0)),
                 "nmse": _round(np.mean((guess - tau) ** 2, axis=0) / np.var(tau, axis=0))}
        if logged is not None:
            raw = np.asarray(logged, dtype=np.float64)[rows]
            var = np.var(raw, axis=0)
            floor = np.mean((tau - raw) ** 2, axis=0)
            entry.update(mse_logged=_round(np.mean((guess - raw) ** 2, axis=0)),
                         nmse_logged=_round(np.mean((guess - raw) ** 2, axis=0) / var),
                         noise_floor=_round(floor), noise_floor_nmse=_round(floor / var))
        out[name] = entry
    return {"trajectories": out}


def logged_test_torque(system, own_data: bool) -> np.ndarray | None:
    """``system``'s logged torque of its test samples, where the data scored are its own
    split (``own_data``) and it logs one; ``None`` for files given for the system, which its
    log does not describe."""
    return system.logged_torque("test") if own_data else None


def per_joint_entry(predicted: np.ndarray | None, system, test: Dataset | None, own_data: bool) -> dict | None:
    """:func:`per_joint` of a model's torque ``predicted`` on ``test``, against
    the logged torque too where ``system`` gives it for these data
    (:func:`logged_test_torque`; the record's ``details.per_joint``); ``None``
    where ``test`` holds no torque."""
    if test is None or test.tau is None or predicted is None:
        return None
    return per_joint(predicted, test, logged_test_torque(system, own_data))


def percent(value: float) -> str:
    """An nMSE (a fraction) in %, to three figures."""
    return f"{100 * value:.3g}"


def against(entry: dict) -> tuple[str, str]:
    """The keys of the nMSE a summary gives, and the torque it is against in
    words: the logged torque where the entry has it, else the scored one."""
    return ("nmse_logged", "the logged torque") if "nmse_logged" in entry else ("nmse", "the scored torque")


def per_joint_lines(before: dict, after: dict | None = None) -> list[str]:
    """One line per test trajectory of :func:`per_joint`'s ``before``: each
    joint's nMSE (in %), or before → after where ``after`` is given, and the
    filter's noise floor where the logged torque is known."""
    lines = []
    for name, b in before["trajectories"].items():
        key, words = against(b)
        if after is None:
            what, values = "", ", ".join(percent(x) for x in b[key])
        else:
            a = after["trajectories"][name][key]
            what = ", before → after"
            values = ", ".join(f"{j + 1}: {percent(x)} → {percent(y)}" for j, (x, y) in enumerate(zip(b[key], a)))
        floor = ("; the filter's noise floor " + ", ".join(percent(x) for x in b["noise_floor_nmse"])
                 if "noise_floor_nmse" in b else "")
        lines.append(f"test trajectory {name} ({b['n']} samples), nMSE per joint against {words}, %{what}: "
                     f"{values}{floor}")
    return lines
