"""The test split is out of reach of any choice: its torques are read only inside
``scoring()``, which only the scorers may import (pyproject.toml's contract "Only
the scorers open the test split", checked by tests/test_architecture.py). A
choosing path handed a test split raises, so its tests fail."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.budget import Budget
from bench.core.data import Dataset
from bench.core.scoring import scoring
from bench.core.sealed import SealedRead, SealedSplit, seal
from bench.evaluation.tuning import tune
from bench.runner.run import given_data
from methods import METHODS
from systems import SYSTEMS


def _data(n: int = 300, dof: int = 2, seed: int = 0) -> Dataset:
    rng = np.random.default_rng(seed)
    q, qd, qdd = (rng.normal(size=(n, dof)) for _ in range(3))
    return Dataset(q, qd, qdd, 2.0 * qdd + np.sin(q), rng.normal(size=n), source="made.csv")


def test_a_test_splits_targets_are_read_only_to_score():
    plain = _data()
    test = seal(plain)
    assert isinstance(test, SealedSplit) and seal(test) is test and seal(None) is None
    np.testing.assert_array_equal(test.q, plain.q)  # a model predicts at its states
    assert len(test) == len(plain) and test.dof == plain.dof and test.source == "made.csv"
    for read in (lambda: test.tau, lambda: test.L, lambda: test.target("indirect"), lambda: test.subset([0, 1])):
        with pytest.raises(SealedRead, match="made.csv: the test split's (tau|L) is read only to score"):
            read()
    with scoring():
        with scoring():
            np.testing.assert_array_equal(test.tau, plain.tau)
        np.testing.assert_array_equal(test.target("direct"), plain.L)  # still open in the outer block
    with pytest.raises(SealedRead):
        test.tau


def _holds(value, targets) -> bool:
    """Whether ``value`` is, or holds, one of ``targets``' arrays or a copy of its values."""
    if isinstance(value, np.ndarray):
        return any(value.shape == t.shape and np.array_equal(value, t) for t in targets)
    if isinstance(value, dict):
        return any(_holds(v, targets) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_holds(v, targets) for v in value)
    return False


def test_no_reading_of_a_test_splits_attributes_finds_its_targets():
    """The split holds a marker in place of each target, the values kept apart: vars, __dict__,
    object.__getattribute__ and a plain Dataset built from its fields find no torque; pickled or copied it is
    sealed still, and scores as the original."""
    import copy
    import pickle

    plain = _data()
    test = seal(plain)
    targets = (plain.tau, plain.L)
    assert not _holds(vars(test), targets) and not _holds(test.__dict__, targets)
    assert not any(_holds(object.__getattribute__(test, name), targets) for name in ("tau", "L"))
    assert not _holds([getattr(test, f, None) for f in vars(test) if f not in ("tau", "L")], targets)
    with pytest.raises(Exception) as built:
        Dataset(**vars(test))
    assert not isinstance(built.value, SealedRead)  # it fails on the marker, not on a torque it read
    test.check_target("indirect")  # it has torques, though none can be read
    for again in (pickle.loads(pickle.dumps(test)), copy.deepcopy(test), copy.copy(test)):
        assert isinstance(again, SealedSplit) and not _holds(vars(again), targets)
        with pytest.raises(SealedRead):
            again.tau
        with scoring():
            np.testing.assert_array_equal(again.tau, plain.tau)


def test_a_fit_or_a_search_handed_a_test_split_raises():
    test = seal(_data())
    sysid = METHODS["sysid"]
    with pytest.raises(SealedRead):
        sysid().fit(test, "indirect", 0, Budget(steps=1), system=SYSTEMS["double_pendulum"]())
    with pytest.raises(SealedRead):
        tune(sysid, {}, test, "indirect", 0, Budget(steps=1), system=SYSTEMS["double_pendulum"]())


def test_a_measured_arms_test_split_is_sealed_from_the_moment_it_is_loaded():
    train, test = given_data(SYSTEMS["kuka_lwr4"](), None, None)
    assert not isinstance(train, SealedSplit) and isinstance(test, SealedSplit)
    assert np.isfinite(train.tau).all()
    with pytest.raises(SealedRead, match="test split's tau"):
        test.tau
