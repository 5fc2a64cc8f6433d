"""The suite's one command line: ``python -m bench COMMAND``.

A thin layer over the library: every command calls functions that are also
usable from Python. Bad input ends with a one-line ``error:`` message on
stderr and exit code 2; nothing is half-written. Every option has a help
text (``python -m bench COMMAND --help``).

Each command is one module with ``add_arguments(parser)`` and
``main(args) -> exit code``, named with its line of help in :data:`COMMANDS`:
the user's commands, then the project's studies under one of them, ``study``
(:mod:`bench.cli.study`, the measurement scripts of :mod:`bench.studies`). A
command's module is imported when that command is parsed
(:func:`bench.cli.parser.add_commands`), so ``--help`` imports none of them.
What several commands share (``--set``, ``--plugin``, ``--budget`` with
``--steps``) is in :mod:`bench.cli.options`; the option values' types are in
:mod:`bench.core.arguments`.
"""

from __future__ import annotations

import argparse
import shlex
import sys

from bench.cli.parser import Command, Parser, add_commands
from bench.core.errors import CallFailed, UserError

EXIT_USAGE = 2

#: the commands, by name: the user's, then the project's studies under one verb
COMMANDS = {
    "list": Command("bench.cli.listing", "list systems and methods, with availability"),
    "run": Command("bench.cli.run", "run a matrix of systems x methods x experiments x seeds and write tables"),
    "table": Command("bench.cli.table", "write DIR/tables.md from DIR's records and print it"),
    "data": Command("bench.cli.data", "generate data in the suite's CSV format"),
    "fit": Command("bench.cli.fit", "one run on your own CSV data or on generated data; prints a one-line summary"),
    "predict": Command("bench.cli.predict",
                       "a saved model's torques on a log in the suite's format; prints their MSE where the log has "
                       "torques"),
    "select": Command("bench.cli.select",
                      "choose a model of a measured arm by validation on its training data; write it, and a page of "
                      "every candidate"),
    "residual": Command("bench.cli.residual",
                        "fit, trace the torque residual to missing effects, add them, refit; report the error before"
                        " and after"),
    "convert": Command("bench.cli.convert",
                       "turn a robot's log into the suite's CSV format: resample, low-pass, differentiate"),
    "robot-log": Command("bench.tools.robot_log",
                         "write a simulated robot's logs (time, positions, velocities, torques) for bench convert "
                         "--columns"),
    "rerun": Command("bench.cli.rerun",
                     "replay a recorded run with the work it did and compare its train and test MSE"),
    "leaderboard": Command("bench.cli.leaderboard",
                           "write a run folder's leaderboard: its tables and the methods' ranks across them"),
    "index": Command("bench.cli.index",
                     "write results/index.md from results/manifest.toml and the records, and refresh the pages' "
                     "marked figures"),
    "study": Command("bench.cli.study",
                     "the project's studies: measurements that write its published pages (python -m bench study "
                     "--help lists them)"),
}


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The command line's parser: every command's, or where ``argv`` is given only the one it names."""
    p = Parser(
        prog="python -m bench",
        description="Benchmark suite for learning Lagrangians of physical systems, symbolically and neurally.",
    )
    add_commands(p, COMMANDS, "command", argv)
    return p


def one_line(message: str) -> str:
    """``message`` with every character that is not printable (a line end, a control character that a file
    put in it) written as its escape, so that an error is one line whatever the file held."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(argv).parse_args(argv)
    args.invocation = "python -m bench " + shlex.join(argv)
    try:
        return COMMANDS[args.command].load().main(args)
    except (UserError, OSError) as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_USAGE
    except CallFailed as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted; finished runs keep their records, rerun the same command to resume", file=sys.stderr)
        return 130
