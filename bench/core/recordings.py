"""Measured recordings: from a robot's log to samples in the suite's format.

A log is a CSV file (optionally compressed) with a time column, in seconds
(or in the units :func:`in_units` converts, checked by :func:`check_rate`),
and per joint a position, a velocity and a torque column; a
:class:`ColumnMap` names them (``time=t,q_1=pos1,qd_1=vel1,tau_1=eff1,...``).
Robots rarely log accelerations, and their clocks and encoders are not
clean, so :func:`preprocess` turns a recording into samples in four steps:

1. the rows as they are where they lie a uniform step apart and ``dt`` is
   not given (the default); else linear interpolation of q, qd and tau onto
   a uniform grid of ``dt`` (or of the log's median step, for rows whose
   steps vary), which :func:`resampling` states in words for the record;
2. a zero-phase Butterworth low-pass (``order``, run forwards and backwards,
   cut-off ``cutoff_hz``) applied alike to q, qd and tau, so that no signal
   is delayed against another and both sides of ``tau = g(L)`` see one filter;
3. ``qdd`` as the central difference of the filtered velocity;
4. ``trim_s`` cut from both ends (the filter's start-up), then every
   ``decimate``-th sample kept, each with its time since the recording's
   first row.

Beside them it gives ``sign_qd``, the sign of the filtered velocity put
through the same low-pass at the full rate (parallel filtering,
:attr:`bench.core.data.Dataset.sign_qd`): the filter rounds Coulomb
friction's jump in the torque over its span, and the same rounding in the
friction column keeps a fitted viscous coefficient from absorbing it. The
rest of a model's columns are smooth functions of the filtered state, which
the low-pass passes as they are.

A log with a gap (a step of :data:`GAP_STEPS` times its median step or more:
rows lost, a logger paused) is split there into segments (:func:`segments`),
each filtered on its own and labelled a recording of its own
(``NAME/1``, ``NAME/2``, ...) of the same trajectory: a gap is never bridged
by interpolation, a filter or a derivative. A segment too short for the
filter is left out; :func:`preprocess_segments` says in words how many
segments and samples were kept, which the data's source carries.

The defaults (:data:`DEFAULT_FILTER`) keep the log's own step and every
sample, with the cut-off measured for the DFKI double pendulum (``python -m
bench study dfki-filter``); a robot of its own wants its own cut-off, chosen
the same way. Resampling happens where ``dt`` asks for it or where the rows'
steps vary (item 1), and :func:`resampling` says so in words, which a
dataset's source and ``meta["resampled"]`` carry and ``fit`` prints.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.core.data import DataError
from bench.core.csv_format import numeric_column, read_frame
from bench.core.errors import ConfigError

#: the fewest rows a recording may have
MIN_ROWS = 16
#: a step between two rows this many times a log's median step or longer is a gap: the log is split there
GAP_STEPS = 5.0
#: the most samples a recording may span on the uniform grid (5.5 hours at 2 ms)
MAX_GRID = 10_000_000
#: seconds per unit of a log's time column (``convert --time-unit``)
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
#: the longest median step between a robot log's rows, s: slower is a time column in other units
MAX_MEDIAN_STEP = 0.5
#: how far a log's stated rate may lie from the one its positions and velocities imply (:func:`check_stated_rate`)
RATE_TOLERANCE = 0.05


@dataclass(frozen=True)
class FilterSpec:
    """How a recording becomes samples; see the module docstring."""

    #: the step to resample to, s; ``None`` keeps the log's own
    dt: float | None = None
    cutoff_hz: float = 6.0
    order: int = 4
    trim_s: float = 0.25
    decimate: int = 1

    def __post_init__(self):
        def number(name: str) -> float:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise ConfigError(f"{name} must be a finite number, got {value!r}")
            return float(value)

        for name in ("order", "decimate"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
                raise ConfigError(f"{name} must be a whole number >= 1, got {value!r}")
        if self.dt is not None and not number("dt") > 0:
            raise ConfigError(f"dt must be positive, got {self.dt}")
        nyquist = math.inf if self.dt is None else 0.5 / self.dt
        if not 0 < number("cutoff_hz") < nyquist:
            bound = "be positive" if self.dt is None else f"lie in (0, {nyquist:g}) for dt = {self.dt:g}"
            raise ConfigError(f"cutoff_hz must {bound}, got {self.cutoff_hz}")
        if not number("trim_s") >= 0:
            raise ConfigError(f"trim_s must be >= 0, got {self.trim_s}")

    def describe(self) -> str:
        step = "at the log's own step" if self.dt is None else f"resampled to {self.dt * 1000:g} ms"
        return (f"{step}, zero-phase Butterworth low-pass of order {self.order} at "
                f"{self.cutoff_hz:g} Hz on q, qd and tau, qdd by central differences of qd, {self.trim_s:g} s trimmed "
                f"from each end, " + ("every sample kept" if self.decimate == 1 else
                                      f"one sample in {self.decimate} kept"))


DEFAULT_FILTER = FilterSpec()


@dataclass(frozen=True)
class Recording:
    """One recording: ``time`` of shape ``(n,)``; ``q``, ``qd``, ``tau`` of shape ``(n, dof)``."""

    time: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    tau: np.ndarray
    #: the logged accelerations, where the log holds them (``ColumnMap.qdd``)
    qdd: np.ndarray | None = None


@dataclass(frozen=True)
class ColumnMap:
    """Which columns of a log hold time and each joint's q, qd and tau (and
    qdd, where the log holds accelerations). ``time`` is ``None`` for a log
    without a time column, whose rate is stated instead (:func:`read_log`)."""

    time: str | None
    q: tuple[str, ...]
    qd: tuple[str, ...]
    tau: tuple[str, ...]
    qdd: tuple[str, ...] = ()

    @classmethod
    def parse(cls, text: str, source: str = "--columns") -> "ColumnMap":
        """``"time=t,q_1=pos1,qd_1=vel1,tau_1=eff1,..."``: every joint from 1 to
        n needs q, qd and tau (and qdd on every joint or none); a clear
        :class:`ConfigError` otherwise."""
        roles: dict[str, str] = {}
        for item in (part.strip() for part in text.split(",") if part.strip()):
            role, sep, column = item.partition("=")
            role, column = role.strip(), column.strip()
            if not sep or not column:
                raise ConfigError(f"{source}: expected ROLE=COLUMN, got {item!r}")
            if role in roles:
                raise ConfigError(f"{source}: {role} is given twice")
            roles[role] = column
        joints = sorted({int(r.rsplit("_", 1)[1]) for r in roles if r != "time" and r.rsplit("_", 1)[-1].isdigit()})
        unknown = [r for r in roles if r != "time" and not (r.rsplit("_", 1)[0] in ("q", "qd", "qdd", "tau")
                                                              and r.rsplit("_", 1)[-1].isdigit())]
        if unknown:
            raise ConfigError(f"{source}: unknown role(s) {', '.join(unknown)}; use time, q_i, qd_i and tau_i (and qdd_i)")
        dof = max(joints, default=0)
        if dof == 0:
            raise ConfigError(f"{source}: name the columns of q_1, qd_1 and tau_1 at least")
        missing = [f"{k}_{i}" for i in range(1, dof + 1) for k in ("q", "qd", "tau") if f"{k}_{i}" not in roles]
        if missing:
            raise ConfigError(f"{source}: missing {', '.join(missing)} (every joint from 1 to {dof} needs q, qd and tau)")
        given = [i for i in range(1, dof + 1) if f"qdd_{i}" in roles]
        if given and len(given) != dof:
            raise ConfigError(f"{source}: qdd is given for joint(s) {', '.join(map(str, given))} only; give it for every "
                              f"joint from 1 to {dof} or for none")
        kinds = ("q", "qd", "tau", "qdd") if given else ("q", "qd", "tau")
        return cls(roles.get("time"), *(tuple(roles[f"{k}_{i}"] for i in range(1, dof + 1)) for k in kinds))

    @property
    def dof(self) -> int:
        return len(self.q)

    @property
    def columns(self) -> tuple[str, ...]:
        return (*((self.time,) if self.time else ()), *self.q, *self.qd, *self.tau, *self.qdd)

    def take(self, frame, path: Path | str = "recording", rate_hz: float | None = None) -> Recording:
        """The recording in ``frame`` (a DataFrame), checked: the columns
        present, numeric and finite, and time strictly increasing; without a
        time column, the rows ``1 / rate_hz`` apart."""
        missing = [c for c in self.columns if c not in frame.columns]
        if missing:
            raise DataError(f"{path}: missing column(s) {', '.join(missing)}")
        if len(frame) < MIN_ROWS:
            raise DataError(f"{path}: {len(frame)} rows are too few for a trajectory (at least {MIN_ROWS})")
        if self.time is None:
            if rate_hz is None:
                raise DataError(f"{path}: the log has no time column (time=COLUMN) and no rate is stated "
                                f"(--rate HZ, or rate_hz in a measured system's file)")
            time = np.arange(len(frame)) / float(rate_hz)
        else:
            time = numeric_column(frame, self.time, path)
        steps = np.diff(time)
        if np.any(steps <= 0):
            row = int(np.flatnonzero(steps <= 0)[0]) + 2
            raise DataError(f"{path}: column {self.time} does not increase at data row {row}")
        q, qd, tau = (np.stack([numeric_column(frame, c, path) for c in cols], axis=1) for cols in (self.q, self.qd, self.tau))
        qdd = np.stack([numeric_column(frame, c, path) for c in self.qdd], axis=1) if self.qdd else None
        return Recording(time, q, qd, tau, qdd)


def in_units(recording: Recording, time_unit: str = "s", degrees: bool = False) -> Recording:
    """``recording`` with its time in seconds (from ``time_unit``, :data:`TIME_UNITS`)
    and, with ``degrees``, its q and qd from degrees to radians."""
    angle = math.pi / 180 if degrees else 1.0
    qdd = None if recording.qdd is None else recording.qdd * angle
    return Recording(recording.time * TIME_UNITS[time_unit], recording.q * angle, recording.qd * angle, recording.tau, qdd)


def check_rate(recording: Recording, spec: FilterSpec, path: Path | str, column: str) -> None:
    """A :class:`DataError` naming the file and its time ``column`` where the
    rows are further apart than a robot logs (a median step above
    :data:`MAX_MEDIAN_STEP`), or where their rate's Nyquist frequency is at or
    below the filter's cut-off: both are a time column in other units than seconds."""
    step = float(np.median(np.diff(recording.time)))
    if step > MAX_MEDIAN_STEP:
        raise DataError(f"{path}: column {column}: rows a median {step:.4g} s apart, slower than a robot logs: is the "
                        f"time in milliseconds? (--time-unit ms, or us)")
    nyquist = 0.5 / step
    if spec.cutoff_hz >= nyquist:
        raise DataError(f"{path}: column {column}: rows a median {step:.4g} s apart have a Nyquist frequency of "
                        f"{nyquist:.4g} Hz, not above the cut-off of {spec.cutoff_hz:g} Hz: is the time in seconds? "
                        f"(--time-unit ms or us; or a lower --cutoff-hz)")


