"""Measure the residual loop on the DFKI robot's measured recordings.

Two kinds of split, each loop in its own process through the runner:

* the suite's split: trained on recordings 00, 01, 02 and 04, tested on 03
  and 05 (``python -m bench residual --system dfki_double_pendulum``), at
  ``--budget`` seconds, one loop at a time so that its wall time is its own;
* leave one recording out over all six: trained on five, tested on the
  sixth, at ``--loro-budget`` seconds, ``--workers`` loops at a time.

For each run the table gives the test torque MSE before and after the loop,
their ratio, the effects it added, the structural findings, its wall time
and the part of it spent in the loop's statistics. The lab's identified
model (rigid body, rotor inertia, viscous and Coulomb friction) has a test
MSE of 0.0177 on the suite's split. Usage::

    python -m bench study residual-dfki [--methods sysid sparse ...] [--budget 60] [--loro-budget 30] [--out results/residual/dfki.md]
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.core.sealed import seal
from bench.core.budget import Budget
from bench.core.arguments import positive, positive_int, add_workers
from bench.core.fileio import atomic_write, check_output, link
from bench.residual import validation
from bench.residual.loop import residual_loop
from bench.runner.job import CaseJob, fit_limit
from bench.runner.schedule import run_jobs
from bench.runner.ledger import Ledger
from bench.runner.progress import print_now, quiet
from bench.runner.provenance import made_at, provenance
from systems import SYSTEMS
from systems.dfki_double_pendulum import CUTOFF_HZ, DECLARATION

SYSTEM = "dfki_double_pendulum"
METHODS_DEFAULT = ["sysid", "sparse", "mlp", "syrenets", "mggp"]
#: the lab's identified model's test torque MSE on the suite's split (results/measured/dfki_filter.md)
LAB_MSE = 0.0177


def split(held_out: str | None):
    """``(train, test)``: the suite's split, or every recording but ``held_out`` and that one."""
    system = SYSTEMS[SYSTEM]()
    if held_out is None:
        return system.load("train"), system.load("test")
    every = system.load("all")
    out = every.recording == held_out
    return every.subset(np.flatnonzero(~out)), seal(every.subset(np.flatnonzero(out)))


def run_case(method: str, held_out: str | None, budget: float | None, seed: int = 0, steps: int | None = None) -> dict:
    """One loop: ``method`` on the split that holds out ``held_out`` (``None``: the suite's),
    within ``budget`` seconds or, with ``steps``, that work budget (:func:`bench.residual.residual_loop`)."""
    train, test = split(held_out)
    start = time.perf_counter()
    out = residual_loop(method, train, test, budget=Budget(seconds=budget, steps=steps), seed=seed, report=quiet)

    def name(e):
        what = e["expression"] if e["name"] == "symbolic" else e["name"]
        return f"{what} j{'-'.join(map(str, e['joints']))}"

    return {
        "method": method, "held_out": held_out, "budget": budget, "steps": steps,
        "cut_short": sum(_cut_short(r) for r in out.rounds),
        "before": out.mse_before["test"], "after": out.mse_after["test"],
        "effects": [name(e) for e in out.effects if e["kind"] != "structural"],
        "findings": [name(e) for e in out.effects if e["kind"] == "structural"],
        "seconds": time.perf_counter() - start, "statistics_seconds": out.statistics_seconds,
        "mass_matrix_positive_definite": out.mass_matrix["positive_definite"],
    }


@dataclass(frozen=True)
class Loop(CaseJob):
    """One loop in its own process (:func:`run_case`), killed at
    :func:`~bench.runner.job.fit_limit` of its budget (a work budget's ceiling)."""

    method: str
    held_out: str | None
    budget: float
    steps: int | None

    def run_limit(self) -> float:
        return fit_limit(Budget(seconds=self.budget, steps=self.steps))

    def compute(self) -> dict:
        return run_case(**self.payload())


def _cut_short(entry: dict) -> bool:
    """Whether a round of the loop's JSON was cut short by its time budget."""
    stops = [entry.get("stop") or ""] + [step.get("stop") or "" for step in entry.get("trace", [])]
    return any("budget" in stop for stop in stops)


def table(rows: list[dict]) -> str:
    lines = [
        "| held out | method | test MSE before | after | after ÷ before | effects added | structural findings "
        "| rounds cut short by the budget | seconds | of which statistics |",
        "|---|---|---:|---:|---:|---|---|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['held_out'] or '03, 05 (suite)'} | {r['method']} | {r['before']:.4g} | {r['after']:.4g} "
            f"| {r['after'] / r['before']:.3f} | {', '.join(r['effects']) or 'nothing'} "
            f"| {', '.join(r['findings']) or '—'} | {r.get('cut_short', '—')} | {r['seconds']:.1f} "
            f"| {r['statistics_seconds']:.2f} |"
        )
    return "\n".join(lines)


