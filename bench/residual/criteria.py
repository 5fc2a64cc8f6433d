"""What a term must pass for the residual loop's trace to accept it
(:mod:`bench.residual.tracing`).

A term is accepted only if all hold, each joint's rows weighted by the inverse
of its residual's scale where the data are independent samples or several
trajectories (:func:`joint_weights`):

* the Bayesian information criterion of the residual fit, over all training
  rows, falls by more than :data:`MIN_BIC_DROP` (strong evidence on Kass &
  Raftery's scale);
* its coefficient is at least :data:`MIN_T` standard errors from zero;
* it lowers the cross-validated mean squared residual on held-out data by at
  least :data:`MIN_HELDOUT_GAIN` of that residual: leave one trajectory out
  where the training data name several trajectories, contiguous spans of
  one trajectory or blocks of independent samples otherwise (:mod:`bench.residual.validation`; on measured trajectories
  neighbouring samples are near copies, so interleaved rows would not test
  generalisation). On independent samples (generated data, no trajectory)
  a smaller gain is enough where it is :data:`MIN_HELDOUT_CHI2` in units of
  the held-out noise (``gain * rows >= MIN_HELDOUT_CHI2``): at high noise a
  real effect's share of the residual is small (viscous friction beside a
  Coulomb level that took most of it, at 5 % noise: a chi-squared of 25 over
  8,000 rows, 0.3 % of the residual), and each row there is a sample of its
  own. A trajectory's rows are not independent, so there the share stays;
* the residual is above the floor of numerical round-off
  (:data:`ROUNDOFF` of the torque's mean square), so a model that already
  fits exactly is left alone;
* its coefficient is physical (:func:`~bench.residual.library.admissible`:
  no negative friction, damping, rotor inertia or stiffness). Where the best
  term of a step passes the other tests with an impossible coefficient,
  the best admissible one that passes them and fits as well (removes at
  least :data:`AS_WELL` of the residual sum of squares the best removes) is
  taken instead; where none does, the step makes a *structural finding*: the
  declared form lacks this freedom, and no term is added for it. The
  finding's column stays in the later steps' fits (and in no model), so no
  admissible term is accepted for mimicking it, while other effects still can be.

Noise alone fails the first two tests: with Gaussian residuals, a useless
column lowers ``n log RSS`` by a chi-squared(1) amount, and ``log n`` plus the
drop of 10 asks for a chi-squared value above 20 (p < 1e-5 per term).
"""

from __future__ import annotations

import math

import numpy as np

from bench.core.data import Dataset
from bench.physics.terms import Term
from bench.residual.library import label

MIN_BIC_DROP = 10.0
MIN_T = 5.0
MIN_HELDOUT_GAIN = 0.01
#: on independent samples, a held-out gain this many rows' worth of residual is enough (see the module docstring)
MIN_HELDOUT_CHI2 = MIN_BIC_DROP
ROUNDOFF = 1e-20
#: the largest ratio of two joints' weights (:func:`joint_weights`)
MAX_WEIGHT_RATIO = 1000.0
#: an admissible term replaces a better one with an impossible coefficient
#: only if it removes at least this share of what that one removes
AS_WELL = 0.9


def joint_weights(y: np.ndarray, basis: np.ndarray, data: Dataset) -> np.ndarray:
    """One weight a row of ``y`` (``tau.ravel()`` of ``data``: a row a joint and sample): the inverse
    of its joint's root mean square residual off the orthonormal ``basis``, the
    weighted least squares of robot identification (Gautier & Poignet 2001; Khalil &
    Dombre 2002, the identification chapters), each joint's equations scaled by
    its error's standard deviation, so that the BIC, the significance and the
    held-out error see each joint's residual in its own units. A joint's error
    is taken at least :data:`MAX_WEIGHT_RATIO` times smaller than the largest,
    so that one fitted to round-off is not magnified without bound.

    On data that hold one trajectory every weight is 1: the weights, read off
    the residual, let a joint with small torques carry laws the pooled fit would
    not, and on independent samples each row is a sample of its own, on several
    trajectories a held-out trajectory confirms such a law on motion it was not
    fitted on; one trajectory's rows are neither, and the loop's other laws that
    no held-out trajectory can confirm (:func:`~bench.residual.beyond_data.held_out_verdict`)
    are not kept there either."""
    if len(data.trajectories()) == 1:
        return np.ones_like(y)
    dof = data.dof
    r = (y - basis @ (basis.T @ y)).reshape(-1, dof) if basis.shape[1] else y.reshape(-1, dof)
    sigma = np.sqrt(np.mean(r**2, axis=0))
    top = float(sigma.max())
    if not top > 0:
        return np.ones_like(y)
    sigma = np.maximum(sigma, top / MAX_WEIGHT_RATIO)
    return np.tile(top / sigma, len(y) // dof)


def bic(rss: float, n: int, k: int) -> float:
    """The Bayesian information criterion of a Gaussian fit with ``k`` columns to ``n`` rows."""
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def slot(term: Term):
    """What a term occupies: a shaped effect's name and joints (one
    Stribeck hump a joint, whatever its velocity), else the term itself."""
    return (term.name, term.joints) if term.shape is not None else term


def passes(best: dict, gain_of, min_gain: float = MIN_HELDOUT_GAIN) -> tuple[bool, dict]:
    """Whether ``best`` passes the BIC, significance and held-out tests
    (``gain_of(group)``: the share of the held-out error that the group's columns
    save beside the design; ``min_gain``: the share it must save), with its statistics."""
    if not (best["bic_drop"] > MIN_BIC_DROP):  # the cheap test first
        return False, {"term": " + ".join(label(t) for t in best["group"]), "bic_drop": best["bic_drop"],
                       "coefficient": best["coef"], "accepted": False}
    gain = gain_of(best["group"])
    t = abs(best["coef"]) / best["stderr"] if best["stderr"] > 0 else math.inf
    ok = best["bic_drop"] > MIN_BIC_DROP and t >= MIN_T and gain >= min_gain
    info = {"term": " + ".join(label(t) for t in best["group"]), "bic_drop": best["bic_drop"],
            "t": t if math.isfinite(t) else None, "coefficient": best["coef"], "heldout_gain": gain, "accepted": False}
    return ok, info
