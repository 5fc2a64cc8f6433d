"""DeLaN's 2-DoF character trajectories (Lutter, Ritter & Peters, ICLR 2019).

A simulated 2-DoF planar robot writing 20 handwritten characters; 2913 samples
of ``q, qd, qdd, tau`` at dt = 0.04 s, shipped in ``systems/data`` with its MIT
license, and declared as a measured system (:mod:`systems.measured`) by
``data/delan_characters.toml``: each character is a recording and a
trajectory of its own, its rows the samples as they are (accelerations
included) with their time. The published split is kept: the characters
``e``, ``q`` and ``v`` are the test set, the other 17 the training set
(``--split swapped``: the other way round). DeLaN's README reports a torque
MSE of 4.327e-4 on them.

These are trajectories with torques only: there are no samples of ``L``, so
only the indirect experiment applies. The robot's true Lagrangian is not
given; system identification fits the rigid-body form of a planar 2-link arm
with relative joint angles, in lumped (base) parameters,

.. math::

    L = \\tfrac12 a_1 \\dot q_1^2 + (a_2 \\cos q_2 + a_3 \\sin q_2)(\\dot q_1^2 + \\dot q_1 \\dot q_2)
      + \\tfrac12 a_4 (\\dot q_1 + \\dot q_2)^2
      - (b_1 \\cos q_1 + b_2 \\sin q_1 + b_3 \\cos(q_1 + q_2) + b_4 \\sin(q_1 + q_2)),

which holds for any link masses, lengths, centres of mass and inertias and
any direction of gravity in the plane.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sympy

from bench.core.data import DataError, Dataset
from bench.core.csv_format import numeric_column, read_frame
from systems.base import SYSTEMS, System
from systems.measured import Measured, read_spec

DATA = Path(__file__).parent / "data" / "delan_characters.csv.gz"
#: the characters, their split and how their rows are read
DECLARATION = read_spec(DATA.with_name("delan_characters.toml"))
PUBLISHED_TORQUE_MSE = 4.327e-4


@dataclass(frozen=True)
class PlanarArmParams:
    """Lumped parameters of a planar 2-link arm (no true values are known)."""

    a1: float = 1.0
    a2: float = 0.0
    a3: float = 0.0
    a4: float = 1.0
    b1: float = 0.0
    b2: float = 0.0
    b3: float = 0.0
    b4: float = 0.0


@functools.lru_cache(maxsize=1)
def _frame():
    if not DATA.is_file():
        raise DataError(f"{DATA}: the packaged DeLaN data is missing")
    return read_frame(DATA)


def _columns(frame, names: tuple[str, ...]) -> np.ndarray:
    """The columns ``NAME_1, NAME_2`` of each name, side by side: ``(n, 2 * len(names))``."""
    return np.concatenate([np.stack([numeric_column(frame, f"{k}_{i}", DATA) for i in (1, 2)], axis=1) for k in names],
                          axis=1)


@SYSTEMS.add("delan_characters", "measured", "external")
class DelanCharacters(Measured, System):
    title = "DeLaN's characters"
    summary = ("measured: DeLaN's 2-DoF character trajectories (MIT), shipped in `systems/data` and declared by "
               "`systems/data/delan_characters.toml` (each character a recording and a trajectory, its rows as logged "
               "with their accelerations and time); published split (test characters e, q, v), `--split swapped` the "
               "other way round; indirect experiment only; runs record driven rollouts of the test characters; SysId "
               "fits a lumped rigid-body form")
    coordinates = ("q1", "q2_relative")
    Params = PlanarArmParams
    sysid_unknowns = ("a1", "a2", "a3", "a4", "b1", "b2", "b3", "b4")
    measured = DECLARATION
    reference = f"DeLaN's README reports a test torque MSE of {PUBLISHED_TORQUE_MSE} on these characters (e, q, v)."
    not_applicable = "DeLaN's data are trajectories with torques and no samples of L, so only the indirect experiment applies"

    def lagrangian_expr(self, q, qd, p):
        """The parametric rigid-body form (the robot's true Lagrangian is not given)."""
        q1, q2 = q
        v1, v2 = qd
        kinetic = p.a1 * v1**2 / 2 + (p.a2 * sympy.cos(q2) + p.a3 * sympy.sin(q2)) * (v1**2 + v1 * v2) + p.a4 * (v1 + v2) ** 2 / 2
        potential = p.b1 * sympy.cos(q1) + p.b2 * sympy.sin(q1) + p.b3 * sympy.cos(q1 + q2) + p.b4 * sympy.sin(q1 + q2)
        return kinetic - potential

    def forces(self, data: Dataset) -> dict[str, np.ndarray] | None:
        """The parts of the torque the data ship (``tau_inertial``,
        ``tau_coriolis``, ``tau_gravity``), at the samples of ``data`` that
        are rows of the packaged file; ``None`` if any is not."""
        frame = _frame()
        index = {row.tobytes(): i for i, row in enumerate(_columns(frame, ("q", "qd", "qdd")))}
        rows = [index.get(row.tobytes()) for row in np.concatenate([data.q, data.qd, data.qdd], axis=1)]
        if any(i is None for i in rows):
            return None
        parts = {"inertial": "tau_inertial", "coriolis": "tau_coriolis", "gravity": "tau_gravity"}
        return {part: _columns(frame, (column,))[rows] for part, column in parts.items()}
