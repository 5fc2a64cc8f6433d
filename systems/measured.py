"""Measured systems: recordings of a real (or recorded) robot, declared by one file.

A measured system's data are recordings grouped by the excitation trajectory
each follows. A robot repeats a trajectory, and a recording of the same
trajectory again is a near copy of the first: a model checked on a repeat of
the trajectory it was fitted on has not been tested. So a measured system's
splits hold out whole trajectories:

* ``default``: train on every trajectory but the held-out ones (``test``),
  test on those;
* ``swapped``: the other way round.

One TOML file declares the recordings (paths relative to it)::

    columns = "time=t,q_1=pos1,qd_1=vel1,tau_1=eff1,q_2=pos2,qd_2=vel2,tau_2=eff2"
    test = ["fast"]                          # the trajectories the default split tests on
    time_unit = "s"                          # optional: the time column's unit, s (default), ms or us
    rate_hz = 100                            # optional, for logs without a time column (no time= in columns)
    degrees = false                          # optional: true where q and qd are in degrees
    [filter]                                 # optional: bench.core.recordings.FilterSpec's fields
    cutoff_hz = 10
    [recordings]
    run1 = { file = "run1.csv", trajectory = "slow" }
    run2 = { file = "run2.csv", trajectory = "slow" }
    run3 = { file = "run3.csv", trajectory = "fast" }

or, where one file holds every recording and a column names each row's
recording (each recording a trajectory of its own), ``recordings_in = {
file = "all.csv", column = "character" }`` in place of ``[recordings]``.
Each recording is a robot log in the format of ``bench convert --columns``,
its rate checked as ``convert`` checks it and turned into samples by the
suite's filter-and-differentiate step
(:func:`bench.core.recordings.preprocess`); with ``as_recorded = true`` the
log holds its accelerations too (``qdd_i`` in ``columns``) and its rows are
the samples as they are. Each sample keeps its recording, its trajectory and
its time, so that the residual loop validates on whole trajectories, offers
the laws that need time (a time shift), and the driven rollouts
(:mod:`bench.evaluation.driven`) follow a recording in time.

:class:`Measured` gives a system its data from such a file; the system
gives the model (a URDF's arm, :mod:`systems.measured_arm`, or a form of its
own, as the DFKI double pendulum and DeLaN's characters do).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from bench.core.experiment import INDIRECT
from bench.core.data import Dataset, DataError
from bench.core.csv_format import read_frame
from bench.core.errors import ConfigError, UserError
from bench.core.fileio import file_digest
from bench.core.sealed import seal
from bench.core.recordings import TIME_UNITS, ColumnMap, FilterSpec, joined, preprocess_segments, read_log

#: the splits of every measured system: its declared one, and train and test exchanged
SPLITS = ("default", "swapped")
#: the parts :meth:`Measured.load` gives: a split's two, or every trajectory
PARTS = ("train", "test", "all")


@dataclass(frozen=True)
class RecordingFile:
    """One recording: its name, the trajectory it follows, its log (and, where
    one log holds several, the column and value that pick its rows)."""

    name: str
    trajectory: str
    path: Path
    column: str | None = None


@dataclass(frozen=True)
class MeasuredSpec:
    """A measured system's file, read and checked (see the module docstring)."""

    source: Path
    columns: ColumnMap
    recordings: tuple[RecordingFile, ...]
    test: tuple[str, ...]
    filter: FilterSpec
    time_unit: str = "s"
    degrees: bool = False
    as_recorded: bool = False
    #: a measured arm's URDF (:mod:`systems.measured_arm`); ``None`` for a system with a form of its own
    urdf: Path | None = None
    #: the logs' rate, Hz, where they have no time column
    rate_hz: float | None = None
    #: the arm within a larger robot's URDF: its root and tip links, or its joints in the logs' order
    root: str | None = None
    tip: str | None = None
    joints: tuple[str, ...] | None = None
    #: where the URDF's other joints are locked, where not at their neutral positions: ``((joint, value), ...)``
    locked_at: tuple[tuple[str, float], ...] = ()
    #: the trajectories whose torques chose the filter (``[filter] chosen_on``): a figure tested on any of them
    #: rests on a choice that read its test torques (:meth:`test_informed`)
    filter_chosen_on: tuple[str, ...] = ()
    #: the trajectories whose test figures were read while a rule of the suite was chosen (``[informed]
    #: trajectories``), and the rule in words (``[informed] rule``): a figure tested on any of them rests on it
    informed_on: tuple[str, ...] = ()
    informed_rule: str | None = None

    @property
    def trajectories(self) -> tuple[str, ...]:
        """Every trajectory, in the order the recordings name them."""
        return tuple(dict.fromkeys(r.trajectory for r in self.recordings))

    def parts(self, split: str) -> dict[str, tuple[str, ...]]:
        """The trajectories each part of ``split`` holds: ``{"train": ..., "test": ..., "all": ...}``."""
        if split not in SPLITS:
            raise ConfigError(f"{self.source}: no split {split!r}; a measured system offers {', '.join(SPLITS)}")
        test = self.test
        train = tuple(t for t in self.trajectories if t not in test)
        if split == "swapped":
            train, test = test, train
        return {"train": train, "test": test, "all": self.trajectories}

    def chose_filter(self, trajectories) -> list[str]:
        """Which of ``trajectories`` chose the filter (:attr:`filter_chosen_on`): a figure tested on any of them
        is test-informed."""
        return sorted(set(trajectories) & set(self.filter_chosen_on))

    def test_informed(self, split: str) -> list[str]:
        """The test trajectories of ``split`` that chose the filter (:meth:`chose_filter`) or were read while a rule
        was chosen (:attr:`informed_on`)."""
        test = self.parts(split)["test"]
        return sorted(set(self.chose_filter(test)) | (set(test) & set(self.informed_on)))

    def informed_by(self, split: str) -> list[str]:
        """What rests on ``split``'s test-informed trajectories (:meth:`test_informed`), in words."""
        test = self.parts(split)["test"]
        return ((["the cut-off of the filter that the system's file declares (`[filter] chosen_on`)"]
                 if self.chose_filter(test) else [])
                + ([self.informed_rule] if self.informed_rule and set(test) & set(self.informed_on) else []))

    def describe(self) -> str:
        """How the recordings become samples, in words."""
        return "the logged rows as they are (accelerations logged)" if self.as_recorded else self.filter.describe()


