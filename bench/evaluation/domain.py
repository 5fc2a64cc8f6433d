"""How far a choice made by validation can be trusted: the distance its folds
reached against the distance its use will ask for.

Distances are those of :class:`bench.core.distance.TrainingStates`: to the
nearest fitted state in ``(q, qd)``, each coordinate in the fitted states'
standard deviations; each figure is a median over the samples.

* **reach**: each validation fold's scored samples, from the states that fold
  is fitted on; the median over the folds;
* **target**: what the model will be asked: the states of a trajectory the
  user names (``--target-states``: its positions and velocities only), from
  the training states; else, where the training data hold several
  trajectories, the spread between them (each trajectory from the others'
  states; their median); else nothing, and the report says so (why not the
  arm's joint ranges: docs/choices.md, "No default target on one trajectory");
* **validated at the target's distance** where the folds reached at least
  as far as the target lies.

:func:`domain` gives the report as ``select.json`` holds it and
:func:`sentences` as the page says it.
"""

from __future__ import annotations

import numpy as np

from bench.core.data import Dataset
from bench.core.distance import TrainingStates
from bench.core.folds import Folds

#: where the training data hold one trajectory and no target is named
NO_TARGET = ("the training data hold one trajectory and no target was named (--target-states LOG): nothing says "
             "how far the next trajectory will lie from them")


def _median_distance(fitted: Dataset, asked: Dataset) -> float:
    return float(np.median(TrainingStates(fitted).distance(asked)))


def held_out_distances(train: Dataset, fold) -> np.ndarray:
    """Each of ``fold``'s scored samples' distance from the nearest state the fold is fitted on."""
    return TrainingStates(train.subset(np.flatnonzero(fold.fit))).distance(train.subset(np.flatnonzero(fold.score)))


def reach(train: Dataset, folds: Folds) -> list[float]:
    """Each fold's scored samples' median distance from the states the fold is fitted on."""
    return [float(np.median(held_out_distances(train, f))) for f in folds]


def spread(train: Dataset) -> list[float] | None:
    """Each training trajectory's median distance from the other trajectories' states;
    ``None`` where the data hold fewer than two trajectories."""
    names = train.trajectories()
    if not names or len(names) < 2:
        return None
    labels = train.trajectory_labels()
    return [_median_distance(train.subset(np.flatnonzero(labels != name)), train.subset(np.flatnonzero(labels == name)))
            for name in names]


def domain(train: Dataset, folds: Folds, target: Dataset | None = None, target_source: str | None = None) -> dict:
    """The report: ``reach`` (per fold and their median), ``target`` (its median distance,
    what it is, and per trajectory for the spread), and ``validated_at_target``
    (``None`` where there is no target)."""
    per_fold = reach(train, folds)
    reached = float(np.median(per_fold))
    if target is not None:
        kind, distances = f"the states of {target_source or target.source} (positions and velocities only)", None
        distance = _median_distance(train, target)
    else:
        distances = spread(train)
        kind = None if distances is None else "the spread between the training trajectories"
        distance = None if distances is None else float(np.median(distances))
    return {"reach": {"per_fold": per_fold, "median": reached, "folds": folds.describe()},
            "target": None if distance is None else {"what": kind, "median_distance": distance,
                                                      "per_trajectory": distances},
            "validated_at_target": None if distance is None else bool(reached >= distance),
            "note": NO_TARGET if distance is None else None}


def sentences(report: dict) -> str:
    """The report in words, for a page."""
    reached = report["reach"]
    text = (f"Validation's folds ({reached['folds']}) scored samples a median "
            f"{reached['median']:.3g} training standard deviations (in q and q̇) from the states each fold was fitted "
            f"on. ")
    target = report["target"]
    if target is None:
        return text + report["note"][0].upper() + report["note"][1:] + "."
    verdict = ("so the choice was validated at the target's distance" if report["validated_at_target"] else
               "so the choice was **not** validated at the target's distance: validation compared the candidates on "
               "states closer to what they were fitted on than the target lies")
    return text + (f"The target, {target['what']}, lies a median {target['median_distance']:.3g} from the training "
                   f"states, {verdict}.")