def beyond_a_turn(recording: Recording) -> list[tuple[int, float, float]]:
    """The joints (0-based) whose q leaves ±2π, with the range seen: angles
    that only make sense in degrees, where the joint turns (a log names no
    joint kinds, so a prismatic joint past 6.28 m would be named too; it is a
    warning, not an error)."""
    out = []
    for j in range(recording.q.shape[1]):
        lo, hi = float(np.min(recording.q[:, j])), float(np.max(recording.q[:, j]))
        if max(abs(lo), abs(hi)) > 2 * math.pi:
            out.append((j, lo, hi))
    return out


def read_recording(path: str | Path, columns: ColumnMap, rate_hz: float | None = None) -> Recording:
    """A log file's recording, checked (:meth:`ColumnMap.take`); :class:`DataError` naming the file otherwise."""
    path = Path(path)
    return columns.take(read_frame(path), path, rate_hz)


def implied_step(recording: Recording) -> float | None:
    """The interval between rows that best matches the differentiated positions
    to the logged velocities: ``dt`` minimising ``|Δq - dt (qd_k + qd_k+1)/2|²``
    over every joint and row (least squares); ``None`` where the velocities are
    all but zero (a log at rest says nothing of its rate)."""
    dq = np.diff(recording.q, axis=0)
    v = 0.5 * (recording.qd[1:] + recording.qd[:-1])
    vv = float(np.sum(v * v))
    if not vv > 1e-12 * max(len(v), 1):
        return None
    return float(np.sum(dq * v) / vv)