KNOWN_KEYS = ("urdf", "columns", "test", "filter", "recordings", "recordings_in", "time_unit", "degrees", "as_recorded",
              "rate_hz", "root", "tip", "joints", "locked_at", "informed")

#: a name in a measured-system file: a trajectory, a recording, a column, a link or a joint
_NAME = {"type": "string", "minLength": 1, "maxLength": 1000}
_TEXT = {"type": "string", "minLength": 1, "maxLength": 100_000}
_NAMES = {"anyOf": [_NAME, {"type": "array", "items": _NAME, "minItems": 1, "maxItems": 100_000}]}
#: every field of a measured-system file, its type and range (JSON Schema, by ``jsonschema``), checked after the
#: file's own checks (which say more of what each field means) and before anything is read of its logs; every
#: number must also be finite (:func:`_finite`)
SCHEMA = {
    "type": "object",
    "properties": {
        "urdf": _TEXT, "columns": _TEXT, "test": _NAMES, "time_unit": {"enum": list(TIME_UNITS)},
        "degrees": {"type": "boolean"}, "as_recorded": {"type": "boolean"},
        "rate_hz": {"type": "number", "exclusiveMinimum": 0, "maximum": 1e7},
        "root": _NAME, "tip": _NAME, "joints": {"type": "array", "items": _NAME, "minItems": 1, "maxItems": 64},
        "locked_at": {"type": "object", "additionalProperties": {"type": "number", "minimum": -1e6, "maximum": 1e6}},
        "filter": {"type": "object", "additionalProperties": False, "properties": {
            "dt": {"type": "number", "exclusiveMinimum": 0, "maximum": 3600},
            "cutoff_hz": {"type": "number", "exclusiveMinimum": 0, "maximum": 1e7},
            "order": {"type": "integer", "minimum": 1, "maximum": 64},
            "trim_s": {"type": "number", "minimum": 0, "maximum": 1e6},
            "decimate": {"type": "integer", "minimum": 1, "maximum": 1_000_000}, "chosen_on": _NAMES}},
        "recordings": {"type": "object", "minProperties": 1, "additionalProperties": {
            "type": "object", "required": ["file", "trajectory"], "additionalProperties": False,
            "properties": {"file": _TEXT, "trajectory": _NAME}}},
        "recordings_in": {"type": "object", "required": ["file", "column"], "additionalProperties": False,
                          "properties": {"file": _TEXT, "column": _NAME}},
        "informed": {"type": "object", "required": ["rule", "trajectories"], "additionalProperties": False,
                     "properties": {"rule": _TEXT, "trajectories": {"type": "array", "items": _NAME, "minItems": 1}}},
    },
}


