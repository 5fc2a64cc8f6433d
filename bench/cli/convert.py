"""``python -m bench convert``: a robot's logs in the suite's CSV format,
resampled, low-passed and differentiated (:mod:`bench.core.recordings`)."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from bench.cli.parser import UsageError
from bench.core.arguments import nonnegative, positive, positive_int
from bench.core.data import Dataset
from bench.core.csv_format import write_csv
from bench.core.fileio import check_output, file_digest, settings_path, write_json
from bench.core.recordings import (DEFAULT_FILTER, TIME_UNITS, ColumnMap, FilterSpec, Recording, beyond_a_turn, joined,
                                   preprocess_segments, read_log)
from systems.dfki_double_pendulum import layout_of


def add_arguments(cv) -> None:
    layout = cv.add_mutually_exclusive_group(required=True)
    layout.add_argument("--format", choices=["dfki"], help="a DFKI double pendulum recording, in either of the lab's layouts")
    layout.add_argument("--columns", metavar="time=T,q_1=C,qd_1=C,tau_1=C,...",
                        help="any log: which columns hold the time (s) and each joint's q, qd and tau")
    cv.add_argument("raw", type=Path, nargs="+",
                    help="the log(s) (CSV, may be gzipped); each is one recording, named in the output's "
                         "trajectory column by its file name")
    named = cv.add_mutually_exclusive_group()
    named.add_argument("--distinct", action="store_true",
                       help="every log follows an excitation trajectory of its own (instead of --trajectory)")
    named.add_argument("--trajectory", nargs="+", default=None, metavar="NAME",
                    help="the excitation trajectory the logs follow: one name for all, or one per log in order "
                         "(logs that repeat a trajectory share its name, so that the residual loop never tests on a "
                         "repeat of what it fitted); with --columns and two or more logs, this or --distinct is "
                         "needed; DFKI recordings are each a trajectory of their own")
    cv.add_argument("--out", type=Path, required=True, help="CSV file to write")
    cv.add_argument("--dt", type=positive, default=DEFAULT_FILTER.dt,
                    help="resample the log to this uniform time step, s (default: none, the log's own step is kept; "
                         "rows whose steps vary are interpolated onto their median step, and the output says so)")
    cv.add_argument("--cutoff-hz", type=positive, default=DEFAULT_FILTER.cutoff_hz,
                    help=f"the zero-phase Butterworth low-pass's cut-off on q, qd and tau, Hz "
                         f"(default {DEFAULT_FILTER.cutoff_hz:g}, measured for the DFKI robot)")
    cv.add_argument("--order", type=positive_int, default=DEFAULT_FILTER.order,
                    help=f"the low-pass's order (default {DEFAULT_FILTER.order})")
    cv.add_argument("--trim", type=nonnegative, default=DEFAULT_FILTER.trim_s,
                    help=f"seconds cut from each end, the filter's start-up (default {DEFAULT_FILTER.trim_s:g})")
    cv.add_argument("--decimate", type=positive_int, default=DEFAULT_FILTER.decimate,
                    help=f"keep every N-th sample (default {DEFAULT_FILTER.decimate})")
    cv.add_argument("--rate", type=positive, default=None, metavar="HZ",
                    help="the rate of a log without a time column, Hz (leave time= out of --columns): its rows are "
                         "1/HZ s apart; a rate more than 5 %% off the one its positions and velocities imply stops the "
                         "conversion with a line giving the interval they suggest")
    cv.add_argument("--time-unit", choices=sorted(TIME_UNITS), default="s",
                    help="the unit of the log's time column (default s); rows further apart than a robot logs, or "
                         "too slow a rate for the cut-off, stop the conversion with a line naming the column")
    cv.add_argument("--degrees", action="store_true",
                    help="the log's q and qd are in degrees and degrees/s: convert them to radians (a q beyond ±2π "
                         "without it gives a warning)")


def main(args) -> int:
    check_output(args.out)
    spec = FilterSpec(dt=args.dt, cutoff_hz=args.cutoff_hz, order=args.order, trim_s=args.trim, decimate=args.decimate)
    names = [recording_name(p) for p in args.raw]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise UsageError(f"two logs would be the same recording {repeated[0]!r}: give files with distinct names")
    # one column map for every log, so they share their joints; each is read and checked before anything is written
    columns = ColumnMap.parse(args.columns) if args.columns else None
    if columns is not None and columns.time is None and args.rate is None:
        raise UsageError("--columns names no time column: name it (time=COLUMN) or give the log's rate (--rate HZ)")
    if args.rate is not None and (columns is None or columns.time is not None):
        raise UsageError("--rate is the rate of a log without a time column: leave time= out of --columns, or --rate out")
    if columns is not None and columns.qdd:
        raise UsageError("--columns: convert differentiates the filtered velocity and would not use logged qdd_i "
                         "columns; leave them out (a measured system's file with as_recorded = true takes logged "
                         "accelerations as they are)")
    trajectories = trajectory_names(args.trajectory, names, need=columns is not None and not args.distinct)
    system = None if columns else "dfki_double_pendulum"
    recordings, warnings = zip(*(log_with_warnings(path, columns, spec, args.time_unit, args.degrees, args.rate)
                                 for path in args.raw))
    parts, moved = zip(*(preprocess_segments(r, spec) for r in recordings))  # a log with a gap: its segments
    split = any(len(pieces) > 1 for pieces in parts)  # each segment a recording of its own, of its log's trajectory
    moved = {n: words for n, words in zip(names, moved) if words}
    s = joined(list(parts), names, trajectories if trajectories is not None or not split else names)
    for line in (w for group in warnings for w in group):  # once every log is read: an error is the one line
        print(line, file=sys.stderr)
    source = ", ".join(map(str, args.raw))
    write_csv(Dataset(s["q"], s["qd"], s["qdd"], s["tau"], None, system, source, recording=s["recording"],
                      sign_qd=s["sign_qd"], trajectory=s.get("trajectory"), time=s["time"]), args.out)
    write_json(settings_path(args.out), {
        "logs": {str(p): file_digest(p) for p in args.raw},
        "columns": args.columns, "format": args.format, "time_unit": args.time_unit, "degrees": args.degrees,
        "rate_hz": args.rate,
        "filter": dataclasses.asdict(spec), "resampled": moved, "trajectories": trajectories,
        "command": args.invocation,
    })
    print(f"wrote {len(s['q'])} samples of {s['q'].shape[1]} joint(s) from {len(parts)} recording(s) to {args.out} "
          f"({spec.describe()}); its settings to {settings_path(args.out)}")
    for name, words in moved.items():
        print(f"  recording {name}: {words}")
    return 0


def log_with_warnings(path: Path, columns: ColumnMap | None, spec: FilterSpec, time_unit: str,
                      degrees: bool, rate_hz: float | None = None) -> tuple[Recording, list[str]]:
    """One log as the suite takes it (:func:`~bench.core.recordings.read_log`;
    ``columns`` ``None``: a DFKI recording in either of the lab's layouts), and
    its warnings: one naming degrees for each q that leaves ±2π where
    ``degrees`` was not given."""
    columns = columns or layout_of(path)
    recording = read_log(path, columns, spec, time_unit, degrees, rate_hz=rate_hz)
    warnings = []
    for j, lo, hi in ([] if degrees else beyond_a_turn(recording)):
        name = columns.q[j]
        warnings.append(f"warning: {path}: column {name} (q_{j + 1}) spans {lo:.4g} to {hi:.4g}, beyond ±2π: if the "
                        f"log is in degrees, give --degrees to convert q and qd to radians")
    return recording, warnings


def trajectory_names(given: list[str] | None, recordings: list[str], need: bool) -> list[str] | None:
    """The trajectory each recording follows: one name for all, or one per
    recording; ``None`` (each recording a trajectory of its own) where none is
    given and none is ``need`` ed, or there is one recording."""
    if given is None:
        if need and len(recordings) > 1:
            raise UsageError(f"name the excitation trajectory that the logs {', '.join(recordings)} follow "
                             f"(--trajectory NAME, or one name per log; --distinct where each follows its own): logs "
                             f"that repeat one trajectory are held out together, since a repeat of a fitted trajectory "
                             f"is no test of the fit")
        return None
    if len(given) == 1:
        return given * len(recordings)
    if len(given) != len(recordings):
        raise UsageError(f"--trajectory gives {len(given)} names for {len(recordings)} logs ({', '.join(recordings)}): "
                         f"give one for all, or one per log")
    return list(given)


def recording_name(path: Path) -> str:
    """A log's recording name: its file name without the .csv and compression suffixes."""
    name = path.name
    for suffix in (".gz", ".bz2", ".xz", ".zip", ".csv"):
        name = name.removesuffix(suffix)
    return name or path.name
