"""``python -m bench ARGS`` run in the test's own process.

A command in a fresh interpreter pays for importing torch, sympy and the
suite again (seconds each), and its runs then start a fork server of their
own. In this process they reuse both; what a test reads (the exit code and
the text on stdout and stderr) is the same. The tests that need a fresh
interpreter (thread pinning, signals, a second matrix) start one themselves.
"""

from __future__ import annotations

import contextlib
import io
import os
from dataclasses import dataclass

from bench.cli import main


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str


def cli(*args, cwd=None) -> Result:
    """Run the command line with ``args``, in ``cwd`` where given."""
    out, err, here = io.StringIO(), io.StringIO(), os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in args])
            except SystemExit as exc:  # argparse: --help, or a usage error
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        os.chdir(here)
    return Result(code, out.getvalue(), err.getvalue())