def check_stated_rate(recording: Recording, rate_hz: float, path: Path | str) -> None:
    """A :class:`DataError` naming the file where a log's stated rate lies more
    than :data:`RATE_TOLERANCE` from the one its positions and velocities
    imply (:func:`implied_step`), with the interval the data suggest."""
    step = implied_step(recording)
    if step is None or not step > 0:
        return
    stated = 1.0 / rate_hz
    if abs(stated - step) > RATE_TOLERANCE * step:
        raise DataError(f"{path}: the stated rate of {rate_hz:g} Hz puts rows {stated * 1000:.4g} ms apart, but its "
                        f"positions and velocities say {step * 1000:.4g} ms ({1.0 / step:.4g} Hz)")


def read_log(path: str | Path, columns: ColumnMap, spec: FilterSpec | None, time_unit: str = "s",
             degrees: bool = False, rows=None, where: str | None = None, rate_hz: float | None = None) -> Recording:
    """A robot log's recording as the suite takes it: checked
    (:meth:`ColumnMap.take`), in seconds and radians (:func:`in_units`), and
    its rate checked against ``spec``'s filter (:func:`check_rate`; ``None``:
    its rows are the samples, no filter). ``rows`` (a DataFrame) are the
    log's rows of this recording where the log holds several, ``where`` how
    an error names them. A log without a time column has its rows
    ``1 / rate_hz`` apart, the rate checked against its velocities
    (:func:`check_stated_rate`); a log with one takes no stated rate."""
    where = where or path
    if rate_hz is not None and columns.time is not None:
        raise DataError(f"{where}: the log has a time column ({columns.time}) and a stated rate of {rate_hz:g} Hz: "
                        f"give one of them")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise DataError(f"{where}: the stated rate must be a positive number of Hz, got {rate_hz!r}")
    raw = read_recording(path, columns, rate_hz) if rows is None else columns.take(rows, where, rate_hz)
    recording = in_units(raw, time_unit if columns.time is not None else "s", degrees)
    if rate_hz is not None:
        check_stated_rate(recording, rate_hz, where)
    if spec is not None:
        check_rate(recording, spec, where, columns.time or f"(rows at {rate_hz:g} Hz)")
    return recording


