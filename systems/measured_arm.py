"""Measured robot arms: a URDF's kinematics with recordings of the real arm.

A measured arm is an arm from its URDF (:mod:`systems.urdf_arm`: Pinocchio
gives the regressors SysId fits) whose data are recordings of the real
robot, grouped by the excitation trajectory each follows. A robot repeats
a trajectory, and a recording of the same trajectory again is a near copy
of the first: a model checked on a repeat of the trajectory it was fitted on
has not been tested. So a measured arm's splits hold out whole trajectories:

* ``default``: train on every trajectory but the held-out ones (``test``),
  test on those;
* ``swapped``: the other way round.

One file declares an arm, a TOML *measured-arm file* (paths relative to it)::

    urdf = "my_arm.urdf"
    columns = "time=t,q_1=pos1,qd_1=vel1,tau_1=eff1,q_2=pos2,qd_2=vel2,tau_2=eff2"
    test = ["fast"]                          # the trajectories the default split tests on
    time_unit = "s"                          # optional: the time column's unit, s (default), ms or us
    degrees = false                          # optional: true where q and qd are in degrees
    [filter]                                 # optional: bench.core.recordings.FilterSpec's fields
    cutoff_hz = 10
    [recordings]
    run1 = { file = "run1.csv", trajectory = "slow" }
    run2 = { file = "run2.csv", trajectory = "slow" }
    run3 = { file = "run3.csv", trajectory = "fast" }

and ``--systems measured:my_arm.toml`` (:func:`register_measured`) makes it a
system named ``measured_my_arm``. Each recording is a robot log in the
format of ``bench convert --columns`` (a time column in seconds, or in
``time_unit``; per joint q, qd and tau, in radians unless ``degrees``),
its rate checked as ``convert`` checks it, turned into samples by the suite's filter-and-differentiate
step (:func:`bench.core.recordings.preprocess`); each sample keeps its
recording, its trajectory and its time, so that the residual loop validates
on whole trajectories and the driven rollouts (:mod:`bench.evaluation.driven`)
follow a recording in time. The file is checked when it is registered, before
anything runs: every recording names a trajectory, the column map names as
many joints as the URDF has, every log has its columns, and the test
trajectories are among those named.

The URDF's masses and inertias are the robot description's, often
placeholders: nothing here needs them. They are not a truth (the form's
``true_values`` are ``None``, so no parameter error is claimed); feasible
identification uses them only as the point its unidentified directions are
pulled to (:func:`bench.core.feasible.feasible_fit`), which leaves every
torque unchanged.

``kuka_lwr4``: a real KUKA LWR4+ (FloBaRoID's recordings; LGPL-3.0,
``data/LICENSE.kuka_lwr4``), declared by ``data/kuka_lwr4.toml`` the same way.
"""

from __future__ import annotations

import dataclasses
import functools
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from bench.core.data import Dataset, DataError, read_frame
from bench.core.errors import ConfigError
from bench.core.recordings import (TIME_UNITS, ColumnMap, FilterSpec, check_rate, in_units, joined, preprocess,
                                   read_recording)
from bench.core.system import LinearForm
from systems.base import SYSTEMS
from systems.urdf_arm import UrdfArm, urdf_arm

DATA_DIR = Path(__file__).parent / "data"
#: a system given by its measured-arm file: ``measured:PATH``
MEASURED = "measured:"
#: the splits of every measured arm: its declared one, and train and test exchanged
SPLITS = ("default", "swapped")


@dataclass(frozen=True)
class RecordingFile:
    """One recording of a measured arm: its name, the trajectory it follows, its log."""

    name: str
    trajectory: str
    path: Path


@dataclass(frozen=True)
class MeasuredArmSpec:
    """A measured-arm file, read and checked (see the module docstring)."""

    source: Path
    urdf: Path
    columns: ColumnMap
    recordings: tuple[RecordingFile, ...]
    test: tuple[str, ...]
    filter: FilterSpec
    time_unit: str = "s"
    degrees: bool = False

    @property
    def trajectories(self) -> tuple[str, ...]:
        """Every trajectory, in the order the recordings name them."""
        return tuple(dict.fromkeys(r.trajectory for r in self.recordings))

    def parts(self, split: str) -> dict[str, tuple[str, ...]]:
        """The trajectories each part of ``split`` holds: ``{"train": ..., "test": ...}``."""
        if split not in SPLITS:
            raise ConfigError(f"{self.source}: no split {split!r}; a measured arm offers {', '.join(SPLITS)}")
        test = self.test
        train = tuple(t for t in self.trajectories if t not in test)
        return {"train": train, "test": test} if split == "default" else {"train": test, "test": train}


