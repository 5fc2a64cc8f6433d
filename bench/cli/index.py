"""``python -m bench index``: results/index.md from results/manifest.toml and
the records, and every page's marked figure rewritten from them
(:mod:`bench.reporting.index`)."""

from __future__ import annotations

from pathlib import Path

from bench.reporting.index import write_index


def add_arguments(parser) -> None:
    parser.add_argument("root", type=Path, nargs="?", default=Path("results"),
                        help="the results folder, with its manifest.toml (default results)")


def main(args) -> int:
    index, changed = write_index(args.root)
    for page in changed:
        print(f"updated the figures of {page}")
    print(f"wrote {index}")
    return 0
