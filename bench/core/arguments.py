"""Types of command-line numbers: each rejects a bad value in one line.

Every option of :mod:`bench.cli` and of the measurement scripts in
:mod:`bench.studies` that takes a count, a duration or a fraction uses
one of these as its ``argparse`` type, so ``--rounds 0`` or ``--budget nan``
ends with ``error: argument --rounds: must be a positive integer, got 0``
and exit code 2 instead of a traceback from deep inside the run.
"""

from __future__ import annotations

import argparse
import ast
import math


def _number(text: str, kind: type, what: str):
    try:
        return kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None


def positive(text: str) -> float:
    """A finite number > 0."""
    value = _number(text, float, "a positive number")
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def nonnegative(text: str) -> float:
    """A finite number >= 0."""
    value = _number(text, float, "a number >= 0")
    if not (value >= 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a number >= 0, got {text}")
    return value


def positive_int(text: str) -> int:
    """A whole number > 0."""
    value = _number(text, int, "a positive integer")
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def nonnegative_int(text: str) -> int:
    """A whole number >= 0."""
    value = _number(text, int, "a whole number >= 0")
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text}")
    return value


def noise_level(text: str) -> float:
    """Gaussian noise on a target as a fraction of its standard deviation: in [0, 10)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a noise level is a number, got {text!r}") from None
    if not (0 <= value < 10 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"a noise level is a fraction of the target's std in [0, 10), got {text}")
    return value


def seed(text: str) -> int:
    """A generator's seed: a whole number >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a seed is a whole number >= 0, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is a whole number >= 0, got {text}")
    return value


def csv_list(text: str) -> list[str]:
    """A comma-separated list of names, at least one."""
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise argparse.ArgumentTypeError("expected a comma-separated list")
    return items


def seed_list(text: str) -> list[int]:
    """Seeds as a comma-separated list of seeds and ``low-high`` ranges, none twice."""
    out = []
    for part in csv_list(text):
        lo, dash, hi = part.partition("-")
        if dash and lo:
            first, last = seed(lo), seed(hi)
            if last < first:
                raise argparse.ArgumentTypeError(f"the seed range {part} is empty (write it low-high)")
            out += list(range(first, last + 1))
        else:
            out.append(seed(part))
    if len(set(out)) != len(out):
        raise argparse.ArgumentTypeError(f"a seed is given twice in {text}")
    return out


def assignment(text: str) -> tuple[str, object]:
    """``NAME=VALUE`` (or ``METHOD.NAME=VALUE``): the value as a Python
    literal where it parses as one (``64``, ``1e-3``, ``True``, ``[8, 8]``),
    else as text."""
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    key, raw = text.split("=", 1)
    try:
        value = ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        value = raw
    return key.strip(), value


#: the help of ``--cluster``, wherever jobs are scheduled (:func:`add_workers`)
CLUSTER_HELP = ("run on Dask distributed: 'local' starts a LocalCluster of --workers processes; tcp://host:8786 "
                "uses a running scheduler (needs the 'dask' extra)")


def add_workers(parser, what: str, default: int | None = 2) -> None:
    """``--workers N`` (``what`` at a time, one process each) and ``--cluster local|ADDRESS``: where the
    jobs of a command or a study run (:func:`bench.runner.schedule.run_jobs`)."""
    told = "one per core" if default is None else default
    parser.add_argument("--workers", type=positive_int, default=default,
                        help=f"{what} at a time, one process each (default {told})")
    parser.add_argument("--cluster", default=None, metavar="local|ADDRESS", help=CLUSTER_HELP)