#: how far a row's step may lie from the median step, as a fraction of it, for the rows to count as uniform
UNIFORM_STEP = 0.01


def _grid(t: np.ndarray, spec: FilterSpec) -> tuple[np.ndarray, float, str | None]:
    """The times the samples are taken at, their step, and :func:`resampling`'s words."""
    steps = np.diff(t)
    own = float(np.median(steps))
    uniform = bool(np.max(np.abs(steps - own)) <= UNIFORM_STEP * own)
    near = spec.dt is None or abs(spec.dt - own) <= UNIFORM_STEP * own
    if near and uniform:
        return t, own, None
    step = own if spec.dt is None else spec.dt
    span = float(t[-1] - t[0])
    if span / step > MAX_GRID:
        raise DataError(f"the recording spans {span:.6g} s: at a step of {step:g} s that is more than "
                        f"{MAX_GRID:,} samples (is the time column in seconds?)")
    if near:
        words = (f"rows {float(steps.min()) * 1000:.4g} to {float(steps.max()) * 1000:.4g} ms apart interpolated "
                 f"onto a uniform {step * 1000:.4g} ms")
    else:
        words = f"resampled from the log's {own * 1000:.4g} ms (median step) to {spec.dt * 1000:g} ms"
    return np.arange(t[0], t[-1], step), step, words


def resampling(recording: Recording, spec: FilterSpec) -> str | None:
    """In words, how :func:`preprocess` moves ``recording``'s rows in time:
    ``None`` where it keeps them as they are (their steps uniform to
    :data:`UNIFORM_STEP`, and ``dt`` not given or equal to their step)."""
    return _grid(recording.time, spec)[2]


class TooShort(DataError):
    """A recording (or a segment of one) too short for the filter."""


def segments(recording: Recording) -> list[Recording]:
    """``recording`` split at each gap: a step of :data:`GAP_STEPS` times its median step or longer."""
    steps = np.diff(recording.time)
    if not len(steps):
        return [recording]
    cuts = np.flatnonzero(steps >= GAP_STEPS * float(np.median(steps))) + 1
    bounds = [0, *cuts.tolist(), len(recording.time)]
    qdd = recording.qdd
    return [Recording(recording.time[a:b], recording.q[a:b], recording.qd[a:b], recording.tau[a:b],
                      None if qdd is None else qdd[a:b]) for a, b in zip(bounds, bounds[1:])]


def preprocess_segments(recording: Recording, spec: FilterSpec | None = DEFAULT_FILTER, *,
                        filter_torque: bool = True) -> tuple[list[dict[str, np.ndarray]], str | None]:
    """:func:`preprocess` of each of ``recording``'s :func:`segments` (``spec`` ``None``: their rows as they are,
    a log of samples as recorded), their times counted from the recording's first row; and in words how its rows
    were split and moved in time (:func:`resampling` of each segment kept; ``None``: neither). A segment too
    short for the filter is left out and counted; a :class:`DataError` where every one is."""
    parts = segments(recording)
    origin = float(recording.time[0])

    def one(part: Recording) -> dict[str, np.ndarray]:
        if len(part.time) < MIN_ROWS:
            raise TooShort(f"a segment of {len(part.time)} row(s)")
        if spec is None:
            return {"q": part.q, "qd": part.qd, "qdd": part.qdd, "tau": part.tau, "time": part.time - origin}
        return preprocess(part, spec, filter_torque=filter_torque, origin=origin)

    if len(parts) == 1:
        return [one(recording)], None if spec is None else resampling(recording, spec)
    kept, moved, short = [], [], []
    for part in parts:
        try:
            kept.append(one(part))
        except TooShort:
            short.append(len(part.time))
            continue
        moved.append(None if spec is None else resampling(part, spec))
    if not kept:
        raise DataError(f"its {len(parts) - 1} gap(s) split it into {len(parts)} segments, each too short for the "
                        f"filter")
    words = (f"split at {len(parts) - 1} gap(s) of {GAP_STEPS:g} steps or more into {len(parts)} segments, each "
             f"filtered on its own and none bridged: {len(kept)} kept, {sum(len(p['q']) for p in kept):,} samples"
             + (f"; {len(short)} too short for the filter left out ({sum(short):,} rows)" if short else ""))
    return kept, "; ".join([words, *dict.fromkeys(w for w in moved if w)])