def _finite(value, path: Path, where: tuple = ()) -> None:
    """A :class:`DataError` naming the first field of a measured-system file whose number is not finite (TOML
    writes ``nan`` and ``inf``)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise DataError(f"{path}: {'.'.join(map(str, where)) or 'a value'} is {value!r}, not a finite number")
    if isinstance(value, dict):
        for k, v in value.items():
            _finite(v, path, (*where, k))
    elif isinstance(value, list):
        for k, v in enumerate(value):
            _finite(v, path, (*where, k))


def _check_schema(raw: dict, path: Path) -> None:
    """:data:`SCHEMA` on ``raw``: a :class:`DataError` naming the file and the first field that is not as stated."""
    import jsonschema  # a dependency of the project; imported where a file is checked

    error = jsonschema.exceptions.best_match(jsonschema.Draft202012Validator(SCHEMA).iter_errors(raw))
    if error is not None:
        field = ".".join(map(str, error.absolute_path)) or "the file"
        raise DataError(f"{path}: {field}: {error.message}"[:500])


def read_spec(path: str | Path) -> MeasuredSpec:
    """The measured system's file at ``path``, checked; :class:`DataError` naming the file otherwise."""
    path = Path(path).expanduser().resolve()
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DataError(f"{path}: no such measured-system file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DataError(f"{path}: not a readable TOML file ({exc})") from None
    unknown = sorted(set(raw) - set(KNOWN_KEYS))
    if unknown:
        raise DataError(f"{path}: unknown key(s) {', '.join(unknown)} (a measured-system file has {', '.join(sorted(KNOWN_KEYS))})")
    _finite(raw, path)
    try:
        return _spec(path, raw)
    except UserError:
        raise
    except (TypeError, AttributeError, ValueError, KeyError, IndexError) as exc:  # a field of another kind than
        _check_schema(raw, path)  # the checks above expect: the schema names it
        raise DataError(f"{path}: a field of the wrong kind ({type(exc).__name__}: {exc})"[:300]) from None


def _spec(path: Path, raw: dict) -> MeasuredSpec:
    """:func:`read_spec`'s checks of the parsed file ``raw``, field by field."""
    for key in ("columns", "test"):
        if key not in raw:
            raise DataError(f"{path}: missing {key!r} (see docs/extending.md, A measured arm)")
    here = path.parent
    try:
        columns = ColumnMap.parse(str(raw["columns"]), f"{path}: columns")
    except ConfigError as exc:
        raise DataError(str(exc)) from None
    as_recorded = raw.get("as_recorded", False)
    if not isinstance(as_recorded, bool):
        raise DataError(f"{path}: as_recorded must be true or false, got {as_recorded!r}")
    if as_recorded and not columns.qdd:
        raise DataError(f"{path}: as_recorded needs the logged accelerations in columns (qdd_1=..., one per joint)")
    recordings = _recordings(path, raw)
    test = (raw["test"],) if isinstance(raw["test"], str) else tuple(map(str, raw["test"]))
    named = list(dict.fromkeys(r.trajectory for r in recordings))
    missing = [t for t in test if t not in named]
    if missing or not test:
        raise DataError(f"{path}: test names trajectory(ies) {', '.join(missing) or '(none)'}, but the recordings "
                        f"follow {', '.join(named)}")
    if set(test) == set(named):
        raise DataError(f"{path}: test holds every trajectory ({', '.join(named)}); leave at least one to train on")
    _no_log_twice(path, recordings, test)
    settings = raw.get("filter", {})
    if not isinstance(settings, dict):
        raise DataError(f"{path}: [filter] must be a table (its keys: "
                        f"{', '.join(f.name for f in dataclasses.fields(FilterSpec))}, chosen_on)")
    settings = dict(settings)
    chosen_on = settings.pop("chosen_on", [])
    if isinstance(chosen_on, str):
        chosen_on = [chosen_on]
    if not isinstance(chosen_on, list) or any(str(t) not in named for t in chosen_on):
        raise DataError(f"{path}: [filter] chosen_on must list trajectories of the recordings ({', '.join(named)}), "
                        f"got {chosen_on!r}")
    try:
        spec = FilterSpec(**settings)
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
    urdf = (here / str(raw["urdf"])).resolve() if "urdf" in raw else None
    rate = raw.get("rate_hz")
    if rate is not None and (isinstance(rate, bool) or not isinstance(rate, (int, float)) or not rate > 0):
        raise DataError(f"{path}: rate_hz must be a positive number of Hz, got {rate!r}")
    if columns.time is None and rate is None:
        raise DataError(f"{path}: columns name no time column: name it (time=COLUMN) or give the logs' rate (rate_hz)")
    if columns.time is not None and rate is not None:
        raise DataError(f"{path}: columns name a time column ({columns.time}) and rate_hz is {rate:g}: give one of them")
    root, tip, joints, locked_at = _chain_keys(path, raw)
    informed_on, rule = _informed(path, raw, named)
    _check_schema(raw, path)
    return MeasuredSpec(path, columns, tuple(recordings), test, spec, time_unit, degrees, as_recorded, urdf,
                        None if rate is None else float(rate), root, tip, joints, locked_at,
                        tuple(dict.fromkeys(map(str, chosen_on))), informed_on, rule)


def _informed(path: Path, raw: dict, named: list[str]) -> tuple[tuple[str, ...], str | None]:
    """The ``[informed]`` table: the ``trajectories`` whose test figures were read while a ``rule`` was chosen."""
    table = raw.get("informed")
    if table is None:
        return (), None
    if not isinstance(table, dict) or set(table) != {"rule", "trajectories"}:
        raise DataError(f"{path}: [informed] must be a table of rule (the rule, in words) and trajectories (those "
                        f"read while it was chosen)")
    rule, trajectories = table["rule"], table["trajectories"]
    if not isinstance(rule, str) or not rule.strip() or len(rule) > 1000:
        raise DataError(f"{path}: [informed] rule must say in words which rule the trajectories informed")
    if not isinstance(trajectories, list) or not trajectories or any(str(t) not in named for t in trajectories):
        raise DataError(f"{path}: [informed] trajectories must list trajectories of the recordings "
                        f"({', '.join(named)}), got {trajectories!r}")
    return tuple(dict.fromkeys(map(str, trajectories))), rule.strip()


def _no_log_twice(path: Path, recordings: list[RecordingFile], test: tuple[str, ...]) -> None:
    """A :class:`DataError` where one log (a file, or a file's rows picked by one value) is named by two
    recordings, or where a test recording's file holds the same bytes as a training one's: its test would be a
    repeat of its training data."""
    seen: dict[tuple, RecordingFile] = {}
    for r in recordings:
        key = (r.path, r.column, r.name if r.column else None)
        if key in seen:
            raise DataError(f"{path}: recordings {seen[key].name!r} and {r.name!r} both read {r.path}: "
                            f"one log is one recording")
        seen[key] = r
    files = {r.path for r in recordings if r.column is None}
    sizes = {f: f.stat().st_size for f in files if f.is_file()}
    trained = [r for r in recordings if r.column is None and r.trajectory not in test and r.path in sizes]
    for r in recordings:
        if r.column is not None or r.trajectory not in test or r.path not in sizes:
            continue
        for other in trained:
            if sizes[other.path] == sizes[r.path] and file_digest(other.path) == file_digest(r.path):  # sizes first
                raise DataError(f"{path}: test recording {r.name!r} ({r.path.name}) holds the same log as training "
                                f"recording {other.name!r} ({other.path.name}): its test would repeat its training data")


def _chain_keys(path: Path, raw: dict):
    """``root``, ``tip``, ``joints`` and ``locked_at`` of a measured arm's file, checked for their types."""
    for key in ("root", "tip"):
        if key in raw and not isinstance(raw[key], str):
            raise DataError(f"{path}: {key} must be a link's name, got {raw[key]!r}")
    joints = raw.get("joints")
    if joints is not None:
        if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
            raise DataError(f"{path}: joints must be a list of the arm's joint names in the logs' order, got {joints!r}")
        if "root" in raw or "tip" in raw:
            raise DataError(f"{path}: give the arm's root and tip links, or its joints, not both")
        joints = tuple(joints)
    if ("root" in raw or "tip" in raw or joints) and "urdf" not in raw:
        raise DataError(f"{path}: root, tip and joints pick an arm within a URDF; the file names none (urdf = ...)")
    locked = raw.get("locked_at", {})
    if not isinstance(locked, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                for v in locked.values()):
        raise DataError(f"{path}: locked_at must map joint names to positions, e.g. {{ head_pan = 0.0 }}, got {locked!r}")
    return raw.get("root"), raw.get("tip"), joints, tuple((str(k), float(v)) for k, v in locked.items())


def _recordings(path: Path, raw: dict) -> list[RecordingFile]:
    """The file's recordings: from ``[recordings]``, or from ``recordings_in``'s file and column."""
    here = path.parent
    if ("recordings" in raw) == ("recordings_in" in raw):
        raise DataError(f"{path}: name the recordings either in [recordings] (run1 = {{ file = ..., trajectory = ... }}) "
                        f"or by recordings_in = {{ file = ..., column = ... }}, one of the two")
    if "recordings_in" in raw:
        entry = raw["recordings_in"]
        if not isinstance(entry, dict) or not {"file", "column"} <= set(entry):
            raise DataError(f"{path}: recordings_in needs a file and a column ({{ file = \"all.csv\", column = \"run\" }})")
        log, column = (here / str(entry["file"])).resolve(), str(entry["column"])
        if not log.is_file():
            raise DataError(f"{path}: recordings_in: {log} does not exist")
        frame = _log(log)
        if column not in frame.columns:
            raise DataError(f"{log}: missing column {column} that {path.name} names the recordings by")
        names = [str(v) for v in dict.fromkeys(frame[column].astype(str))]
        return [RecordingFile(name, name, log, column) for name in names]
    if not isinstance(raw["recordings"], dict) or not raw["recordings"]:
        raise DataError(f"{path}: [recordings] must name at least one recording, each {{ file = ..., trajectory = ... }}")
    out = []
    for name, entry in raw["recordings"].items():
        if not isinstance(entry, dict) or "file" not in entry:
            raise DataError(f"{path}: recording {name!r} needs a file (run1 = {{ file = \"run1.csv\", trajectory = \"A\" }})")
        trajectory = str(entry.get("trajectory", "")).strip()
        if not trajectory:
            raise DataError(f"{path}: recording {name!r} ({entry['file']}) names no trajectory: say which excitation "
                            f"trajectory it follows (trajectory = \"...\"), so that a repeat of it is never its test")
        log = (here / str(entry["file"])).resolve()
        if not log.is_file():
            raise DataError(f"{path}: recording {name!r}: its file {entry['file']} ({log}) does not exist")
        out.append(RecordingFile(str(name), trajectory, log))
    return out


def check_logs(spec: MeasuredSpec, dof: int) -> None:
    """Each log has the columns of the map, and the map names ``dof`` joints:
    :class:`DataError` naming both files otherwise. Reads the logs' headers only."""
    if spec.columns.dof != dof:
        model = spec.urdf.name if spec.urdf is not None else "the system"
        raise DataError(f"{spec.source}: {model} has {dof} joint(s), but its columns name {spec.columns.dof} "
                        f"(q_1 .. q_{spec.columns.dof}) for the logs {', '.join(sorted({r.path.name for r in spec.recordings}))}")
    for path in dict.fromkeys(r.path for r in spec.recordings):
        header = read_frame(path, nrows=1).columns
        absent = [c for c in spec.columns.columns if c not in header]
        if absent:
            model = f" for {spec.urdf.name}'s {dof} joint(s)" if spec.urdf is not None else ""
            raise DataError(f"{path}: missing column(s) {', '.join(absent)} that {spec.source.name} maps{model}")


@functools.lru_cache(maxsize=4)
def _log(path: Path):
    return read_frame(path)


def samples(spec: MeasuredSpec, r: RecordingFile, filter: FilterSpec,
            filter_torque: bool = True) -> tuple[list[dict[str, np.ndarray]], str | None]:
    """Recording ``r``'s samples (:func:`~bench.core.recordings.read_log`), one part a segment of it
    (:func:`~bench.core.recordings.preprocess_segments`: a log with a gap is split there, never bridged):
    filtered and differentiated, or its rows as they are where the file says ``as_recorded``; and in words how
    its rows were split or moved in time (``None``: not at all)."""
    rows = where = None
    if r.column is not None:
        frame = _log(r.path)
        rows, where = frame[frame[r.column].astype(str) == r.name], f"{r.path} ({r.column} = {r.name})"
    rec = read_log(r.path, spec.columns, None if spec.as_recorded else filter, spec.time_unit, spec.degrees, rows, where,
                   spec.rate_hz)
    try:
        return preprocess_segments(rec, None if spec.as_recorded else filter, filter_torque=filter_torque)
    except DataError as exc:
        raise DataError(f"{where or r.path}: {exc}") from None


@functools.lru_cache(maxsize=16)
def _samples(spec: MeasuredSpec, trajectories: tuple[str, ...], filter: FilterSpec,
             filter_torque: bool) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    chosen = [r for r in spec.recordings if r.trajectory in trajectories]
    parts, moved = zip(*(samples(spec, r, filter, filter_torque) for r in chosen))
    return (joined(list(parts), [r.name for r in chosen], [r.trajectory for r in chosen]),
            {r.name: w for r, w in zip(chosen, moved) if w is not None})


class Measured:
    """A system whose data are the recordings its file declares (:attr:`measured`); mixed in before
    :class:`~bench.physics.system.System` (or a subclass that gives the model)."""

    simulated = False
    experiments = (INDIRECT,)
    splits = SPLITS
    measured: ClassVar[MeasuredSpec]

    @classmethod
    def source_files(cls) -> list[str]:
        files = dict.fromkeys([str(cls.measured.source), *(str(r.path) for r in cls.measured.recordings)])
        return [*files, *super().source_files()]

    def load(self, part: str, filter: FilterSpec | None = None, *, filter_torque: bool = True) -> Dataset:
        """The ``train`` or ``test`` part of the instance's split (:attr:`split`), or ``all``
        of it: whole trajectories, each sample with its recording, trajectory
        and time; the test part sealed (:mod:`bench.core.sealed`: its torques
        are read only to score). ``filter`` replaces the file's (a study of cut-offs);
        ``filter_torque=False`` leaves the torque unfiltered."""
        parts = self.measured.parts(self.split)
        if part not in parts:
            raise ValueError(f"part must be one of {', '.join(PARTS)}, got {part!r}")
        trajectories = parts[part]
        filter = self.measured.filter if filter is None else filter
        s, moved = _samples(self.measured, trajectories, filter, filter_torque)
        names = [r.name for r in self.measured.recordings if r.trajectory in trajectories]
        source = (f"{self.measured.source.name}:{part} of split {self.split} (trajectories {', '.join(trajectories)}; "
                  f"recordings {', '.join(names)}" + "".join(f"; {n} {w}" for n, w in moved.items()) + ")")
        meta = {"split": self.split} if self.measured.as_recorded else {
            "filter": dataclasses.asdict(filter), "split": self.split, **({"resampled": moved} if moved else {}),
            **({} if filter_torque else {"torque_filtered": False})}
        sign = s.get("sign_qd")
        data = Dataset(s["q"].copy(), s["qd"].copy(), s["qdd"].copy(), s["tau"].copy(), None, self.name, source, meta,
                       recording=s["recording"].copy(), sign_qd=None if sign is None else sign.copy(),
                       trajectory=s["trajectory"].copy(), time=s["time"].copy())
        return seal(data) if part == "test" else data

    def logged_torque(self, part: str) -> np.ndarray:
        """The torque of ``part`` as logged, at the samples :meth:`load` gives (the filter's q and qd, its grid and
        trim), before the low-pass; the logged rows as they are where the file says ``as_recorded``."""
        return self.load(part, filter_torque=False).tau

    def describe(self) -> dict:
        m = self.measured
        return {**super().describe(), "split": self.split, "test_trajectories": list(m.parts(self.split)["test"]),
                "recordings": {r.name: r.trajectory for r in m.recordings}, "samples": m.describe(),
                **({} if m.as_recorded else {"filter": dataclasses.asdict(m.filter)})}

    @classmethod
    def listing(cls) -> str:
        """What ``bench list`` says of the recordings."""
        m = cls.measured
        return (f"{len(m.recordings)} recordings of {len(m.trajectories)} trajectories, the default split testing on "
                f"{', '.join(m.test)}; time stamps: driven rollouts and the time shift")