def read_spec(path: str | Path) -> MeasuredArmSpec:
    """The measured-arm file at ``path``, checked; :class:`DataError` naming the file otherwise."""
    path = Path(path).expanduser().resolve()
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DataError(f"{path}: no such measured-arm file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DataError(f"{path}: not a readable TOML file ({exc})") from None
    known = {"urdf", "columns", "test", "filter", "recordings", "time_unit", "degrees"}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise DataError(f"{path}: unknown key(s) {', '.join(unknown)} (a measured-arm file has {', '.join(sorted(known))})")
    for key in ("urdf", "columns", "recordings", "test"):
        if key not in raw:
            raise DataError(f"{path}: missing {key!r} (see python -m bench list's measured arms, or the README)")
    here = path.parent
    urdf = (here / str(raw["urdf"])).resolve()
    try:
        columns = ColumnMap.parse(str(raw["columns"]), f"{path}: columns")
    except ConfigError as exc:
        raise DataError(str(exc)) from None
    if not isinstance(raw["recordings"], dict) or not raw["recordings"]:
        raise DataError(f"{path}: [recordings] must name at least one recording, each {{ file = ..., trajectory = ... }}")
    recordings = []
    for name, entry in raw["recordings"].items():
        if not isinstance(entry, dict) or "file" not in entry:
            raise DataError(f"{path}: recording {name!r} needs a file (run1 = {{ file = \"run1.csv\", trajectory = \"A\" }})")
        trajectory = str(entry.get("trajectory", "")).strip()
        if not trajectory:
            raise DataError(f"{path}: recording {name!r} ({entry['file']}) names no trajectory: say which excitation "
                            f"trajectory it follows (trajectory = \"...\"), so that a repeat of it is never its test")
        recordings.append(RecordingFile(str(name), trajectory, (here / str(entry["file"])).resolve()))
    test = (raw["test"],) if isinstance(raw["test"], str) else tuple(map(str, raw["test"]))
    named = list(dict.fromkeys(r.trajectory for r in recordings))
    missing = [t for t in test if t not in named]
    if missing or not test:
        raise DataError(f"{path}: test names trajectory(ies) {', '.join(missing) or '(none)'}, but the recordings "
                        f"follow {', '.join(named)}")
    if set(test) == set(named):
        raise DataError(f"{path}: test holds every trajectory ({', '.join(named)}); leave at least one to train on")
    try:
        spec = FilterSpec(**raw.get("filter", {}))
    except TypeError as exc:
        raise DataError(f"{path}: [filter]: {exc} (its keys: {', '.join(f.name for f in dataclasses.fields(FilterSpec))})") from None
    except ConfigError as exc:
        raise DataError(f"{path}: [filter]: {exc}") from None
    time_unit = raw.get("time_unit", "s")
    if time_unit not in TIME_UNITS:
        raise DataError(f"{path}: time_unit must be one of {', '.join(TIME_UNITS)}, got {time_unit!r}")
    degrees = raw.get("degrees", False)
    if not isinstance(degrees, bool):
        raise DataError(f"{path}: degrees must be true or false, got {degrees!r}")
    return MeasuredArmSpec(path, urdf, columns, tuple(recordings), test, spec, time_unit, degrees)


def check_logs(spec: MeasuredArmSpec, dof: int) -> None:
    """Each log has the columns of the map, and the map names ``dof`` joints
    (the URDF's): :class:`DataError` naming both files otherwise. Reads the
    logs' headers only."""
    if spec.columns.dof != dof:
        raise DataError(f"{spec.source}: {spec.urdf.name} has {dof} joint(s), but its columns name {spec.columns.dof} "
                        f"(q_1 .. q_{spec.columns.dof}) for the logs {', '.join(r.path.name for r in spec.recordings)}")
    for r in spec.recordings:
        header = read_frame(r.path, nrows=1).columns
        absent = [c for c in spec.columns.columns if c not in header]
        if absent:
            raise DataError(f"{r.path}: missing column(s) {', '.join(absent)} that {spec.source.name} maps for "
                            f"{spec.urdf.name}'s {dof} joint(s)")


@functools.lru_cache(maxsize=8)
def _samples(spec: MeasuredArmSpec, trajectories: tuple[str, ...]) -> dict[str, np.ndarray]:
    chosen = [r for r in spec.recordings if r.trajectory in trajectories]
    parts = []
    for r in chosen:
        recording = in_units(read_recording(r.path, spec.columns), spec.time_unit, spec.degrees)
        check_rate(recording, spec.filter, r.path, spec.columns.time)
        parts.append(preprocess(recording, spec.filter))
    return joined(parts, [r.name for r in chosen], [r.trajectory for r in chosen])


class MeasuredArm(UrdfArm):
    """An arm from its URDF whose data are recordings of the real robot; see the module docstring."""

    simulated = False
    experiments = ("indirect",)
    splits = SPLITS
    not_applicable = "a measured arm's recordings have torques and no samples of L, so only the indirect experiment applies"
    measured: ClassVar[MeasuredArmSpec]

    @classmethod
    def source_files(cls) -> list[str]:
        return [str(cls.measured.source), *(str(r.path) for r in cls.measured.recordings), *super().source_files()]

    def load(self, part: str) -> Dataset:
        """The ``train`` or ``test`` part of the instance's split (:attr:`split`): whole
        trajectories, each sample with its recording, trajectory and time."""
        parts = self.measured.parts(self.split)
        if part not in parts:
            raise ValueError(f"part must be 'train' or 'test', got {part!r}")
        trajectories = parts[part]
        s = _samples(self.measured, trajectories)
        names = sorted({str(r) for r in s["recording"]})
        source = (f"{self.measured.source.name}:{part} of split {self.split} (trajectories {', '.join(trajectories)}; "
                  f"recordings {', '.join(names)})")
        meta = {"filter": dataclasses.asdict(self.measured.filter), "split": self.split}
        return Dataset(s["q"].copy(), s["qd"].copy(), s["qdd"].copy(), s["tau"].copy(), None, self.name, source, meta,
                       recording=s["recording"].copy(), sign_qd=s["sign_qd"].copy(), trajectory=s["trajectory"].copy(),
                       time=s["time"].copy())

    def linear_form(self) -> LinearForm:
        """The URDF's regressors; no true values (the URDF's inertias are no measurement of the arm)."""
        return dataclasses.replace(super().linear_form(), true_values=None)

    def describe(self) -> dict:
        m = self.measured
        return {**super().describe(), "split": self.split, "test_trajectories": list(m.parts(self.split)["test"]),
                "recordings": {r.name: r.trajectory for r in m.recordings}, "filter": dataclasses.asdict(m.filter)}


def measured_arm(spec: MeasuredArmSpec | str | Path, *, name: str | None = None) -> type[MeasuredArm]:
    """The System class of the measured arm a measured-arm file declares, checked (:func:`read_spec`, :func:`check_logs`)."""
    spec = spec if isinstance(spec, MeasuredArmSpec) else read_spec(spec)
    if not spec.urdf.is_file():
        raise DataError(f"{spec.source}: its URDF {spec.urdf} does not exist")
    arm = urdf_arm(spec.urdf, name=name or spec.source.stem)
    check_logs(spec, len(arm.coordinates))
    test = ", ".join(spec.test)
    return type(f"Measured_{arm.__name__}", (MeasuredArm, arm), {
        "measured": spec, "__module__": __name__, "__doc__": f"{spec.source.name}: {len(spec.recordings)} recording(s) of "
                                    f"{len(spec.trajectories)} trajectories; the default split tests on {test}.",
    })


def register_measured(plugin: str) -> str:
    """Register the arm of ``measured:PATH`` under ``measured_<file stem>``; returns
    that name. Registering the same file again is a no-op."""
    path = Path(plugin[len(MEASURED):]).expanduser().resolve()
    name = "measured_" + re.sub(r"[^0-9a-zA-Z]+", "_", path.name.split(".")[0]).strip("_").lower()
    if name in SYSTEMS:
        if getattr(SYSTEMS[name], "measured", None) is not None and SYSTEMS[name].measured.source == path:
            return name
        raise DataError(f"{path}: another measured-arm file is registered as {name!r} already")
    SYSTEMS.add(name, "measured", "arm")(measured_arm(path, name=name))
    return name


@SYSTEMS.add("kuka_lwr4", "measured", "arm")
class KukaLwr4(measured_arm(DATA_DIR / "kuka_lwr4.toml", name="kuka_lwr4")):
    """A real KUKA LWR4+, 7 joints: runs 1 and 2 repeat excitation trajectory A, run 3 follows B (faster)."""