def preprocess(recording: Recording, spec: FilterSpec = DEFAULT_FILTER, *, filter_torque: bool = True,
               origin: float | None = None) -> dict[str, np.ndarray]:
    """Samples ``q, qd, qdd, tau`` and ``sign_qd`` (each ``(n, dof)``) of one
    recording; see the module docstring for the steps. ``filter_torque=False``
    keeps the measured torque unfiltered (on the same grid), for judging
    a filter; ``sign_qd`` is then ``sign(qd)``. Times are counted from ``origin``
    (default: the recording's first row). A recording with gaps is split by
    :func:`preprocess_segments`, not here."""
    from scipy.signal import butter, sosfiltfilt  # 0.3 s to import: only conversions need it

    t = recording.time
    grid, dt, moved = _grid(t, spec)
    if not spec.cutoff_hz < 0.5 / dt:
        raise DataError(f"a cut-off of {spec.cutoff_hz:g} Hz is not below the Nyquist frequency of rows "
                        f"{dt * 1000:.4g} ms apart ({0.5 / dt:.4g} Hz)")
    trim = int(round(spec.trim_s / dt))
    sos = butter(spec.order, spec.cutoff_hz, fs=1.0 / dt, output="sos")
    padding = 3 * (2 * len(sos) + 1)  # what sosfiltfilt extends each end by
    if len(grid) <= max(2 * trim + 2, padding):
        raise TooShort(f"a recording of {t[-1] - t[0]:.3g} s is too short for the filter "
                        f"(twice the trim of {spec.trim_s:g} s, and at least {padding} steps of {dt:.4g} s)")

    def resampled(values: np.ndarray) -> np.ndarray:
        if moved is None:
            return np.array(values, dtype=float)
        return np.stack([np.interp(grid, t, values[:, i]) for i in range(values.shape[1])], axis=1)

    q = sosfiltfilt(sos, resampled(recording.q), axis=0)
    qd = sosfiltfilt(sos, resampled(recording.qd), axis=0)
    tau = resampled(recording.tau)
    sign_qd = np.sign(qd)
    if filter_torque:
        tau = sosfiltfilt(sos, tau, axis=0)
        sign_qd = sosfiltfilt(sos, sign_qd, axis=0)
    qdd = np.gradient(qd, grid, axis=0) if moved is None else np.gradient(qd, dt, axis=0)
    keep = slice(trim, len(grid) - trim, spec.decimate)
    return {"q": q[keep], "qd": qd[keep], "qdd": qdd[keep], "tau": tau[keep], "sign_qd": sign_qd[keep],
            "time": grid[keep] - (t[0] if origin is None else origin)}


def joined(recordings: list[list[dict[str, np.ndarray]]], names: list[str],
           trajectories: list[str] | None = None) -> dict[str, np.ndarray]:
    """The samples of several recordings one after another, each given as its segments
    (:func:`preprocess_segments`), with ``recording``: each sample's recording name from ``names``, ``NAME/k``
    for the ``k``-th segment of a recording split at a gap; and, given ``trajectories`` (one per recording),
    ``trajectory``: the trajectory each sample's recording follows, its segments' too."""
    parts, labels, followed = [], [], []
    for pieces, name, trajectory in zip(recordings, names, trajectories or names):
        parts += pieces
        labels += [name] if len(pieces) == 1 else [f"{name}/{k + 1}" for k in range(len(pieces))]
        followed += [trajectory] * len(pieces)
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    out["recording"] = np.concatenate([np.full(len(p["q"]), n) for n, p in zip(labels, parts)])
    if trajectories is not None:
        out["trajectory"] = np.concatenate([np.full(len(p["q"]), n) for n, p in zip(followed, parts)])
    return out
