"""The command line's parser, its usage error and its table of commands, apart
from the commands, so that ``python -m bench --help`` imports none of them: a
command's module is imported when that command is parsed."""

from __future__ import annotations

import argparse
import importlib
from typing import NamedTuple

from bench.core.errors import UserError


class UsageError(UserError):
    """A bad command line; reported in one line with exit code 2."""


class Parser(argparse.ArgumentParser):
    """Argument errors in one line (``--help`` still shows the usage)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class Command(NamedTuple):
    """A command (or a study): its module, with ``add_arguments(parser)`` and ``main(args)``, and its line in
    ``--help``."""

    module: str
    help: str

    def load(self):
        return importlib.import_module(self.module)


def add_commands(parser, commands: dict[str, Command], dest: str, argv: list[str] | None) -> None:
    """``commands`` as ``parser``'s subcommands in ``dest``: where ``argv`` is given, only the one it names (its
    first word) gets its module's arguments, the others their help line; every one where it is ``None``. A
    module whose ``NESTED`` is true has commands of its own: its ``add_arguments`` is given the rest of ``argv``."""
    sub = parser.add_subparsers(dest=dest, required=True, metavar="COMMAND" if dest == "command" else "NAME",
                                parser_class=Parser)
    named = argv[0] if argv else None
    for name, command in commands.items():
        child = sub.add_parser(name, help=command.help)
        if argv is None or name == named:
            module = command.load()
            if getattr(module, "NESTED", False):
                module.add_arguments(child, None if argv is None else argv[1:])
            else:
                module.add_arguments(child)
