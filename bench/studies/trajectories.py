"""What a measured arm's trajectories let validation see: how far the test
trajectory lies from the training states, and how far the samples each
validation fold scores lie from the states that fold is fitted on.

Distances are those of :class:`bench.core.distance.TrainingStates`: to the
nearest state in ``(q, qd)``, each coordinate in the fitted states' standard
deviations. The folds are the suite's one validation protocol
(:func:`bench.core.folds.folds`) on the split's training data, with the gap
and the torque's integrated autocorrelation time it is cut by. No model is
fitted: the figures are the data's own, the same on any machine. Usage::

    python -m bench study trajectories [--system kuka_lwr4] [--splits default swapped] \\
        [--out results/measured/trajectories.json]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.core.distance import TrainingStates
from bench.core.fileio import check_output, write_json
from bench.core.folds import folds
from bench.runner.provenance import provenance
from bench.studies.generalisation import split_data
from systems import SYSTEMS

HELP = "how far a measured arm's test trajectory and its validation folds lie from the states they were fitted on"


def split_figures(system: str, split: str) -> dict:
    """One split's figures: the test trajectory's and each fold's median distance, the folds' gap."""
    _, train, test = split_data(system, split)
    cut = folds(train)
    per_fold = [float(np.median(TrainingStates(train.subset(np.flatnonzero(f.fit)))
                                .distance(train.subset(np.flatnonzero(f.score))))) for f in cut]
    return {"split": split, "train_samples": len(train), "test_samples": len(test),
            "test_median_distance": float(np.median(TrainingStates(train).distance(test))),
            "folds": cut.to_json(), "fold_median_distance": per_fold,
            "fold_median_distance_median": float(np.median(per_fold))}


def add_arguments(parser) -> None:
    parser.add_argument("--system", default="kuka_lwr4", help="a measured arm (default kuka_lwr4)")
    parser.add_argument("--splits", nargs="+", default=["default", "swapped"], help="its splits (default both)")
    parser.add_argument("--out", type=Path, default=Path("results/measured/trajectories.json"),
                        help="the JSON it writes (default results/measured/trajectories.json)")


def main(args) -> int:
    check_output(args.out)
    SYSTEMS.entry(args.system)  # an unknown name: one line naming the known systems
    out = {"system": args.system, "command": args.invocation, "provenance": provenance(),
           "splits": {split: split_figures(args.system, split) for split in args.splits}}
    write_json(args.out, out)
    for split, f in out["splits"].items():
        print(f"{args.system}, split {split}: test trajectory a median {f['test_median_distance']:.3g} from its "
              f"training states; {f['folds']['description']}; the scored samples of each fold a median "
              f"{', '.join(f'{d:.2g}' for d in f['fold_median_distance'])} from the states it is fitted on")
    return 0
