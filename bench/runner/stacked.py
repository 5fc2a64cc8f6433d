"""Runs of a matrix that differ only in their seed, trained in one process as
one stacked model (``bench run --stack-seeds``, :mod:`methods.stacking`) and
written as ordinary records.

* :func:`groups`: the runs to do, each seed of a stackable method's run
  grouped with the seeds whose specs equal it in all else;
* :class:`StackedJob`: one group in its own process, killed like any run
  (its fit shares one limit, its evaluations have one each); each seed's
  record is then what :func:`~bench.runner.run.execute` writes for a fit
  made alone, its ``details.stacked`` the number of seeds that trained with it.
  Where the group's process fails or is killed, each of its seeds runs again
  on its own (:func:`~bench.runner.run.run_one`), so that no seed's record is
  lost to another's failure. The matrix hands the groups to the one
  scheduler, :func:`~bench.runner.schedule.run_jobs`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from bench.core.errors import UserError
from bench.runner.job import Job, Outcome
from bench.runner.run import execute, load_data, make_method, make_system, phase_limits, run_one, warm_up_torch
from bench.runner.plugins import import_plugins
from bench.runner.records import Record, record_path, write_record
from bench.runner.spec import RunSpec
from methods import METHODS
from methods.stacking import fit_stacked


def groups(specs: list[RunSpec], report: Callable[[str], None] | None = None) -> list[list[RunSpec]]:
    """``specs`` in order, the runs of a stackable method in a stackable configuration
    (:meth:`~methods.base.Method.stacking_unavailable_reason`) grouped by everything
    but their seed; every other run alone. ``report`` gets one line per method
    (and configuration) whose seeds could stack but train alone, with the reason."""
    out: dict = {}
    said = set()
    for spec in specs:
        reason = _unstackable(spec)
        key = repr(sorted(dataclasses.replace(spec, seed=0).to_dict().items())) if reason is None else spec.run_id
        out.setdefault(key, []).append(spec)
        if reason and report is not None and reason not in said:
            said.add(reason)
            report(f"--stack-seeds: {spec.method} runs each seed alone: {reason}")
    return list(out.values())


def _unstackable(spec: RunSpec) -> str | None:
    """Why ``spec``'s seeds cannot stack (``""`` for a method never meant to), or ``None``."""
    if spec.method not in METHODS or not METHODS.entry(spec.method).available or not METHODS[spec.method].stackable:
        return ""
    try:
        return make_method(spec).stacking_unavailable_reason()
    except UserError:  # a configuration the run itself will refuse, with its reason, alone
        return ""


@dataclass(frozen=True)
class StackedJob(Job):
    """A group of seeds (:meth:`RunSpec.to_dict` each) trained stacked in one process, as a
    :class:`~bench.runner.job.Job`; the process writes each seed's record into ``out_dir``, once, and its
    result is one record's JSON a seed, or ``None`` where the process failed or was killed (each seed then
    runs alone)."""

    specs: tuple
    phase_limits: dict
    out_dir: str

    @classmethod
    def of(cls, group: list[RunSpec], out_dir: str | Path) -> "StackedJob":
        """``group``'s job, its limits a run's (:func:`~bench.runner.run.phase_limits`)."""
        return cls(tuple(s.to_dict() for s in group), phase_limits(group[0]), str(out_dir))

    @property
    def name(self) -> str:
        """Its process's name, its log's and call's (:func:`stack_name`)."""
        return stack_name([RunSpec.from_dict(d) for d in self.specs])

    def folder(self) -> Path:
        return Path(self.out_dir) / "logs"

    @property
    def threads(self) -> int:
        return RunSpec.from_dict(self.specs[0]).threads

    def limits(self) -> dict[str, float]:
        """One run's limits, the evaluation's times the seeds."""
        return {**self.phase_limits, "evaluate": self.phase_limits["evaluate"] * len(self.specs)}

    def run(self, on_phase: Callable[[str], None]) -> dict:
        specs = [RunSpec.from_dict(d) for d in self.specs]
        import_plugins(specs[0].plugins)
        first = specs[0]
        system = make_system(first)
        data = [load_data(spec, system) for spec in specs]
        methods = [make_method(spec) for spec in specs]
        warm_up_torch()
        on_phase("prepare")
        fit_stacked(methods, [train for train, _ in data], first.experiment, [s.seed for s in specs], first.budget,
                    system=system, on_fit=lambda: on_phase("fit"))
        on_phase("evaluate")
        code = first.code()
        records = []
        for spec, pair, method in zip(specs, data, methods):
            record = execute(spec, data=pair, fitted=method, checked=True).replace(code=code)
            write_record(record_path(self.out_dir, spec.run_id), record)
            records.append(record.to_json())
        return {"records": records}

    def finish(self, outcome: Outcome, report) -> list[Record]:
        """Each seed's record: the stack's, or, where its process gave none (it failed or was killed), each
        seed's run on its own."""
        specs = [RunSpec.from_dict(d) for d in self.specs]
        if outcome.result is None:
            return [run_one(spec, self.out_dir, checked=True) for spec in specs]
        return [Record.from_json(obj, f"{self.name}: {spec.run_id}") for spec, obj in zip(specs, outcome.result["records"])]


def stack_name(group: list[RunSpec]) -> str:
    """The name of a group's process, its log's and call's: its first run's id and its size."""
    return f"{group[0].run_id}__stack{len(group)}"
