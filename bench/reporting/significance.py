"""Which differences between methods the tables may call real.

With ten seeds a method and standard deviations as large as the means, most
differences between two methods' means are not evidence of anything. Three
summaries say which are:

* **Ties with the best** (:func:`ties_with_best`), for the All n rows of a table:
  the best method has the lowest mean; every other method's seeds are
  compared with the best's by a two-sided Mann–Whitney U test
  (:func:`scipy.stats.mannwhitneyu`), the p-values adjusted over the row by
  Holm's step-down procedure (:func:`holm`), at :data:`ALPHA`. A method
  whose difference is not significant ties with the best. Where either of
  the two has fewer than :data:`MIN_SEEDS` seeds, no test is made and no
  difference is called significant: the method is *untested*. With ten
  seeds against ten, the smallest two-sided p-value the test can give is
  1.1e-5, but a shift of one standard deviation is found only about half
  the time: a tie is the absence of evidence, not evidence of equality.
* **Ranks across seeds** (:func:`seed_ranks`), for each table: at every
  seed all the methods completed, the methods are ranked by test MSE
  (ties share the mean rank); the summary is each method's mean rank.
* **Ranks across sections** (:func:`friedman`), for a leaderboard, as
  SRBench reports them: each section (system, experiment, noise) ranks the
  methods by their median test MSE over seeds; the summary is each
  method's mean rank and a Friedman test (:func:`scipy.stats.friedmanchisquare`)
  of whether the ranks differ at all, over the methods with results in
  every section.

A method's variants (``syrenets@pruned``) are post-processings of its own
runs, not independent methods; they are left out of both rank summaries.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from bench.core.names import MethodName

#: the family-wise error rate of each row's comparisons with the best
ALPHA = 0.05
#: a comparison needs at least this many seeds on each side
MIN_SEEDS = 5


def holm(p: list[float]) -> list[float]:
    """Holm's step-down adjusted p-values, in the order given.

    The ``i``-th smallest p-value is multiplied by ``m - i`` (``i`` from 0),
    the running maximum taken so that the adjusted values keep their order,
    capped at 1. (statsmodels' ``multipletests(method="holm")`` computes the
    same; it is not a dependency of the suite for these few lines.)
    """
    m = len(p)
    order = np.argsort(p, kind="stable")
    adjusted = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adjusted[i] = running
    return adjusted.tolist()


def _finite(v) -> bool:
    return v is not None and math.isfinite(v)


@dataclass(frozen=True)
class Comparison:
    """One method against the row's best: ``p`` is Holm-adjusted; ``None`` where untested."""

    p: float | None

    @property
    def tested(self) -> bool:
        return self.p is not None

    @property
    def ties(self) -> bool:
        """Not significantly different from the best (an untested method does not tie)."""
        return self.p is not None and self.p >= ALPHA


def ties_with_best(samples: dict[str, list[float]]) -> tuple[str | None, dict[str, Comparison]]:
    """The method with the lowest mean of ``samples`` (``{method: values}``)
    and each other method's comparison with it; non-finite values are left out."""
    from scipy.stats import mannwhitneyu  # only tables need scipy.stats; keep it off the import path

    clean = {m: [float(v) for v in vs if _finite(v)] for m, vs in samples.items()}
    clean = {m: vs for m, vs in clean.items() if vs}
    if not clean:
        return None, {}
    best = min(clean, key=lambda m: (float(np.mean(clean[m])), m))
    others = [m for m in clean if m != best]
    tested = [m for m in others if len(clean[m]) >= MIN_SEEDS and len(clean[best]) >= MIN_SEEDS]
    raw = [float(mannwhitneyu(clean[best], clean[m], alternative="two-sided").pvalue) for m in tested]
    adjusted = dict(zip(tested, holm(raw)))
    return best, {m: Comparison(adjusted.get(m)) for m in others}


def _is_variant(method: str) -> bool:
    return MethodName.parse(method).variant is not None


def seed_ranks(test_mse: dict[str, dict[int, float]]) -> tuple[dict[str, float], int]:
    """Each method's mean rank (1 = lowest test MSE) over the seeds every
    method completed with a finite figure, and how many seeds that is;
    ``({}, 0)`` with fewer than two methods or no such seed.
    ``test_mse`` is ``{method: {seed: value}}``."""
    from scipy.stats import rankdata

    methods = sorted(m for m in test_mse if not _is_variant(m))
    if len(methods) < 2:
        return {}, 0
    seeds = sorted(set.intersection(*(
        {s for s, v in test_mse[m].items() if _finite(v)} for m in methods)))
    if not seeds:
        return {}, 0
    ranks = np.array([rankdata([test_mse[m][s] for m in methods]) for s in seeds])
    return dict(zip(methods, ranks.mean(axis=0).tolist())), len(seeds)


@dataclass(frozen=True)
class Friedman:
    """Mean ranks across sections and the Friedman test over them."""

    ranks: dict[str, float]
    sections: int
    statistic: float | None
    p: float | None
    left_out: list[str]


def friedman(medians: dict[str, dict[str, float]]) -> Friedman | None:
    """``medians`` is ``{section: {method: median test MSE}}``. The methods
    with a finite median in every section are ranked in each (ties share the
    mean rank); ``None`` with fewer than two such methods or two sections.
    The Friedman test needs at least three methods; with two its fields are ``None``."""
    from scipy.stats import friedmanchisquare, rankdata

    sections = sorted(medians)
    every = set().union(*(medians[s] for s in sections)) if sections else set()
    every = {m for m in every if not _is_variant(m)}
    methods = sorted(m for m in every if all(_finite(medians[s].get(m)) for s in sections))
    if len(methods) < 2 or len(sections) < 2:
        return None
    table = np.array([[medians[s][m] for m in methods] for s in sections])
    ranks = np.array([rankdata(row) for row in table]).mean(axis=0)
    statistic = p = None
    if len(methods) >= 3:
        result = friedmanchisquare(*table.T)
        statistic, p = float(result.statistic), float(result.pvalue)
    return Friedman(dict(zip(methods, ranks.tolist())), len(sections), statistic, p, sorted(every - set(methods)))


def section_medians(by_method: dict[str, list[float]]) -> dict[str, float]:
    """``{method: median}`` of the finite values of each method that has any."""
    out = {}
    for m, vals in by_method.items():
        finite = [v for v in vals if _finite(v)]
        if finite:
            out[m] = float(np.median(finite))
    return out


def by_seed(records) -> dict[str, dict[int, float]]:
    """``{method: {seed: test MSE}}`` of the ``ok`` records."""
    out: dict[str, dict[int, float]] = defaultdict(dict)
    for r in records:
        if r.status == "ok" and r.test_mse is not None:
            out[r.method][r.seed] = r.test_mse
    return dict(out)
