"""Types of command-line numbers: each rejects a bad value in one line.

Every option of :mod:`bench.cli` and of the measurement scripts in
:mod:`bench.experiments` that takes a count, a duration or a fraction uses
one of these as its ``argparse`` type, so ``--rounds 0`` or ``--budget nan``
ends with ``error: argument --rounds: must be a positive integer, got 0``
and exit code 2 instead of a traceback from deep inside the run.
"""

from __future__ import annotations

import argparse
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
