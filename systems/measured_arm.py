"""Measured robot arms: a URDF's kinematics with recordings of the real arm.

A measured arm is an arm from its URDF (:mod:`systems.urdf_arm`: Pinocchio
gives the regressors SysId fits) whose data are recordings of the real
robot (:mod:`systems.measured`: named trajectories, the splits that hold
them out whole, time). Its file is a measured system's file with a
``urdf`` key::

    urdf = "my_arm.urdf"
    columns = "time=t,q_1=pos1,qd_1=vel1,tau_1=eff1,q_2=pos2,qd_2=vel2,tau_2=eff2"
    test = ["fast"]
    [recordings]
    run1 = { file = "run1.csv", trajectory = "slow" }
    run2 = { file = "run2.csv", trajectory = "slow" }
    run3 = { file = "run3.csv", trajectory = "fast" }

An arm within a larger robot (one arm of two, with a head and grippers) names
its chain: ``root`` and ``tip`` links (``tip`` alone: from the robot's base),
or ``joints``, its joint names in the logs' order; every other joint is
locked, at its neutral position or where ``locked_at = { joint = value }``
says (Pinocchio's reduced model, :func:`systems.urdf_arm.chain`).

``--systems measured:my_arm.toml`` (:func:`register_measured`) makes it a
system named ``measured_my_arm``. The file is checked when it is registered,
before anything runs: every recording names a trajectory, the column map
names as many joints as the URDF has, every log has its columns, and the
test trajectories are among those named.

The URDF's masses and inertias are the robot description's, often
placeholders: nothing here needs them. They are not a truth (the form's
``true_values`` are ``None``, so no parameter error is claimed); feasible
identification uses them only as the point its unidentified directions are
pulled to (:func:`bench.physics.feasible.feasible_fit`), which leaves every
torque unchanged.

``kuka_lwr4``: a real KUKA LWR4+ (FloBaRoID's recordings; LGPL-3.0,
``data/LICENSE.kuka_lwr4``), declared by ``data/kuka_lwr4.toml`` the same way.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from bench.core.data import DataError
from bench.physics.system import LinearForm
from systems.base import SYSTEMS, register_file
from systems.measured import Measured, MeasuredSpec, check_logs, read_spec
from systems.urdf_arm import UrdfArm, chain, urdf_arm

DATA_DIR = Path(__file__).parent / "data"


class MeasuredArm(Measured, UrdfArm):
    """An arm from its URDF whose data are recordings of the real robot; see the module docstring."""

    not_applicable = "a measured arm's recordings have torques and no samples of L, so only the indirect experiment applies"

    def linear_form(self) -> LinearForm:
        """The URDF's regressors; no true values (the URDF's inertias are no measurement of the arm)."""
        return dataclasses.replace(super().linear_form(), true_values=None)


def measured_arm(spec: MeasuredSpec | str | Path, *, name: str | None = None) -> type[MeasuredArm]:
    """The System class of the measured arm a measured-arm file declares, checked (:func:`read_spec`, :func:`check_logs`)."""
    spec = spec if isinstance(spec, MeasuredSpec) else read_spec(spec)
    if spec.urdf is None:
        raise DataError(f"{spec.source}: missing 'urdf' (a measured arm's file names its URDF: urdf = \"my_arm.urdf\")")
    if not spec.urdf.is_file():
        raise DataError(f"{spec.source}: its URDF {spec.urdf} does not exist")
    locked = ()
    if spec.tip is not None or spec.root is not None or spec.joints is not None:
        try:
            picked, locked = chain(spec.urdf, spec.root, spec.tip, spec.joints)
        except DataError as exc:
            raise DataError(f"{spec.source}: {exc}") from None
        if len(picked) != spec.columns.dof:
            what = (f"the chain from {spec.root or 'the base'} to {spec.tip}" if spec.joints is None
                    else "the joints named")
            raise DataError(f"{spec.source}: {what} in {spec.urdf.name} has {len(picked)} joint(s) "
                            f"({', '.join(picked)}), but its columns name {spec.columns.dof}")
    elif spec.locked_at:
        raise DataError(f"{spec.source}: locked_at holds the joints outside the arm; name the arm (root and tip, or joints)")
    arm = urdf_arm(spec.urdf, name=name or spec.source.stem, locked=locked, locked_at=spec.locked_at)
    check_logs(spec, len(arm.coordinates))
    test = ", ".join(spec.test)
    return type(f"Measured_{arm.__name__}", (MeasuredArm, arm), {
        "measured": spec, "__module__": __name__, "__doc__": f"{spec.source.name}: {len(spec.recordings)} recording(s) of "
                                    f"{len(spec.trajectories)} trajectories; the default split tests on {test}.",
    })


def register_measured(plugin: str) -> str:
    """Register the arm of ``measured:PATH`` under ``measured_<file stem>``
    (:func:`systems.base.register_file`); returns that name."""
    return register_file("measured", plugin.split(":", 1)[1], ("measured", "arm"),
                         lambda path, name: measured_arm(path, name=name),
                         lambda cls: getattr(getattr(cls, "measured", None), "source", None))


@SYSTEMS.add("kuka_lwr4", "measured", "arm")
class KukaLwr4(measured_arm(DATA_DIR / "kuka_lwr4.toml", name="kuka_lwr4")):
    """A real KUKA LWR4+, 7 joints: runs 1 and 2 repeat excitation trajectory A, run 3 follows B (faster)."""

    title = "a real KUKA LWR4+"
    summary = ("measured: a real KUKA LWR4+, 7 joints (FloBaRoID's recordings and URDF, LGPL-3.0, shipped in "
               "`systems/data`): three 25 s recordings at 200 Hz with the joint torque sensors' torques; runs 1 and 2 "
               "repeat trajectory A, run 3 is trajectory B; the default split trains on A and tests on B, `--split "
               "swapped` the other way round; low-passed at 10 Hz, 10 ms a sample; indirect only; the URDF gives the "
               "kinematics (its inertias are placeholders nothing uses); every run records the standard model beside "
               "it and the driven rollouts of the test recording ([systems/measured_arm.py](../systems/measured_arm.py))")
