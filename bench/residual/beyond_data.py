"""What a law may claim beyond the data it was fitted on.

A law fitted on one trajectory can fit that trajectory and not the arm: a
spring whose rest angle lies where the arm never went, or an open-ended term
(``qd_j^4 / 4``, a term of ``L`` from the library) that bends the fit to the
motion it saw. Such an effect *claims beyond the data*
(:func:`beyond_data`):

* every open-ended term;
* a spring on a joint whose rest angle lies outside the joint's recorded
  range: ``-tau_0 / k`` with the offset ``tau_0`` on its joint (the
  offset-spring law), else 0;
* a periodic torque (its sine and cosine parts): along one trajectory a
  joint's position is a function of time, so two coefficients and a choice
  of N among a dozen fit a smooth share of any residual the trajectory
  leaves, cogging or not.

An effect whose standard error is at least its value is not identified by
the data at all (:func:`not_identified`): it is dropped and reported the
same way, whatever the trajectories.

An effect that claims beyond the data stays in the model only if it earns
its place on a trajectory it was not fitted on (:func:`held_out_verdict`,
the test the laws of the sensor and the drive pass too): with the training
data's trajectories left out one at a time (:mod:`bench.residual.validation`),
the model without it must have a held-out error at least :data:`MIN_GAIN`
higher than with it.
Independent samples (generated data) have no trajectory to overfit, and the
loop's held-out blocks have judged the effect already. Training data that
hold one trajectory have no other to judge by, so there such an effect
never stays: the loop drops it, reports it as a finding with
its fitted value and the reason, and does not offer it again. (A law of
the sensor or the drive, of a fixed form, is judged there on held-out
regions of the trajectory's states instead.)
"""

from __future__ import annotations

from typing import Callable

from bench.core.data import Dataset
from bench.physics.effects import EFFECTS
from bench.residual.library import is_named, label, law_text
from bench.residual.checks import heldout
from bench.residual.model import LoopModel
from bench.residual.strategies import Strategy

#: the held-out error an effect that claims beyond the data, or a law of the sensor or the drive, must save,
#: as a fraction of the error without it
MIN_GAIN = 0.01


def beyond_data(model: LoopModel, train: Dataset) -> list[tuple[int, str]]:
    """The effects of ``model`` (by index) that claim beyond the training data, each with why."""
    out = []
    low, high = train.q.min(axis=0), train.q.max(axis=0)
    index = {(t.name, t.joint): i for i, t in enumerate(model.effects)}
    for i, term in enumerate(model.effects):
        if not is_named(term):
            out.append((i, f"an open-ended term, {term.name}"))
        elif EFFECTS[term.name].grid is not None:
            out.append((i, f"a periodic torque ({label(term)}), which one trajectory cannot tell from a function of time"))
        elif term.name == "spring" and term.joint is not None:
            j = term.joint
            offset = index.get(("offset", j))
            k = model.coef[i]
            rest = -model.coef[offset] / k if offset is not None and k else 0.0
            if not low[j] <= rest <= high[j]:
                out.append((i, f"a spring whose rest angle {rest:.3g} rad lies outside joint {j + 1}'s recorded range "
                               f"[{low[j]:.3g}, {high[j]:.3g}]"))
    return out


def not_identified(model: LoopModel) -> list[tuple[int, str]]:
    """The effects of ``model`` (by index) whose standard error is at least their value, each with why."""
    return [(i, f"not identified: its standard error {se:.2g} is at least its value {c:.4g}")
            for i, (c, se) in enumerate(zip(model.coef, model.stderr)) if se > 0 and se >= abs(c)]


def held_out_verdict(train: Dataset, errors: Callable[[], tuple[float, float]], *, regions: bool = False):
    """The one test a law that may fit its own trajectory rather than the arm
    must pass to stay: an effect that claims beyond the data
    (:func:`earns_place`) and a law of the sensor or the drive
    (:func:`bench.residual.sensors.confine`). ``errors()`` gives the held-out
    errors over the loop's folds (:mod:`bench.residual.validation`: whole
    trajectories, or regions of the states of one) with the law and without
    it; without it the error must be at least :data:`MIN_GAIN` higher.
    Training data without trajectories (independent samples) have none to
    overfit, and the law stays. On data that hold one trajectory, a law of a
    fixed form (``regions``: a sensor's gain, load-dependent friction, a
    time shift, each of one parameter) is judged on held-out regions of
    its states, where it must predict torques it was not fitted on; an effect
    that claims beyond the data has no other trajectory to judge by, and
    never stays: a periodic torque's period and an open-ended term are chosen
    among many on all of the trajectory, which its regions then cannot judge,
    and a spring's rest angle lies where no region reaches. Returns ``(None,
    errors)`` where it stays, else ``(verdict in words, errors)``; ``errors``
    is ``None`` where they were not needed."""
    names = train.trajectories()
    if not names:
        return None, None
    if len(names) < 2 and not regions:
        return "the training data hold one trajectory, so no held-out trajectory can confirm it", None
    kept, dropped = errors()
    if dropped >= (1 + MIN_GAIN) * kept:
        return None, (kept, dropped)
    where = "held-out trajectories" if len(names) >= 2 else "held-out regions of its one trajectory's states"
    return f"on {where} it does not pay: held-out MSE {kept:.4g} with it, {dropped:.4g} without", (kept, dropped)


def earns_place(strategy: Strategy, model: LoopModel, train: Dataset, index: int) -> tuple[bool, str]:
    """Whether effect ``index`` of ``model`` earns its place on held-out
    trajectories (:func:`held_out_verdict`); and the verdict, in words, where
    it does not. Independent samples (generated data, no recordings): the
    loop's held-out blocks, which accepted the effect, are other samples of
    the same domain, and the effect stays."""
    def errors():
        without = strategy.refit(model, train, [t for k, t in enumerate(model.effects) if k != index])
        return heldout(strategy, model, train), heldout(strategy, without, train)

    verdict, _ = held_out_verdict(train, errors)
    return verdict is None, verdict or ""


def finding(term, coefficient: float, stderr: float, why: str, verdict: str) -> dict:
    """The JSON entry of an effect dropped because it claims beyond the data."""
    parameter = EFFECTS[term.name].parameter if is_named(term) else "c"
    entry = {"name": term.name if is_named(term) else "symbolic", "kind": "beyond_data" if verdict else "not_identified",
             "law": law_text(term, parameter), "joints": [j + 1 for j in term.joints], "parameters": {},
             "finding": (f"{label(term)} fits the training data with {parameter} = {coefficient:.4g} ± {stderr:.2g}, "
                         f"but it is {why}{', and ' + verdict if verdict else ''}: reported, not added")}
    if not is_named(term):
        entry["expression"] = term.name
    return entry
