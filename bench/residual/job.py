"""The residual loop through the runner: one :class:`ResidualJob` in its own
process (:func:`run_residual`), as ``python -m bench residual`` runs it."""

from __future__ import annotations

import dataclasses
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from bench.core.data import Dataset
from bench.core.errors import UserError
from bench.core.fileio import file_digest, read_settings
from bench.residual.loop import DEFAULT_BUDGET_S, residual_loop
from bench.residual.report import write_outputs
from bench.residual.result import ResidualResult
from bench.runner.execute import given_data
from bench.runner.isolation import Call, CallFailed, run_call
from bench.runner.matrix import KILL_FACTOR
from bench.runner.plugins import import_plugins
from bench.runner.progress import Report, print_now
from methods import METHODS
from systems import SYSTEMS


@dataclass(frozen=True)
class ResidualJob:
    """One run of the loop, as the command line gives it.

    ``train_path`` / ``test_path`` are CSV files in the suite's format; a
    measured system without them uses its own split ``split`` (``None``: its default). ``json_path`` and
    ``report_path`` are written by the loop's process, atomically.
    ``check_limits`` stops the loop where the files' positions leave the
    arm's joint limits (:meth:`~bench.core.system.System.check_positions`).
    """

    system: str
    method: str
    train_path: str | None = None
    test_path: str | None = None
    budget_s: float | None = DEFAULT_BUDGET_S
    steps: int | None = None
    seed: int = 0
    hyperparameters: dict = field(default_factory=dict)
    json_path: str | None = None
    report_path: str | None = None
    plugins: tuple[str, ...] = ()
    split: str | None = None
    device: str = "cpu"
    check_limits: bool = True
    command: str = ""
    overrides: dict = field(default_factory=dict)
    configuration: str = "default"

    def data(self) -> tuple[Dataset, Dataset | None]:
        data = given_data(SYSTEMS[self.system](split=self.split), self.train_path, self.test_path,
                          check_limits=self.check_limits)
        if data is None:
            raise UserError(f"{self.system} is simulated: give --train (and --test) CSV files, e.g. from python -m bench data")
        return data

    def run(self, report: Report = print_now) -> ResidualResult:
        """The loop in this process, with its outputs written."""
        import_plugins(self.plugins)
        train, test = self.data()
        result = residual_loop(self.method, train, test, budget_s=self.budget_s, steps=self.steps, seed=self.seed,
                               hyperparameters=self.hyperparameters, report=report, device=self.device)
        result.inputs = self.inputs()
        write_outputs(result, train, test, self.json_path, self.report_path)
        return result

    def inputs(self) -> dict:
        """What the result is made from: the command line, the ``--set``
        values, the named configuration and the method's whole configuration,
        and each data file (the given CSVs, else the measured system's own
        files) with its sha256 and the settings ``convert`` wrote beside it."""
        paths = [p for p in (self.train_path, self.test_path) if p] or SYSTEMS[self.system].source_files()
        files = {}
        for path in paths:
            files[str(path)] = {"sha256": file_digest(path)}
            settings = read_settings(path)
            if settings is not None:
                files[str(path)]["convert"] = settings
        method = METHODS[self.method](**self.hyperparameters)
        return {"command": self.command, "set": dict(self.overrides), "configuration": self.configuration,
                "hyperparameters": method.hyperparameters(), "files": files}


def run_payload(payload: dict, on_phase: Callable[[str], None]) -> dict:
    """The entry point of the loop in its own process: ``payload`` is a
    :class:`ResidualJob` as a dict; returns the result's JSON, or the
    one-line ``user_error`` that bad input gave."""
    job = ResidualJob(**{**payload, "plugins": tuple(payload.get("plugins", ()))})
    on_phase("loop")
    try:
        return job.run(print_now).to_json()
    except UserError as exc:
        return {"user_error": str(exc)}


def run_residual(job: ResidualJob, report: Report = print_now) -> ResidualResult:
    """Run ``job`` in its own process, forked from the runner's fork server,
    showing its progress lines through ``report``; the process is killed at
    1.5 x the job's time budget, or at a work budget's ceiling. Bad input
    raises :class:`UserError` with the loop's one-line message."""
    if job.steps is None:
        limit, what = KILL_FACTOR * job.budget_s, f"{KILL_FACTOR} x its budget of {job.budget_s:g} s"
    else:
        limit, what = (math.inf, "") if job.budget_s is None else (job.budget_s, f"its ceiling of {job.budget_s:g} s")
    with tempfile.TemporaryDirectory(prefix="bench-residual-") as work:
        result_file = Path(work) / "result.json"
        call = Call("bench.residual.job:run_payload", dataclasses.asdict(job))
        outcome = run_call(call, result_file, work, "residual", {"loop": limit}, echo=report)
    if outcome.killed:
        raise CallFailed(f"the residual loop was still running at {what}; killed")
    if outcome.result is None:
        raise CallFailed(f"the residual loop's process exited with code {outcome.exit_code}: {outcome.log_tail}")
    if "user_error" in outcome.result:
        raise UserError(outcome.result["user_error"])
    return ResidualResult.from_json(outcome.result)
