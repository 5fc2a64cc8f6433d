"""Which differences the tables call real, checked on synthetic records and
against scipy's own tests."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import friedmanchisquare, mannwhitneyu

from bench.reporting.significance import friedman, holm, seed_ranks, ties_with_best
from bench.reporting.tables import build_table
from tests.reporting.test_tables import rec


def _row(table: str, group: str, split: str) -> list[str]:
    lines = table.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith(f"| {group} | train"))
    line = lines[i] if split == "train" else lines[i + 1]
    return [c.strip() for c in line.strip("|").split("|")][2:]


def _records(method, values, seed0=0):
    return [rec(method, seed0 + s, v, v) for s, v in enumerate(values)]


def test_two_methods_from_one_distribution_share_the_bold_and_one_far_apart_does_not():
    rng = np.random.default_rng(3)
    same_a, same_b = rng.lognormal(0.0, 1.0, 10), rng.lognormal(0.0, 1.0, 10)
    far = rng.lognormal(4.0, 1.0, 10)  # e^4 = 55 times larger in the median
    table = build_table(_records("a", same_a) + _records("b", same_b) + _records("c", far))
    a, b, c = _row(table, "All 10", "test")
    assert a.startswith("**") and b.startswith("**")  # the better one, and the one it cannot be told from
    assert not c.startswith("**") and "†" not in c
    # the same verdicts as scipy's test, Holm-adjusted over the row's two comparisons
    best, other = (same_a, same_b) if same_a.mean() < same_b.mean() else (same_b, same_a)
    p_tie = mannwhitneyu(best, other, alternative="two-sided").pvalue
    p_far = mannwhitneyu(best, far, alternative="two-sided").pvalue
    assert min(1.0, 2 * min(p_tie, p_far)) < 0.05 and max(p_tie, p_far) >= 0.05


def test_fewer_than_five_seeds_are_never_called_different():
    table = build_table(_records("a", [1.0, 1.1, 0.9, 1.0, 1.05, 0.95]) + _records("b", [50.0, 60.0, 55.0, 52.0]))
    a, b = _row(table, "All 6", "test")
    assert a.startswith("**") and b.endswith("†") and not b.startswith("**")
    best, compared = ties_with_best({"a": [1.0] * 6, "b": [50.0] * 4})
    assert best == "a" and not compared["b"].tested and not compared["b"].ties


def test_only_the_all_10_rows_are_tested_the_others_bold_their_lowest_mean():
    rng = np.random.default_rng(4)
    table = build_table(_records("a", rng.lognormal(0, 1, 10)) + _records("b", rng.lognormal(0, 1, 10)))
    assert all(c.startswith("**") for c in _row(table, "All 10", "test"))
    for group in ("Best", "5 Best", "5 Worse"):
        cells = _row(table, group, "test")
        assert sum(c.startswith("**") for c in cells) == 1 and not any("†" in c for c in cells)


def test_holm_adjusts_like_its_definition():
    # p sorted 0.01 < 0.02 < 0.04: times 3, 2, 1, then the running maximum
    assert holm([0.04, 0.01, 0.02]) == pytest.approx([0.04, 0.03, 0.04])
    assert holm([0.5, 0.6]) == pytest.approx([1.0, 1.0])
    assert holm([]) == []


def test_seed_ranks_use_the_seeds_every_method_completed():
    ranks, n = seed_ranks({"a": {0: 1.0, 1: 1.0, 2: 9.0}, "b": {0: 2.0, 1: 2.0}, "b@refined": {0: 0.1}})
    assert n == 2 and ranks == {"a": 1.0, "b": 2.0}  # seed 2 is a's alone; a variant is not ranked
    table = build_table(_records("a", [1.0] * 3) + _records("b", [2.0] * 3))
    assert "Mean rank by test MSE over the 3 seed(s) every method completed (1 = best): a 1.0, b 2.0." in table


def test_friedman_ranks_sections_by_their_medians_and_agrees_with_scipy():
    medians = {f"s{k}": {"a": 1.0 + k, "b": 2.0 + 2 * k, "c": 0.5 + 3 * k, "d": 7.0} for k in range(6)}
    out = friedman(medians)
    assert out.sections == 6 and out.left_out == [] and sorted(out.ranks) == ["a", "b", "c", "d"]
    table = np.array([[medians[s][m] for m in sorted(out.ranks)] for s in sorted(medians)])
    assert out.statistic == pytest.approx(friedmanchisquare(*table.T).statistic)
    assert out.ranks["a"] < out.ranks["b"]
    partial = friedman({"s0": {"a": 1.0, "b": 2.0, "c": 3.0}, "s1": {"a": 1.0, "b": 2.0}})
    assert partial.left_out == ["c"] and partial.statistic is None  # two methods: no Friedman test
