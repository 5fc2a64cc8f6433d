"""Where each learner stops generalising on a measured arm: test MSE against the
distance from the training states.

For each test sample, its distance from the training states is the distance
to the nearest of them in the space of ``(q, qd)``, each coordinate in
training standard deviations (:class:`bench.core.distance.TrainingStates`).
The test samples are cut into :data:`BINS` bins of equal count by that
distance; each learner's torque MSE is computed in each bin, and so are the
standard model's (SysId's ``standard`` configuration) and the constant's
(each joint's training-mean torque). Each learner is fitted once (seed
``--seed``) in its own process through the runner, under ``--budget`` seconds
or ``--steps`` of its work; one seed shows where a learner's error grows, not
its spread over seeds (the matrices' tables give that). For each split the
page gets a table and a plot. Usage::

    python -m bench study generalisation [--system kuka_lwr4] [--splits default swapped] \\
        [--methods sysid delan mlp feasible+gp ...] [--budget 60] [--out results/measured/generalisation.md]
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.core.scoring import scoring
from bench.core.arguments import positive, positive_int, seed, add_workers
from bench.core.budget import Budget
from bench.core.distance import TrainingStates
from bench.core.fileio import atomic_write, check_output, write_json
from bench.evaluation.reference import CONFIGURATION, METHOD as STANDARD_METHOD
from bench.reporting.plots import line_plot
from bench.runner.job import KILL_FACTOR, CaseJob
from bench.runner.schedule import run_jobs
from bench.runner.ledger import Ledger
from bench.runner.progress import print_now
from bench.runner.provenance import made_at, provenance
from methods import METHODS
from systems import SYSTEMS

#: test samples are cut into this many bins of equal count by their distance from the training states
BINS = 6
#: the two references every split's table carries beside the learners
STANDARD, CONSTANT = "standard model", "constant"
METHODS_DEFAULT = ["sysid", "delan", "mlp", "syrenets", "mggp", "standard+gp", "feasible+gp", "standard+mlp",
                   "feasible+delan"]


def split_data(system: str, split: str):
    """A measured system's split (``default`` or a named one), its training and its test data."""
    s = SYSTEMS[system](split=None if split == "default" else split)
    return s, s.load("train"), s.load("test")


def edges(system: str, split: str) -> list[float]:
    """The bins' edges in distance: quantiles of the test samples' distances."""
    _, train, test = split_data(system, split)
    d = TrainingStates(train).distance(test)
    return [float(x) for x in np.quantile(d, np.linspace(0, 1, BINS + 1))]


def run_case(system: str, split: str, method: str, seed: int, budget: float | None, steps: int | None) -> dict:
    """One learner (or reference) on one split: its test MSE, and its MSE in each distance bin."""
    s, train, test = split_data(system, split)
    start = time.perf_counter()
    if method == CONSTANT:
        tau, done = np.broadcast_to(train.tau.mean(axis=0), (len(test), test.dof)), None
    else:
        name, config = (STANDARD_METHOD, CONFIGURATION) if method == STANDARD else (method, "default")
        work = Budget(steps=1) if method == STANDARD else Budget(seconds=budget, steps=steps)
        model = METHODS[name](**METHODS[name].configuration(config)).fit(train, "indirect", seed, work, system=s)
        tau, done = model.predict_torque(test), model.fit_info.get("steps")
    with scoring():  # the test split, read to score
        error = np.mean((tau - test.tau) ** 2, axis=1)
    distance = TrainingStates(train).distance(test)
    cut = np.asarray(edges(system, split))
    which = np.clip(np.searchsorted(cut, distance, side="right") - 1, 0, BINS - 1)
    return {"system": system, "split": split, "method": method, "seed": seed, "steps": done,
            "test_mse": float(np.mean(error)), "seconds": time.perf_counter() - start,
            "bins": [{"mse": float(np.mean(error[which == k])) if np.any(which == k) else None,
                      "distance": float(np.median(distance[which == k])) if np.any(which == k) else None,
                      "samples": int(np.sum(which == k))} for k in range(BINS)]}


@dataclass(frozen=True)
class Case(CaseJob):
    """One learner (or reference) on one split in its own process (:func:`run_case`),
    killed at 1.5 x its time budget plus 300 s for its predictions (under a work budget, never)."""

    system: str
    split: str
    method: str
    seed: int
    budget: float | None
    steps: int | None

    def run_limit(self) -> float:
        return math.inf if self.steps is not None else KILL_FACTOR * self.budget + 300.0

    def compute(self) -> dict:
        return run_case(**self.payload())


