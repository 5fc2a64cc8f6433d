"""``python -m bench leaderboard``: the leaderboard from a run folder and its commentary."""

from __future__ import annotations

from pathlib import Path

from bench.core.fileio import check_output
from bench.reporting.leaderboard import write_leaderboard

HELP = "write the leaderboard from a run folder's records and a commentary"


def add_arguments(parser) -> None:
    parser.add_argument("run_dir", type=Path, help="the run folder (default results/leaderboard)", nargs="?",
                        default=Path("results/leaderboard"))
    parser.add_argument("--commentary", type=Path, default=Path("results/commentary.md"),
                        help="markdown with a '## system, experiment' paragraph per table (default results/commentary.md)")
    parser.add_argument("--out", type=Path, default=Path("results/README.md"),
                        help="the leaderboard (default results/README.md)")


def main(args) -> int:
    check_output(args.out)
    missing = write_leaderboard(args.run_dir, args.commentary, args.out)
    for key in missing:
        print(f"no commentary for the table '{key}' (add '## {key}' to {args.commentary})")
    print(f"wrote {args.out}")
    return 0
