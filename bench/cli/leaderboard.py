"""``python -m bench leaderboard``: a run folder's leaderboard: its tables,
with their plots and the methods' ranks across them, and, where
``--commentary`` names one, a commentary's paragraphs among them."""

from __future__ import annotations

from pathlib import Path

from bench.core.fileio import check_output
from bench.reporting.leaderboard import write_leaderboard


def add_arguments(parser) -> None:
    parser.add_argument("run_dir", type=Path, help="the run folder, with records/")
    parser.add_argument("--commentary", type=Path, default=None,
                        help="markdown with a '## system, experiment' paragraph per table and an optional "
                             "'## Introduction', put among the tables (default: none)")
    parser.add_argument("--out", type=Path, default=None, help="the leaderboard (default RUN_DIR/leaderboard.md)")


def main(args) -> int:
    out = args.out if args.out is not None else args.run_dir / "leaderboard.md"
    check_output(out)
    missing = write_leaderboard(args.run_dir, args.commentary, out)
    if args.commentary is not None:
        for key in missing:
            print(f"no commentary for the table '{key}' (add '## {key}' to {args.commentary})")
    print(f"wrote {out}")
    return 0
