"""The test split, sealed: its targets are read only to score.

The test set is read once, to score ([docs/choices.md](../../docs/choices.md)).
Test data are a :class:`SealedSplit` from the moment they are loaded (a
measured system's ``load("test")``, :mod:`systems.measured`; a run's test
files or generated test set, :func:`bench.runner.run.given_data` and
:func:`bench.runner.run.execute`): anyone may read their states, labels
and times, since a model predicts there and a domain report measures how far
they lie, but reading their targets (``tau``, ``L``) raises
:class:`SealedRead` unless it happens inside
:func:`bench.core.scoring.scoring`.

Only the modules that score may import :mod:`bench.core.scoring`: an import
contract in pyproject.toml ("Only the scorers open the test split", checked
by ``lint-imports``, which the test suite runs) names them, and no other
module touches this module's gate (tests/test_architecture.py). A choice made
anywhere else (a method's fit, the tuning, the folds, the residual loop's
rounds, select's rule) therefore cannot read a test torque: handed a test
split, it raises, and its tests fail; and a new module that imports
``scoring`` to get round that breaks the contract.
"""

from __future__ import annotations

import dataclasses
import weakref

from bench.core.data import STATES, Dataset

#: the fields a test split seals
SEALED = ("tau", "L")


class _Gate:
    """Whether test splits' targets may be read now: the depth of :func:`bench.core.scoring.scoring`'s blocks
    (one object of the process, so that forked children and threads see it)."""

    depth = 0


_GATE = _Gate()


class SealedRead(RuntimeError):
    """A test split's targets were read outside :func:`bench.core.scoring.scoring`."""


class _Held:
    """What a sealed split holds in place of a target it has: the values are kept apart (:data:`_HELD`)."""

    def __repr__(self) -> str:
        return "<sealed: read only to score>"


HELD = _Held()
#: each sealed split's targets, by the split's id, kept apart from the split itself so that no reading of its
#: attributes (``vars``, ``__dict__``, ``object.__getattribute__``, a copy of its fields) finds them; dropped
#: with the split
_HELD: dict[int, dict] = {}


class SealedSplit(Dataset):
    """A :class:`~bench.core.data.Dataset` whose :data:`SEALED` fields are read only inside
    :func:`bench.core.scoring.scoring`: the split itself holds :data:`HELD` in their place (``None`` where it has
    none), and the values are kept apart."""

    def __post_init__(self):
        super().__post_init__()
        _HELD[id(self)] = {name: object.__getattribute__(self, name) for name in SEALED}
        weakref.finalize(self, _HELD.pop, id(self), None)
        for name in SEALED:
            if object.__getattribute__(self, name) is not None:
                object.__setattr__(self, name, HELD)

    def __getattribute__(self, name):
        if name in SEALED:
            if not _GATE.depth:
                source = object.__getattribute__(self, "source")
                raise SealedRead(f"{source}: the test split's {name} is read only to score (bench.core.sealed); "
                                 f"a choice must be made on the training data")
            held = _HELD.get(id(self))  # none yet while its construction checks them
            return object.__getattribute__(self, name) if held is None else held[name]
        return object.__getattribute__(self, name)

    def __reduce__(self):
        """Pickled and copied sealed, with its targets (another process scores it too)."""
        _GATE.depth += 1
        try:
            return seal, (Dataset(**fields(self)),)
        finally:
            _GATE.depth -= 1

    def replace(self, **changes) -> "SealedSplit":
        """A copy with ``changes`` (states moved along the recording, a time shift's), sealed as this one
        is: its targets are carried over, not read."""
        _GATE.depth += 1  # the copy's construction and checks read them
        try:
            return dataclasses.replace(self, **changes)
        finally:
            _GATE.depth -= 1

    def readable(self) -> tuple[str, ...]:
        """The states only, outside :func:`bench.core.scoring.scoring` (a model predicts from them)."""
        return super().readable() if _GATE.depth else STATES


def fields(data: Dataset) -> dict:
    """``data``'s fields by name, to build a copy of another kind (a sealed one's only while scoring)."""
    return {f.name: getattr(data, f.name) for f in dataclasses.fields(Dataset)}


def seal(data: Dataset | None) -> Dataset | None:
    """``data`` as a :class:`SealedSplit` (``None`` stays ``None``; a test split is returned as it is)."""
    if data is None or isinstance(data, SealedSplit):
        return data
    values = fields(data)
    _GATE.depth += 1  # its own checks in __post_init__ read the targets
    try:
        return SealedSplit(**values)
    finally:
        _GATE.depth -= 1
