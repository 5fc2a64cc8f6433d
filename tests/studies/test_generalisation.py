"""Where a learner stops generalising: each test sample binned by its distance
from the training states, each learner's MSE per bin."""

from __future__ import annotations

import numpy as np

from bench.studies.generalisation import BINS, CONSTANT, STANDARD, run_case


def test_each_bin_holds_a_share_of_the_test_samples_and_the_bins_make_the_whole():
    constant = run_case("kuka_lwr4", "swapped", CONSTANT, 0, None, None)
    standard = run_case("kuka_lwr4", "swapped", STANDARD, 0, None, None)
    for row in (constant, standard):
        bins = row["bins"]
        assert len(bins) == BINS and sum(b["samples"] for b in bins) > 0
        sizes = [b["samples"] for b in bins]
        assert max(sizes) - min(sizes) <= 2  # bins of equal count
        whole = sum(b["mse"] * b["samples"] for b in bins) / sum(sizes)
        assert np.isclose(whole, row["test_mse"])
        distances = [b["distance"] for b in bins]
        assert distances == sorted(distances)
    assert standard["test_mse"] < constant["test_mse"]  # the rigid body beats a constant on the other trajectory
