"""What a measured arm's trajectories let validation see: how far the test
trajectory lies from the training states, and how far the samples each
validation fold scores lie from the states that fold is fitted on: the
protocol's spans in time, and the regions of the states that ``bench select``
folds one trajectory into. Beside them, how far the arm's joint ranges lie
(:func:`joint_ranges`: the target a user without a second trajectory might
name), on the arm's splits and, with ``--generated``, on the selection
benchmark's one-trajectory cases (:mod:`bench.studies.selection_benchmark`).

Distances are those of :class:`bench.core.distance.TrainingStates`: to the
nearest state in ``(q, qd)``, each coordinate in the fitted states' standard
deviations. The folds are the suite's one validation protocol
(:func:`bench.core.folds.folds`) on the split's training data, with the gap
and the torque's integrated autocorrelation time it is cut by. No model is
fitted: the figures are the data's own, the same on any machine. Usage::

    python -m bench study trajectories [--system kuka_lwr4] [--splits default swapped] \\
        [--generated development evaluation] [--out results/measured/trajectories.json]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from bench.core.data import Dataset
from bench.core.distance import TrainingStates
from bench.core.fileio import check_output, write_json
from bench.core.folds import folds
from bench.core.protocols import folds as protocol_folds
from bench.evaluation.domain import reach
from bench.evaluation.tuning import MAX_FOLDS
from bench.runner.plugins import register_by_file
from bench.runner.provenance import provenance
from bench.studies.generalisation import split_data
from bench.studies.selection_benchmark import DEVELOPMENT, EVALUATION, cases, make
from systems import SYSTEMS


#: states drawn over the arm's joint ranges (:func:`joint_ranges`), from this seed
RANGE_SAMPLES, RANGE_SEED = 4000, 0


def joint_ranges(system, n: int = RANGE_SAMPLES, seed: int = RANGE_SEED) -> Dataset:
    """States uniform over ``system``'s own sampling domain: an arm's angles inside its limits (less 5 % at
    each end) and its velocities within half their limits (:mod:`systems.urdf_arm`)."""
    rng = np.random.default_rng(seed)
    dof, domain = system.dof, system.default_domain
    q, qd = (rng.uniform(*domain.bounds(name, dof), size=(n, dof)) for name in ("q", "qd"))
    zeros = np.zeros((n, dof))
    return Dataset(q, qd, zeros, zeros)


def figures(system, train: Dataset, test: Dataset) -> dict:
    """The test trajectory's, the joint ranges' and each fold's median distance (spans in time, and select's
    regions of one trajectory), and the spans' gap."""
    states = TrainingStates(train)
    cut = folds(train)
    per_fold = reach(train, cut)
    regions = reach(train, protocol_folds(train, "regions", MAX_FOLDS))
    return {"train_samples": len(train), "test_samples": len(test),
            "test_median_distance": float(np.median(states.distance(test))),
            "joint_ranges_median_distance": float(np.median(states.distance(joint_ranges(system)))),
            "folds": cut.to_json(), "fold_median_distance": per_fold,
            "fold_median_distance_median": float(np.median(per_fold)),
            "regions_median_distance": regions, "regions_median_distance_median": float(np.median(regions))}


def split_figures(system: str, split: str) -> dict:
    """One split's :func:`figures`."""
    arm, train, test = split_data(system, split)
    return {"split": split, **figures(arm, train, test)}


def generated_figures(which: str) -> list[dict]:
    """:func:`figures` of each one-trajectory case of the selection benchmark's set ``which``, its recordings
    made as the benchmark makes them (into a scratch folder)."""
    out = []
    with tempfile.TemporaryDirectory(prefix="bench-trajectories-") as scratch:
        for case in cases(which):
            if case.layout != "one":
                continue
            arm = SYSTEMS[register_by_file(f"measured:{make(case, Path(scratch) / case.name)}")]()
            out.append({"set": which, "case": case.name, **figures(arm, arm.load("train"), arm.load("test"))})
    return out


def add_arguments(parser) -> None:
    parser.add_argument("--system", default="kuka_lwr4", help="a measured arm (default kuka_lwr4)")
    parser.add_argument("--splits", nargs="+", default=["default", "swapped"], help="its splits (default both)")
    parser.add_argument("--generated", nargs="*", choices=[DEVELOPMENT, EVALUATION], default=[],
                        help="also the one-trajectory cases of these sets of the selection benchmark (default none)")
    parser.add_argument("--out", type=Path, default=Path("results/measured/trajectories.json"),
                        help="the JSON it writes (default results/measured/trajectories.json)")


def main(args) -> int:
    check_output(args.out)
    SYSTEMS.entry(args.system)  # an unknown name: one line naming the known systems
    out = {"system": args.system, "command": args.invocation, "provenance": provenance(),
           "splits": {split: split_figures(args.system, split) for split in args.splits},
           "generated": [row for which in args.generated for row in generated_figures(which)]}
    write_json(args.out, out)
    for split, f in out["splits"].items():
        print(f"{args.system}, split {split}: test trajectory a median {f['test_median_distance']:.3g} from its "
              f"training states; {f['folds']['description']}; the scored samples of each fold a median "
              f"{', '.join(f'{d:.2g}' for d in f['fold_median_distance'])} from the states it is fitted on; "
              f"select's regions reach {f['regions_median_distance_median']:.3g}; the joint ranges lie "
              f"{f['joint_ranges_median_distance']:.3g}")
    for f in out["generated"]:
        print(f"{f['case']} ({f['set']}): test {f['test_median_distance']:.3g}, regions reach "
              f"{f['regions_median_distance_median']:.3g}, joint ranges {f['joint_ranges_median_distance']:.3g}")
    return 0
