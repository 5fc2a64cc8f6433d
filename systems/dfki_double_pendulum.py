"""The DFKI real double pendulum (design A.0): measured trajectories.

Six excitation trajectories recorded on the real robot of the DFKI RIC
Underactuated Robotics Lab (``double_pendulum`` repository, design A.0,
``data/experiment_records/design_A.0/20220815/sys_id``), shipped gzipped in
``systems/data`` with their BSD-3-Clause license. Angles are *relative*: q2
is measured against link 1 and ``q = 0`` hangs down.

Split
-----
Trajectories 00, 01, 02 and 04 train, 03 and 05 test. 04 and 05 are the two
fast ones (joint 2 turns over, velocities to 20 rad/s), so each side has one.

From a recording to samples (``preprocess``)
--------------------------------------------
No accelerations are recorded, the timestamps are not uniform (2 ms, with
gaps to 3.6 ms) and the measured velocities are quantized (steps of
0.011 rad/s). Each trajectory is turned into samples by:

1. linear interpolation of ``pos_meas``, ``vel_meas`` and ``tau_meas`` onto a
   uniform grid of ``dt`` = 2 ms;
2. a zero-phase Butterworth low-pass (``order`` 4 run forwards and backwards,
   cut-off ``cutoff_hz``) applied alike to q, qd and tau, so that no signal is
   delayed against another and both sides of ``tau = g(L)`` see one filter;
3. ``qdd`` as the central difference of the filtered velocity;
4. ``trim_s`` cut from both ends (filter start-up), then every
   ``decimate``-th sample kept.

The cut-off was chosen by measuring: ``python -m bench dfki-filter`` fits the
lab's model structure (rigid body, rotor inertia, viscous and Coulomb
friction) by least squares for a range of cut-offs and prints its test torque
MSE against the *unfiltered* measured torque. Results are in
``results/dfki_filter.md``.

Parametric form
---------------
The rigid-body Lagrangian in the lab's parameters (link 1 length ``l1`` and
``g`` known; masses, centre-of-mass distances and inertias about the joint
axes unknown):

.. math::

    L = \\tfrac12 (I_1 + m_2 l_1^2) \\dot q_1^2 + \\tfrac12 I_2 (\\dot q_1 + \\dot q_2)^2
      + m_2 l_1 r_2 \\cos q_2 (\\dot q_1^2 + \\dot q_1 \\dot q_2)
      + g (m_1 r_1 + m_2 l_1) \\cos q_1 + g m_2 r_2 \\cos(q_1 + q_2).

Only the combinations ``I1 + m2 l1^2``, ``I2``, ``m2 r2`` and
``m1 r1 + m2 l1`` act on the torque, so individual parameters are not
identifiable; the torque error is what is reported. The data also hold what
this form lacks: joint friction and rotor inertia (the lab identified
``b = 0.001 N m s``, ``cf1 = 0.093 N m``, ``cf2 = 0.078 N m`` with the model
``b qd + cf atan(100 qd)``, and a rotor inertia ``Ir = 7.7e-5 kg m^2`` behind
a gear ratio of 6).
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import sympy

from bench.core.data import DataError, Dataset, numeric_column, read_frame
from systems.base import SYSTEMS, System

DATA_DIR = Path(__file__).parent / "data"
TRAIN_TRAJECTORIES = ("00", "01", "02", "04")
TEST_TRAJECTORIES = ("03", "05")
RAW_COLUMNS = ("time", "pos_meas1", "pos_meas2", "vel_meas1", "vel_meas2", "tau_meas1", "tau_meas2")
#: the lab's own identified friction (model 2.0), for reference
LAB_FRICTION = {"viscous": (0.001, 0.001), "coulomb": (0.093, 0.078), "coulomb_slope": 100.0}


@dataclass(frozen=True)
class FilterSpec:
    """How a recording becomes samples; see the module docstring."""

    dt: float = 0.002
    cutoff_hz: float = 6.0
    order: int = 4
    trim_s: float = 0.25
    decimate: int = 5

    def __post_init__(self):
        nyquist = 0.5 / self.dt
        if not 0 < self.cutoff_hz < nyquist:
            raise ValueError(f"cutoff_hz must lie in (0, {nyquist:g}) for dt = {self.dt:g}, got {self.cutoff_hz}")
        if self.order < 1 or self.decimate < 1 or self.trim_s < 0:
            raise ValueError("order and decimate must be >= 1 and trim_s >= 0")


DEFAULT_FILTER = FilterSpec()


@dataclass(frozen=True)
class DfkiParams:
    """The lab's identified values (model 2.0), for reference only."""

    m1: float = 0.5593806151425046
    m2: float = 0.6043459469186889
    l1: float = 0.3
    r1: float = 0.3
    r2: float = 0.18377686083653508
    I1: float = 0.053470810264216295
    I2: float = 0.02392374528789766
    g: float = 9.81


def lab_parameters() -> dict[str, float]:
    """The lab's identified parameters (``dfki_identified_parameters_model_2.0.yml``,
    flat ``name: value`` lines)."""
    path = DATA_DIR / "dfki_identified_parameters_model_2.0.yml"
    values = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            key, sep, value = line.partition(":")
            try:
                values[key.strip()] = float(value)
            except ValueError:
                raise DataError(f"{path}: line {n} is not 'name: number'") from None
    return values


