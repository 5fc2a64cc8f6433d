"""The one validation protocol: whole trajectories, spans in time of one
trajectory kept the torque's autocorrelation time from what they are scored
against, blocks of independent samples."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from bench.core.autocorrelation import integrated_time
from bench.core.data import Dataset
from bench.core.folds import MAX_SPANS, MIN_SCORED, folds
from bench.residual.validation import FoldFits, cv_mse


def _recordings(lengths, trajectories, smooth: float, seed: int = 0) -> Dataset:
    """Recordings of a 2-joint torque, each a random walk smoothed over ``smooth`` samples."""
    rng = np.random.default_rng(seed)
    parts, names, paths, times = [], [], [], []
    for r, (n, trajectory) in enumerate(zip(lengths, trajectories)):
        noise = rng.normal(size=(n + 200, 2))
        kernel = np.exp(-0.5 * (np.arange(-100, 101) / max(smooth, 1e-3)) ** 2)
        tau = np.stack([np.convolve(noise[:, j], kernel, "same")[100:100 + n] for j in range(2)], axis=1)
        parts.append(tau)
        names += [f"run{r}"] * n
        paths += [trajectory] * n
        times.append(np.arange(n) * 0.01)
    tau = np.vstack(parts)
    q = rng.normal(size=tau.shape)
    return Dataset(q, q, q, tau, recording=np.array(names), trajectory=np.array(paths), time=np.concatenate(times))


def _distance_to_fit(data: Dataset, fold) -> int:
    """The fewest samples in time between a scored sample and a fitted sample of the same recording."""
    best = np.inf
    for index in data.in_time_order():
        position = np.arange(len(index))
        scored, fitted = position[fold.score[index]], position[fold.fit[index]]
        if len(scored) and len(fitted):
            best = min(best, np.min(np.abs(scored[:, None] - fitted[None, :])))
    return best


def test_spans_of_one_trajectory_are_scored_a_gap_of_the_autocorrelation_time_from_the_fit():
    data = _recordings([2000, 2000], ["A", "A"], smooth=20.0)
    tau = max(integrated_time(data.tau[i, j]) for i in data.in_time_order() for j in range(2))
    out = folds(data)
    assert out.kind == "spans" and out.gap >= tau > 20
    assert out.autocorrelation == pytest.approx(tau)
    assert np.array_equal(np.sum(out.held, axis=0), np.ones(len(data)))  # the held-out spans partition the samples
    for fold in out:
        assert not np.any(fold.score & ~fold.held)
        assert _distance_to_fit(data, fold) > out.gap - 1
        assert sorted(set(data.recording[fold.held])) == ["run0", "run1"]  # the span of both repeats together
        assert fold.score.sum() >= MIN_SCORED * fold.held.sum() - 2
    assert "scored only" in out.describe() and "autocorrelation" not in out.describe()


def test_a_slow_torque_gets_fewer_spans_and_a_gap_it_says_is_short_where_even_two_cannot_hold_it():
    quick = folds(_recordings([2000], ["A"], smooth=2.0))
    slow = folds(_recordings([2000], ["A"], smooth=60.0))
    assert len(quick) == MAX_SPANS and len(slow) < len(quick)
    tiny = folds(_recordings([200], ["A"], smooth=60.0))
    assert len(tiny) == 2 and tiny.gap < tiny.autocorrelation
    assert "shorter than the torque's integrated autocorrelation time" in tiny.describe()


def test_trajectories_fold_whole_with_their_repeats_and_max_folds_groups_them():
    data = _recordings([300] * 6, ["A", "A", "B", "C", "D", "E"], smooth=5.0)
    every = folds(data)
    assert every.kind == "trajectories" and len(every) == 5 and every.gap == 0
    assert every.describe() == "leave one trajectory out, over 5 trajectories (6 recordings)"
    three = folds(data, max_folds=3)
    assert len(three) == 3 and "3 folds of whole trajectories" in three.describe()
    for fold in three:
        assert np.array_equal(fold.score, fold.held)
        inside = set(data.trajectory[fold.held])
        assert not inside & set(data.trajectory[fold.fit])


def test_independent_samples_fold_in_contiguous_blocks():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(1000, 2))
    out = folds(Dataset(x, x, x, x))
    assert out.kind == "blocks" and len(out) == MAX_SPANS and [int(f.held.sum()) for f in out] == [250] * 4


@settings(max_examples=25, deadline=None)
@given(lengths=st.lists(st.integers(2, 400), min_size=1, max_size=3), smooth=st.floats(0.5, 80.0),
       seed=st.integers(0, 1000))
def test_spans_always_partition_and_keep_their_gap(lengths, smooth, seed):
    data = _recordings(lengths, ["A"] * len(lengths), smooth, seed)
    out = folds(data)
    assert np.array_equal(np.sum(out.held, axis=0), np.ones(len(data)))
    for fold in out:
        assert not np.any(fold.score & ~fold.held)
        if out.kind == "spans":
            assert _distance_to_fit(data, fold) >= out.gap


def test_the_compressed_folds_score_the_gapped_spans_as_a_fit_per_fold_does():
    data = _recordings([900, 900], ["A", "A"], smooth=10.0)
    out = folds(data).rows(data.dof)
    rng = np.random.default_rng(1)
    D, G = rng.normal(size=(2 * len(data), 3)), rng.normal(size=(2 * len(data), 2))
    y = data.tau.ravel() + D @ [1.0, -2.0, 0.5]
    total, rows = 0.0, 0
    for fold in out:
        X = np.hstack([D, G])
        coef = np.linalg.lstsq(X[fold.fit], y[fold.fit], rcond=None)[0]
        r = y[fold.score] - X[fold.score] @ coef
        total, rows = total + r @ r, rows + fold.score.sum()
    assert cv_mse(np.hstack([D, G]), y, out) == pytest.approx(total / rows, rel=1e-10)
    assert FoldFits(D, y, out).cv(G) == pytest.approx(total / rows, rel=1e-10)


def test_a_sparse_threshold_is_validated_on_the_protocols_folds_where_the_data_name_trajectories():
    from bench.physics import regression

    rng = np.random.default_rng(0)
    F = rng.normal(size=(400, 3))
    y = F @ [1.0, 0.0, 0.5] + 0.01 * rng.normal(size=400)
    cut = regression.fit_columns(F, y, 400)  # independent samples: the last quarter held out, as before
    held = [(np.arange(300), np.arange(300, 400))]
    assert np.array_equal(cut, regression.fit_columns(F, y, 400, folds=held))
    data = _recordings([200, 200], ["A", "B"], smooth=5.0)
    by_trajectory = folds(data).indices()
    coef = regression.fit_columns(F, y, 400, folds=by_trajectory)
    assert coef[1] == 0.0 and abs(coef[0] - 1.0) < 0.01


def test_a_long_log_is_thinned_within_each_recording_in_time_order():
    data = _recordings([1000, 600], ["A", "B"], smooth=3.0)
    same, step = data.thinned(5000)
    assert same is data and step == 1
    thin, step = data.thinned(400)
    assert step == 4 and len(thin) == 250 + 150
    for index, kept in zip(data.in_time_order(), thin.in_time_order()):
        np.testing.assert_array_equal(thin.time[kept], data.time[index][::4])
    assert thin.recordings() == data.recordings()
