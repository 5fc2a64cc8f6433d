"""How many independent samples a recording holds.

Neighbouring samples of a recording are near copies of each other: a torque
sampled at 100 Hz along a smooth trajectory changes little from one sample to
the next. A likelihood that counts every sample as independent evidence
weighs a recording of 2,000 samples as if it held 2,000 independent ones, and
a model fitted to it becomes as sure of itself as that count allows.

:func:`integrated_time` is a series' integrated autocorrelation time ``tau``
(in samples): ``1 + 2 * sum_k rho_k``, the autocorrelations summed by Geyer's
initial positive sequence (Geyer, Statistical Science 7, 1992: pairs of
neighbouring lags are summed while their sum stays positive), so that the
noisy tail of the estimate is cut where it stops carrying signal.
:func:`effective_samples` divides each recording's length by it, per column,
and sums over the recordings. Independent samples (no recording labels) count
one each.
"""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset


def integrated_time(x: np.ndarray) -> float:
    """The integrated autocorrelation time of the series ``x``, in samples, at least 1
    (see the module docstring). A constant series, or one of fewer than 3 samples, gives 1."""
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    x = x - x.mean() if n else x
    if n < 3 or not np.any(x):
        return 1.0
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    acf = acf / acf[0]
    total = 0.0
    for k in range(0, n - 1, 2):
        pair = acf[k] + acf[k + 1]
        if pair <= 0:
            break
        total += pair
    return max(2.0 * total - 1.0, 1.0)


def effective_samples(data: Dataset, values: np.ndarray) -> np.ndarray:
    """Per column of ``values`` (shape ``(n, k)``, one row per sample of ``data``):
    the number of independent samples it holds, ``sum over recordings of
    n_r / tau_r``, each recording taken in time order; ``n`` for each column
    where ``data`` has no recordings."""
    values = np.asarray(values, dtype=np.float64).reshape(len(data), -1)
    if data.recording is None:
        return np.full(values.shape[1], float(len(data)))
    total = np.zeros(values.shape[1])
    for index in data.in_time_order():
        total += [len(index) / integrated_time(values[index, c]) for c in range(values.shape[1])]
    return total
