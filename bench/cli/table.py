"""``python -m bench table DIR``: a run folder's tables from its records."""

from __future__ import annotations

from pathlib import Path

from bench.cli.options import UsageError
from bench.reporting.tables import write_tables

HELP = "write DIR/tables.md from DIR's records and print it"


def add_arguments(parser) -> None:
    parser.add_argument("dir", type=Path, help="a run folder (with records/) or a folder of records")


def main(args) -> int:
    try:
        text = write_tables(args.dir)
    except FileNotFoundError as exc:
        raise UsageError(str(exc)) from None
    print(text)
    return 0
