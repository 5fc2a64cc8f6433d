"""A run's test split, sealed: its targets are read only to score.

The test set is read once, to score ([docs/choices.md](../../docs/choices.md)).
A run's test data are a :class:`SealedSplit` from the moment they are loaded
(:func:`bench.runner.execute.given_data` and :func:`bench.runner.execute.execute`
seal them): anyone may read their states, labels and times, since a model
predicts there and a domain report measures how far they lie, but reading
their targets (``tau``, ``L``) raises :class:`SealedRead` unless it happens
inside :func:`scoring`.

Only the modules that score may import this module: an import contract in
pyproject.toml ("Only the scorers open the test split", checked by
``lint-imports``, which the test suite runs) names them. A choice made
anywhere else (a method's fit, the tuning, the folds, the residual loop's
rounds, select's rule, a study's rule) therefore cannot read a test torque:
handed a test split, it raises, and its tests fail; and a new module that
imports :func:`scoring` to get round that breaks the contract.
"""

from __future__ import annotations

import contextlib
import dataclasses

from bench.core.data import Dataset

#: the fields a test split seals
SEALED = ("tau", "L")
_open = 0  # scoring() depth: a plain global, so that forked children and threads see it


class SealedRead(RuntimeError):
    """A test split's targets were read outside :func:`scoring`."""


class SealedSplit(Dataset):
    """A :class:`~bench.core.data.Dataset` whose :data:`SEALED` fields are read only inside :func:`scoring`."""

    def __getattribute__(self, name):
        if name in SEALED and not _open:
            source = object.__getattribute__(self, "source")
            raise SealedRead(f"{source}: the test split's {name} is read only to score (bench.core.sealed); "
                                f"a choice must be made on the training data")
        return object.__getattribute__(self, name)


@contextlib.contextmanager
def scoring():
    """Within this block, test splits' targets may be read."""
    global _open
    _open += 1
    try:
        yield
    finally:
        _open -= 1


def seal(data: Dataset | None) -> Dataset | None:
    """``data`` as a :class:`SealedSplit` (``None`` stays ``None``; a test split is returned as it is)."""
    if data is None or isinstance(data, SealedSplit):
        return data
    with scoring():
        return SealedSplit(**{f.name: getattr(data, f.name) for f in dataclasses.fields(Dataset)})
