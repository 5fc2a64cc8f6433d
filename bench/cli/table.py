"""``python -m bench table DIR``: a run folder's tables from its records."""

from __future__ import annotations

from pathlib import Path

from bench.cli.parser import UsageError
from bench.reporting.per_joint import write_per_joint
from bench.reporting.tables import write_tables


def add_arguments(parser) -> None:
    parser.add_argument("dir", type=Path, help="a run folder (with records/) or a folder of records")
    parser.add_argument("--per-joint", action="store_true",
                        help="also write DIR/per_joint.md, the test error per joint and per test trajectory (MSE and "
                             "nMSE, against the logged and the filtered torque, beside the filter's noise floor) of "
                             "runs on measured systems, and print it")


def main(args) -> int:
    try:
        text = write_tables(args.dir)
        if args.per_joint:
            text = write_per_joint(args.dir)
    except FileNotFoundError as exc:
        raise UsageError(str(exc)) from None
    print(text)
    return 0
