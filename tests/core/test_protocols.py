"""Validation protocols in state space: leave-region-out folds hold out states
far from what they fit, kNNDM picks the folds whose held-out distances match
its target's (near target: near folds; far target: far folds), both serve as
scikit-learn splitters, ``pooled`` folds the states of two or three trajectories into regions and leaves more
out whole, and a protocol that cannot work is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.errors import ConfigError
from bench.core.protocols import KNNDM, POOLED_UP_TO, Regions, folds, parse, resolve, states, target_distances
from bench.evaluation.domain import domain
from tests.evaluation.test_domain import _joined, _trajectory


def test_leave_region_out_folds_reach_farther_than_spans_in_time():
    train = _trajectory("A", 1.0, 1.0, repeats=2)
    by_time = domain(train, folds(train, "time", 4))["reach"]["median"]
    by_region = folds(train, "regions", 4)
    reached = domain(train, by_region)["reach"]["median"]
    assert by_region.kind == "regions" and len(by_region) == 4 and "regions of the states" in by_region.describe()
    assert reached > 10 * by_time
    held = np.stack([f.held for f in by_region])
    assert (held.sum(axis=0) == 1).all()  # every sample held out by exactly one fold


def test_pooled_folds_fit_every_one_of_few_trajectories_and_leave_more_out_whole():
    few = _joined([_trajectory("slow", 0.5, 0.6), _trajectory("fast", 2.0, 1.4)])
    pooled, auto = folds(few, "pooled", 4), folds(few, "auto", 4)
    assert pooled.kind == "regions" and auto.kind != "regions" and len(pooled) == 4
    labels = few.trajectory_labels()
    for fold in pooled:  # each fold is fitted on part of both trajectories, where auto's fits one
        assert set(labels[~fold.held]) == {"slow", "fast"}
    assert [resolve("pooled", n) for n in (0, 1, 2, 3, 4, 7)] == \
        ["time", "regions", "regions", "regions", "time", "time"] and POOLED_UP_TO == 3
    assert [resolve("auto", n) for n in (1, 2, 4)] == ["regions", "time", "time"]


def test_the_splitters_follow_scikit_learns_interface():
    from sklearn.linear_model import Ridge
    from sklearn.model_selection import cross_val_score

    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 4))
    y = x @ [1.0, -2.0, 0.5, 0.0]
    for splitter in (Regions(3), KNNDM(np.full(50, 0.5), 3)):
        scores = cross_val_score(Ridge(), x, y, cv=splitter)
        assert len(scores) == 3 == splitter.get_n_splits()
        tests = np.concatenate([t for _, t in splitter.split(x)])
        assert sorted(tests.tolist()) == list(range(300))


def test_knndm_chooses_near_folds_for_a_near_target_and_far_ones_for_a_far_one():
    train = _trajectory("A", 1.0, 1.0, repeats=2)
    near = folds(train, "knndm", 4, target=_trajectory("again", 1.0, 1.0))  # the same motion again
    far = folds(train, "knndm", 4, target=_trajectory("B", 2.0, 1.3))
    near_reach = domain(train, near)["reach"]["median"]
    far_reach = domain(train, far)["reach"]["median"]
    assert near.kind == "spans" and "kNNDM" in near.describe()  # the folds of time matched best
    assert far.kind == "knndm" and far_reach > 10 * near_reach
    tried = {c["folds"]: c["wasserstein"] for c in far.choices}
    assert min(tried, key=tried.get) in far.describe() and "time" in tried


def test_knndm_matches_the_spread_between_trajectories_by_default():
    train = _joined([_trajectory("slow", 0.5, 0.6), _trajectory("mid", 1.0, 1.0), _trajectory("fast", 2.0, 1.4)])
    distances = target_distances(train, None)
    assert len(distances) == len(train)
    chosen = folds(train, "knndm", 4)
    assert chosen.choices and "kNNDM" in chosen.describe()
    x = states(train)
    assert x.shape == (len(train), 4) and np.allclose(x.std(axis=0), 1.0)


def test_a_protocol_that_cannot_work_is_refused():
    one = _trajectory("A", 1.0, 1.0)
    with pytest.raises(ConfigError, match="one trajectory and no target"):
        folds(one, "knndm", 4)
    with pytest.raises(ConfigError, match="unknown protocol"):
        parse("blocks")
    with pytest.raises(ConfigError, match="unknown protocol"):
        parse("regions:x.csv")
    assert parse("knndm:/a/b.csv") == ("knndm", "/a/b.csv") and parse(None) == ("time", None)
