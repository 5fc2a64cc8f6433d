"""Where the test split is opened, to score (:mod:`bench.core.sealed`).

Only the modules that score import this one: pyproject.toml's contract "Only
the scorers open the test split" lists them.
"""

from __future__ import annotations

import contextlib

from bench.core import sealed
from bench.core.data import Dataset


@contextlib.contextmanager
def scoring():
    """Within this block, test splits' targets may be read."""
    sealed._GATE.depth += 1
    try:
        yield
    finally:
        sealed._GATE.depth -= 1


def opened(data: Dataset | None) -> Dataset | None:
    """A plain copy of a sealed test split (``data`` itself where it is not one): for the scorers' own
    reading, and the tests'."""
    if not isinstance(data, sealed.SealedSplit):
        return data
    with scoring():
        return Dataset(**sealed.fields(data))