def summary(rows: list[dict], methods: list[str]) -> str:
    lines = ["| method | runs | after ≤ before | worst after ÷ before | median after ÷ before |", "|---|---:|---:|---:|---:|"]
    for m in methods:
        ratios = [r["after"] / r["before"] for r in rows if r["method"] == m]
        if ratios:
            lines.append(f"| {m} | {len(ratios)} | {sum(x <= 1 for x in ratios)} | {max(ratios):.3f} "
                         f"| {float(np.median(ratios)):.3f} |")
    return "\n".join(lines)


#: the subcommand's one-line help


def add_arguments(parser) -> None:
    parser.add_argument("--methods", nargs="+", default=METHODS_DEFAULT, help=f"methods (default {' '.join(METHODS_DEFAULT)})")
    parser.add_argument("--budget", type=positive, default=60.0, help="seconds for each loop on the suite's split (default 60)")
    parser.add_argument("--loro-budget", type=positive, default=30.0,
                        help="seconds for each loop that leaves one recording out (default 30)")
    parser.add_argument("--steps", type=positive_int, default=None,
                        help="bound each loop by N steps of its method's work instead of by time (the budgets are "
                             "then ceilings): the same command gives the same effects on any machine")
    add_workers(parser, "leave-one-out loops")
    parser.add_argument("--out", type=Path, default=Path("results/residual/dfki.md"),
                        help="the tables to write (default results/residual/dfki.md)")


def informed_line(recordings) -> str:
    """What a leave-one-recording-out row rests on: the rows holding out a recording that the filter's
    cut-off was chosen on (``[filter] chosen_on`` in the declaration:
    :meth:`systems.measured.MeasuredSpec.chose_filter`) are test-informed."""
    informed = DECLARATION.chose_filter(recordings)
    clean = sorted(set(recordings) - set(informed))
    return (f"**Test-informed:** the rows holding out {', '.join(informed)} rest on a choice that read the held-out "
            f"recording's torques: the pre-processing's {CUTOFF_HZ:g} Hz low-pass cut-off was chosen with each of them "
            "held out "
            "in turn (`python -m bench study dfki-filter`, docs/choices.md). The rows holding out "
            f"{', '.join(clean) or 'none'} do not." if informed else "")


def main(args) -> int:
    check_output(args.out)
    recordings = SYSTEMS[SYSTEM]().load("all").recordings()

    def describe(r: dict) -> str:
        return f"test MSE {r['before']:.4g} -> {r['after']:.4g} ({r['after'] / r['before']:.3f}x) in {r['seconds']:.1f} s"

    ledger = Ledger(args.out)
    suite = run_jobs({f"suite split {m}": Loop(m, None, args.budget, args.steps) for m in args.methods},
                     1, describe, print_now, ledger)
    loro = run_jobs({f"held out {k} {m}": Loop(m, k, args.loro_budget, args.steps)
                     for k in recordings for m in args.methods}, args.workers, describe, print_now, ledger,
                    cluster=args.cluster)
    suite_rows, loro_rows = list(suite.values()), list(loro.values())
    prov = provenance()
    sysid = next((r for r in suite_rows if r["method"] == "sysid"), None)
    lab = "" if sysid is None else (
        f" SysId after the loop: {sysid['after']:.4g}, {sysid['after'] / sysid['before']:.3f} × before; "
        f"the lab's identified model: {LAB_MSE}.")
    text = "\n".join([
        "# The residual loop on the DFKI robot's recordings",
        "",
        f"Generated by `{args.invocation}` ({made_at(prov)}"
        f"). Indirect experiment (torques), the suite's pre-processing; "
        "inside each loop, every choice is validated by leaving one training recording out "
        f"([bench/residual/validation.py]({link(validation.__file__, args.out)})).",
        "",
        f"## The suite's split: trained on 00, 01, 02, 04; tested on 03, 05; {args.budget:g} s a loop, one at a time",
        "",
        table(suite_rows) + "\n" + lab,
        "",
        f"## Leave one recording out: trained on five, tested on the sixth; {args.loro_budget:g} s a loop, "
        f"{args.workers} at a time",
        "",
        summary(loro_rows, args.methods),
        "",
        table(loro_rows),
        "",
        informed_line(recordings),
        "",
    ])
    atomic_write(args.out, lambda f: f.write(text))
    ledger.close()
    print(text)
    return 0