#: the subcommand's one-line help


def add_arguments(parser) -> None:
    parser.add_argument("--system", default="kuka_lwr4", help="a measured arm (default kuka_lwr4)")
    parser.add_argument("--splits", nargs="+", default=["default", "swapped"], help="its splits (default both)")
    parser.add_argument("--methods", nargs="+", default=METHODS_DEFAULT,
                        help=f"learners, hybrids included (default {' '.join(METHODS_DEFAULT)})")
    parser.add_argument("--seed", type=seed, default=0, help="each learner's seed (default 0)")
    parser.add_argument("--budget", type=positive, default=None, help="seconds for each fit (default 60)")
    parser.add_argument("--steps", type=positive_int, default=None,
                        help="bound each fit by N steps of its work instead (--budget is then a ceiling)")
    add_workers(parser, "fits")
    parser.add_argument("--out", type=Path, default=Path("results/measured/generalisation.md"),
                        help="the page (default results/measured/generalisation.md); the runs go beside it as .json, "
                             "each split's plot as _SPLIT.png")


def table(rows: list[dict]) -> str:
    """One split's table: a learner a row, its MSE in each distance bin and over the whole test set."""
    bins = rows[0]["bins"]
    head = "| learner | " + " | ".join(f"bin {k + 1}: d ≈ {b['distance']:.2g} ({b['samples']})" for k, b in enumerate(bins)) \
        + " | all |"
    lines = [head, "|---|" + "---:|" * (len(bins) + 1)]
    for r in rows:
        lines.append(f"| {r['method']} | " + " | ".join("—" if b["mse"] is None else f"{b['mse']:.3g}" for b in r["bins"])
                     + f" | {r['test_mse']:.3g} |")
    return "\n".join(lines)


def main(args) -> int:
    check_output(args.out)
    if args.budget is None and args.steps is None:
        args.budget = 60.0
    for method in args.methods:
        METHODS.entry(method)  # an unknown name: one line, before any fit
    names = [STANDARD, CONSTANT] + list(args.methods)
    jobs = {f"{split} {m}": Case(args.system, split, m, args.seed, args.budget, args.steps)
            for split in args.splits for m in names}
    ledger = Ledger(args.out)
    rows = list(run_jobs(jobs, args.workers, lambda r: f"test MSE {r['test_mse']:.3g}", print_now, ledger,
                          cluster=args.cluster).values())
    prov = provenance()
    work = f"{args.steps} steps of its work" if args.steps is not None else f"{args.budget:g} s"
    lines = ["# Where each learner stops generalising", "",
             f"Generated by `{args.invocation}` ({made_at(prov)}"
             f"); every fit is in [{args.out.with_suffix('.json').name}]"
             f"({args.out.with_suffix('.json').name}).", "",
             f"`{args.system}`: each learner fitted once (seed {args.seed}, {work}) on the split's training trajectory "
             f"and scored on its test trajectory. Each test sample's distance from the training states is the "
             f"distance to the nearest of them in (q, q̇), each coordinate in training standard deviations "
             f"([bench/core/distance.py](../../bench/core/distance.py)); the test samples are cut into {BINS} bins "
             f"of equal count by it (d: the bin's median distance; in brackets its samples), and each cell is the "
             f"torque MSE (N²m²) in that bin. The standard model is SysId's `standard` configuration; the constant "
             f"is each joint's training-mean torque. One seed shows where a learner's error grows, not its spread.", ""]
    for split in args.splits:
        mine = [r for r in rows if r["split"] == split]
        plot = args.out.with_name(f"{args.out.stem}_{split}.png")
        line_plot({r["method"]: [(b["distance"], b["mse"]) for b in r["bins"] if b["mse"] is not None] for r in mine},
                  plot, xlabel="distance from the training states (training standard deviations)",
                  ylabel="test torque MSE (N²m²)", title=f"{args.system}, split {split}")
        lines += [f"## Split {split}", "", table(mine), "", f"![test MSE against distance, split {split}]({plot.name})",
                  ""]
    write_json(args.out.with_suffix(".json"), rows)
    atomic_write(args.out, lambda f: f.write("\n".join(lines)))
    ledger.close()
    print("\n".join(lines))
    return 0
