"""The DFKI real double pendulum (design A.0): measured trajectories.

Six excitation trajectories recorded on the real robot of the DFKI RIC
Underactuated Robotics Lab (``double_pendulum`` repository, design A.0,
``data/experiment_records/design_A.0/20220815/sys_id``), shipped gzipped in
``systems/data`` with their BSD-3-Clause license. Angles are *relative*: q2
is measured against link 1 and ``q = 0`` hangs down.

Split
-----
A measured system (:mod:`systems.measured`) declared by
``data/dfki_double_pendulum.toml``: six trajectories, one recording each.
Trajectories 00, 01, 02 and 04 train, 03 and 05 test (``--split swapped``:
the other way round). 04 and 05 are the two fast ones (joint 2 turns over,
velocities to 20 rad/s), so each side has one. Each sample keeps its time,
so runs report driven rollouts of the test recordings and the residual loop
offers a time shift.

From a recording to samples (:func:`bench.core.recordings.preprocess`)
----------------------------------------------------------------------
No accelerations are recorded, the timestamps are not uniform (2 ms, with
gaps to 3.6 ms) and the measured velocities are quantized (steps of
0.011 rad/s). Each trajectory is turned into samples by the suite's
filter-and-differentiate step: interpolation onto a uniform 2 ms grid, a
zero-phase Butterworth low-pass of order 4 on q, qd and tau, qdd by central
differences, 0.25 s trimmed from each end, every 5th sample kept.

The lab publishes recordings in two column layouts (:data:`LAYOUTS`):
``time, pos_meas1, pos_meas2, vel_meas1, vel_meas2, tau_meas1, tau_meas2``
(the shipped ones) and ``time, pos1, pos2, vel1, vel2, tau1, tau2``;
:func:`read_raw` reads either.

The cut-off was chosen by measuring: ``python -m bench study dfki-filter`` fits the
lab's model structure (rigid body, rotor inertia, viscous and Coulomb
friction) by least squares for a range of cut-offs and prints its test torque
MSE against the *unfiltered* measured torque. Results are in
``results/measured/dfki_filter.md``.

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

from dataclasses import dataclass
from pathlib import Path

import sympy

from bench.core.data import DataError
from bench.core.csv_format import read_frame
from bench.core.recordings import ColumnMap, Recording, read_recording
from systems.base import SYSTEMS, System
from systems.measured import Measured, read_spec

DATA_DIR = Path(__file__).parent / "data"
#: the recordings, their trajectories and the split
DECLARATION = read_spec(DATA_DIR / "dfki_double_pendulum.toml")
#: the lab's two column layouts of a recording
LAYOUTS = (
    ColumnMap("time", ("pos_meas1", "pos_meas2"), ("vel_meas1", "vel_meas2"), ("tau_meas1", "tau_meas2")),
    ColumnMap("time", ("pos1", "pos2"), ("vel1", "vel2"), ("tau1", "tau2")),
)
RAW_COLUMNS = LAYOUTS[0].columns
#: the lab's own identified friction (model 2.0), for reference
LAB_FRICTION = {"viscous": (0.001, 0.001), "coulomb": (0.093, 0.078), "coulomb_slope": 100.0}
#: the low-pass cut-off, as the declaration gives it; the recordings whose torques chose it on training data alone (each held
#: out in turn, ``python -m bench study dfki-filter``; docs/choices.md) are the declaration's ``[filter] chosen_on``,
#: and a figure tested on any of them is test-informed (:meth:`~systems.measured.MeasuredSpec.chose_filter`)
CUTOFF_HZ = DECLARATION.filter.cutoff_hz


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


def layout_of(path: str | Path) -> ColumnMap:
    """The lab's layout (:data:`LAYOUTS`) a raw DFKI recording is in; a
    :class:`DataError` naming the file and the columns it lacks otherwise."""
    path = Path(path)
    header = read_frame(path, nrows=1).columns
    layout = next((m for m in LAYOUTS if set(m.columns) <= set(header)), None)
    if layout is None:
        best = min(LAYOUTS, key=lambda m: len(set(m.columns) - set(header)))
        missing = [c for c in best.columns if c not in header]
        raise DataError(f"{path}: missing column(s) {', '.join(missing)} of a DFKI recording "
                        f"(or give your own layout: bench convert --columns time=...,q_1=...,qd_1=...,tau_1=...)")
    return layout


def read_raw(path: str | Path) -> Recording:
    """A raw DFKI recording in either of the lab's layouts (:data:`LAYOUTS`),
    checked: numeric and finite, with strictly increasing time. Raises
    :class:`DataError` naming the file and the column."""
    return read_recording(path, layout_of(path))


def trajectory_path(name: str) -> Path:
    return DATA_DIR / f"dfki_trajectory_{name}.csv.gz"


@SYSTEMS.add("dfki_double_pendulum", "measured", "external")
class DfkiDoublePendulum(Measured, System):
    title = "the DFKI real double pendulum"
    summary = ("measured: the DFKI real double pendulum (BSD-3), six excitation trajectories shipped in "
               "`systems/data`; relative angles; accelerations by a documented zero-phase low-pass and central "
               "differences (cut-off chosen by `python -m bench study dfki-filter`); declared by "
               "`systems/data/dfki_double_pendulum.toml`; train 00, 01, 02, 04, test 03, 05 (`--split swapped` the "
               "other way round); each sample keeps its time, so runs record driven rollouts of the test recordings "
               "and the residual loop offers a time shift; indirect only; SysId fits the rigid-body form in masses, "
               "centre-of-mass distances and inertias")
    coordinates = ("q1", "q2_relative")
    planar_chain = True  # its second link's length is not given: no tip payload
    as_arm = f"measured:{DATA_DIR / 'dfki_double_pendulum_arm.toml'}"
    Params = DfkiParams
    sysid_unknowns = ("m1", "m2", "r1", "r2", "I1", "I2")
    measured = DECLARATION
    reference = ("with this pre-processing, the lab's own identified model 2.0 (rigid body, rotor inertia, "
                 "viscous and Coulomb friction; not fitted here) has a test torque MSE of 0.0177, and a "
                 "least-squares fit of the rigid-body form alone 0.0343 "
                 "(`python -m bench study dfki-filter`, results/measured/dfki_filter.md).")
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
