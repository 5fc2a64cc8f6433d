"""The suite's one command line: ``python -m bench COMMAND``.

A thin layer over the library: every command calls functions that are also
usable from Python. Bad input ends with a one-line ``error:`` message on
stderr and exit code 2; nothing is half-written. Every option has a help
text (``python -m bench COMMAND --help``).

Each command is one module with ``HELP``, ``add_arguments(parser)`` and
``main(args) -> exit code``: the user's commands here, in :data:`COMMANDS`,
and the project's studies under one of them, ``study`` (:mod:`bench.cli.study`,
the measurement scripts of :mod:`bench.studies`). What several
commands share (``--set``, ``--plugin``, ``--budget`` with ``--steps``) is in
:mod:`bench.cli.options`; the option values' types are in
:mod:`bench.core.arguments`.
"""

from __future__ import annotations

import argparse
import shlex
import sys

from bench.cli import convert, data, fit, index, leaderboard, listing, predict, rerun, residual, run, select, study, table
from bench.cli.options import Parser
from bench.core.errors import UserError
from bench.tools import robot_log
from bench.runner.job import CallFailed

EXIT_USAGE = 2

#: the commands, by name: the user's, then the project's studies under one verb
COMMANDS = {
    "list": listing, "run": run, "table": table, "data": data, "fit": fit, "predict": predict, "select": select, "residual": residual,
    "convert": convert, "robot-log": robot_log, "rerun": rerun, "leaderboard": leaderboard, "index": index,
    "study": study,
}


def build_parser() -> argparse.ArgumentParser:
    p = Parser(
        prog="python -m bench",
        description="Benchmark suite for learning Lagrangians of physical systems, symbolically and neurally.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=Parser)
    for name, module in COMMANDS.items():
        module.add_arguments(sub.add_parser(name, help=module.HELP))
    return p


def one_line(message: str) -> str:
    """``message`` with every character that is not printable (a line end, a control character that a file
    put in it) written as its escape, so that an error is one line whatever the file held."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    args.invocation = "python -m bench " + shlex.join(argv)
    try:
        return COMMANDS[args.command].main(args)
    except (UserError, OSError) as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    except CallFailed as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted; finished runs keep their records, rerun the same command to resume", file=sys.stderr)
        return 130
