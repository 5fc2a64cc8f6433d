"""Which candidates explain a residual: forward stepwise selection judged by
information, significance and held-out error.

A candidate is accepted only if all hold:

* the Bayesian information criterion of the residual fit, over all training
  rows, falls by more than :data:`MIN_BIC_DROP` (strong evidence on Kass &
  Raftery's scale);
* its coefficient is at least :data:`MIN_T` standard errors from zero;
* it lowers the cross-validated mean squared residual on held-out data by at
  least :data:`MIN_HELDOUT_GAIN` of that residual: leave one recording out
  where the training data name several recordings, contiguous blocks
  otherwise (:mod:`bench.residual.validation`; on measured trajectories
  neighbouring samples are near copies, so interleaved rows would not test
  generalisation);
* the residual is above the floor of numerical round-off
  (:data:`ROUNDOFF` of the torque's mean square), so a model that already
  fits exactly is left alone;
* its coefficient is physical (:func:`~bench.residual.candidates.admissible`:
  no negative friction, damping, rotor inertia or stiffness). Where the best
  candidate of a step passes the other tests with an impossible coefficient,
  the best admissible one that passes them and fits as well (removes at
  least :data:`AS_WELL` of the residual sum of squares the best removes) is
  taken instead; where none does, the step ends the selection with a *structural finding*: the
  declared form lacks this freedom, and no term is added for it.

Noise alone fails the first two tests: with Gaussian residuals, a useless
column lowers ``n log RSS`` by a chi-squared(1) amount, and ``log n`` plus the
drop of 10 asks for a chi-squared value above 20 (p < 1e-5 per candidate).
All fits are :func:`bench.core.regression.fit_statistics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bench.core.data import Dataset
from bench.core.regression import fit_statistics
from bench.core.terms import Term, TermLibrary
from bench.residual.candidates import admissible, is_named, label
from bench.residual.validation import cv_mse, row_folds

MIN_BIC_DROP = 10.0
MIN_T = 5.0
MIN_HELDOUT_GAIN = 0.01
ROUNDOFF = 1e-20
#: an admissible candidate replaces a better one with an impossible coefficient
#: only if it removes at least this share of what that one removes
AS_WELL = 0.9


def bic(rss: float, n: int, k: int) -> float:
    """The Bayesian information criterion of a Gaussian fit with ``k`` columns to ``n`` rows."""
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


@dataclass
class Selection:
    accepted: list[Term]
    steps: list[dict] = field(default_factory=list)
    #: ``(term, coefficient, stderr)`` of a residual only an inadmissible coefficient explains
    structural: list[tuple[Term, float, float]] = field(default_factory=list)


def trace(target: np.ndarray, data: Dataset, pool: TermLibrary, fixed: np.ndarray | None = None,
          exclude: list[Term] = ()) -> Selection:
    """Forward stepwise selection of candidates explaining ``target`` (``(n, dof)``).

    Each step tries the named effects first and the open-ended (symbolic)
    terms only when no named effect passes: a physical effect is preferred
    where both explain the residual (a spring ``c q`` beside a model whose
    gravity absorbs ``sin q`` leaves ``c (q - sin q)``, which ``q^3`` also fits).
    ``fixed`` columns (the model's own terms and effects already accepted)
    stay in every fit, so a candidate that only repeats them gains nothing.
    Returns the newly accepted candidates, per step the statistics of the
    best candidate, accepted or not, and any structural finding.
    """
    y = target.ravel()
    n_rows = len(y)
    held = row_folds(data)
    floor = ROUNDOFF * float(np.mean(data.tau**2))
    fixed = np.zeros((n_rows, 0)) if fixed is None else fixed
    F_all = {c: c.column(data, "indirect") for c in pool if c not in exclude}
    accepted, steps, structural = [], [], []

    def design(cands):
        return np.column_stack([fixed] + [F_all[c][:, None] for c in cands]) if cands else fixed

    rss_now = fit_statistics(fixed, y)[2] if fixed.shape[1] else float(y @ y)
    # the named effects first; the open-ended terms only where no named effect passes
    tiers = [[c for c in pool if is_named(c)], [c for c in pool if not is_named(c)]]
    while True:
        if rss_now / n_rows <= floor:
            steps.append({"stop": "the residual is at round-off level", "residual_mse": rss_now / n_rows})
            break
        k_now = fixed.shape[1] + len(accepted)
        chosen = inadmissible = None
        for tier in tiers:
            ranked = []
            for c in tier:
                if c in exclude or c in accepted:
                    continue
                coef, stderr, rss = fit_statistics(design(accepted + [c]), y)
                drop = bic(rss_now, n_rows, k_now) - bic(rss, n_rows, k_now + 1)
                ranked.append({"candidate": c, "bic_drop": drop, "coef": float(coef[-1]), "stderr": float(stderr[-1]),
                               "rss": rss})
            ranked.sort(key=lambda b: -b["bic_drop"])
            for best in ranked:  # the best first; past an impossible coefficient, the next best that fits as well
                if inadmissible is not None and rss_now - best["rss"] < AS_WELL * (rss_now - inadmissible["rss"]):
                    break
                ok, stats = _passes(best, accepted, design, y, held)
                if ok and admissible(best["candidate"], best["coef"]):
                    steps.append(stats)
                    chosen = best
                    break
                if ok:
                    if inadmissible is None:
                        steps.append({**stats, "inadmissible": True})
                        inadmissible = best
                    continue
                if inadmissible is None:
                    steps.append(stats)  # the best candidate, rejected
                break  # a weaker candidate would fail as well
            if chosen is not None or inadmissible is not None:
                break  # an impossible coefficient is not handed to the open-ended terms to mimic
        if chosen is None:
            if inadmissible is not None:
                structural.append((inadmissible["candidate"], inadmissible["coef"], inadmissible["stderr"]))
            break
        accepted.append(chosen["candidate"])
        rss_now = chosen["rss"]
    return Selection(accepted, steps, structural)


def _passes(best: dict, accepted: list[Term], design, y: np.ndarray, held: list[np.ndarray]) -> tuple[bool, dict]:
    """Whether ``best`` passes the BIC, significance and held-out tests, with its statistics."""
    c = best["candidate"]
    before = cv_mse(design(accepted), y, held)
    after = cv_mse(design(accepted + [c]), y, held)
    gain = (before - after) / before if before > 0 else 0.0
    t = abs(best["coef"]) / best["stderr"] if best["stderr"] > 0 else math.inf
    ok = best["bic_drop"] > MIN_BIC_DROP and t >= MIN_T and gain >= MIN_HELDOUT_GAIN
    return ok, {"candidate": label(c), "bic_drop": best["bic_drop"], "t": t if math.isfinite(t) else None,
                "coefficient": best["coef"], "heldout_gain": gain, "accepted": ok and admissible(c, best["coef"])}
