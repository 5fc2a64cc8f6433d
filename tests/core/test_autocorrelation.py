"""A recording's independent samples: the integrated autocorrelation time of a
series whose value is known in closed form, and the sum over recordings."""

from __future__ import annotations

import numpy as np
import pytest

from bench.core.autocorrelation import effective_samples, integrated_time
from bench.core.data import Dataset


def ar1(rho: float, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = np.zeros(n)
    e = rng.normal(size=n)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + e[k]
    return x


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.9])
def test_the_integrated_time_of_an_ar1_series_is_its_closed_form(rho):
    # an AR(1) series x_k = rho x_(k-1) + e_k has rho_k = rho^k, so tau = (1 + rho) / (1 - rho)
    exact = (1 + rho) / (1 - rho)
    estimates = [integrated_time(ar1(rho, 20_000, seed)) for seed in range(5)]
    assert np.mean(estimates) == pytest.approx(exact, rel=0.1)


def test_constant_and_short_series_count_each_sample():
    assert integrated_time(np.ones(100)) == 1.0
    assert integrated_time(np.array([1.0, 2.0])) == 1.0


def dataset(n: int, recording=None, time=None) -> Dataset:
    z = np.zeros((n, 1))
    return Dataset(z, z, z, z, recording=recording, time=time)


def test_effective_samples_sum_over_recordings_in_time_order_and_independent_samples_count_one_each():
    smooth = np.sin(np.linspace(0, 6 * np.pi, 1000))[:, None]
    assert effective_samples(dataset(1000), smooth) == pytest.approx([1000.0])
    one = effective_samples(dataset(1000, np.array(["a"] * 1000), np.arange(1000) * 0.01), smooth)
    assert one[0] < 50  # a smooth signal's 1,000 samples hold few independent ones
    # the same two recordings stored shuffled: taken in time order, each counts as much as alone
    order = np.random.default_rng(0).permutation(2000)
    values, labels = np.vstack([smooth, smooth])[order], np.array(["a"] * 1000 + ["b"] * 1000)[order]
    times = np.concatenate([np.arange(1000), np.arange(1000)])[order] * 0.01
    assert effective_samples(dataset(2000, labels, times), values) == pytest.approx(2 * one)