def read_raw(path: str | Path):
    """A raw DFKI recording as a DataFrame, checked: the columns in ``RAW_COLUMNS``,
    numeric and finite, with strictly increasing time. Raises :class:`DataError`
    naming the file and the column."""
    import pandas as pd

    path = Path(path)
    frame = read_frame(path)
    missing = [c for c in RAW_COLUMNS if c not in frame.columns]
    if missing:
        raise DataError(f"{path}: missing column(s) {', '.join(missing)} of a DFKI recording")
    out = {col: numeric_column(frame, col, path) for col in RAW_COLUMNS}
    if len(out["time"]) < 16:
        raise DataError(f"{path}: {len(out['time'])} rows are too few for a trajectory")
    if np.any(np.diff(out["time"]) <= 0):
        row = int(np.flatnonzero(np.diff(out["time"]) <= 0)[0]) + 2
        raise DataError(f"{path}: column time does not increase at data row {row}")
    return pd.DataFrame(out)


def preprocess(frame, spec: FilterSpec = DEFAULT_FILTER, *, filter_torque: bool = True) -> dict[str, np.ndarray]:
    """Samples ``q, qd, qdd, tau`` (each ``(n, 2)``) of one recording; see the
    module docstring for the steps. ``filter_torque=False`` keeps the measured
    torque unfiltered (it is still resampled), for judging a filter."""
    from scipy.signal import butter, sosfiltfilt

    t = frame["time"].to_numpy()
    grid = np.arange(t[0], t[-1], spec.dt)
    trim = int(round(spec.trim_s / spec.dt))
    if len(grid) <= 2 * trim + 2:
        raise DataError(f"recording of {t[-1] - t[0]:.3g} s is shorter than twice the trim of {spec.trim_s} s")

    def resampled(stem):
        return np.stack([np.interp(grid, t, frame[f"{stem}{i}"].to_numpy()) for i in (1, 2)], axis=1)

    sos = butter(spec.order, spec.cutoff_hz, fs=1.0 / spec.dt, output="sos")
    q = sosfiltfilt(sos, resampled("pos_meas"), axis=0)
    qd = sosfiltfilt(sos, resampled("vel_meas"), axis=0)
    tau = resampled("tau_meas")
    if filter_torque:
        tau = sosfiltfilt(sos, tau, axis=0)
    qdd = np.gradient(qd, spec.dt, axis=0)
    keep = slice(trim, len(grid) - trim, spec.decimate)
    return {"q": q[keep], "qd": qd[keep], "qdd": qdd[keep], "tau": tau[keep]}


def trajectory_path(name: str) -> Path:
    return DATA_DIR / f"dfki_trajectory_{name}.csv.gz"


@functools.lru_cache(maxsize=8)
def _samples(split: str, spec: FilterSpec, filter_torque: bool) -> dict[str, np.ndarray]:
    names = TRAIN_TRAJECTORIES if split == "train" else TEST_TRAJECTORIES
    parts = [preprocess(read_raw(trajectory_path(n)), spec, filter_torque=filter_torque) for n in names]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


@SYSTEMS.add("dfki_double_pendulum", "measured", "external")
class DfkiDoublePendulum(System):
    coordinates = ("q1", "q2_relative")
    Params = DfkiParams
    sysid_unknowns = ("m1", "m2", "r1", "r2", "I1", "I2")
    simulated = False
    experiments = ("indirect",)
    reference = ("with this pre-processing, the lab's own identified model 2.0 (rigid body, rotor inertia, "
                 "viscous and Coulomb friction; not fitted here) has a test torque MSE of 0.0177, and a "
                 "least-squares fit of the rigid-body form alone 0.0343 "
                 "(`python -m bench dfki-filter`, results/dfki_filter.md).")
    not_applicable = "the DFKI recordings are measured trajectories with torques and no samples of L, so only the indirect experiment applies"

    def lagrangian_expr(self, q, qd, p):
        """The rigid-body form (the robot's true Lagrangian is not known)."""
        q1, q2 = q
        v1, v2 = qd
        half = sympy.Rational(1, 2)
        kinetic = (
            half * (p.I1 + p.m2 * p.l1**2) * v1**2
            + half * p.I2 * (v1 + v2) ** 2
            + p.m2 * p.l1 * p.r2 * sympy.cos(q2) * (v1**2 + v1 * v2)
        )
        # q = 0 hangs down: V = -g (m1 r1 + m2 l1) cos q1 - g m2 r2 cos(q1 + q2)
        gravity = p.g * (p.m1 * p.r1 + p.m2 * p.l1) * sympy.cos(q1) + p.g * p.m2 * p.r2 * sympy.cos(q1 + q2)
        return kinetic + gravity

    def load(self, split: str, spec: FilterSpec = DEFAULT_FILTER, *, filter_torque: bool = True) -> Dataset:
        """The ``train`` (trajectories 00, 01, 02, 04) or ``test`` (03, 05) split."""
        if split not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', got {split!r}")
        s = _samples(split, spec, filter_torque)
        names = TRAIN_TRAJECTORIES if split == "train" else TEST_TRAJECTORIES
        source = f"dfki_trajectory_{{{','.join(names)}}}.csv.gz:{split}"
        meta = {"filter": asdict(spec), "torque_filtered": filter_torque}
        return Dataset(s["q"].copy(), s["qd"].copy(), s["qdd"].copy(), s["tau"].copy(), None, self.name, source, meta)
