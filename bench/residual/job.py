"""The residual loop through the runner: one :class:`ResidualJob` in its own
process (:func:`run_residual`), as ``python -m bench residual`` runs it."""

from __future__ import annotations

import dataclasses
import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from bench.core.data import Dataset
from bench.core.errors import UserError
from bench.core.fileio import file_digest, read_settings, write_json
from bench.evaluation.per_joint import per_joint, per_joint_lines
from bench.residual.loop import DEFAULT_BUDGET_S, residual_loop
from bench.residual.report import write_outputs
from bench.residual.result import ResidualResult
from bench.runner.execute import given_data
from bench.runner.isolation import Call, CallFailed, run_call
from bench.runner.matrix import EVALUATION_MIN_S, KILL_FACTOR
from bench.runner.plugins import import_plugins
from bench.runner.progress import Report, print_now
from methods import METHODS
from systems import SYSTEMS

#: the driven rollouts after the rounds may take this multiple of the loop's budget (:func:`evaluation_limit`)
EVALUATION_FACTOR = 5.0


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
    #: where the loop's process keeps the result as it stands after each round (set by :func:`run_residual`)
    checkpoint_path: str | None = None

    def data(self, system=None) -> tuple[Dataset, Dataset | None]:
        """The train and test data: the given CSVs, else ``system``'s (by default, the job's system and split)."""
        system = SYSTEMS[self.system](split=self.split) if system is None else system
        data = given_data(system, self.train_path, self.test_path, check_limits=self.check_limits)
        if data is None:
            raise UserError(f"{self.system} is simulated: give --train (and --test) CSV files, e.g. from python -m bench data")
        return data

    def run(self, report: Report = print_now, on_phase: Callable[[str], None] | None = None) -> ResidualResult:
        """The loop in this process, with its outputs written; ``on_phase`` hears
        when the rounds end and the driven rollouts begin (``"evaluate"``)."""
        import_plugins(self.plugins)
        system = SYSTEMS[self.system](split=self.split)
        train, test = self.data(system)
        inputs = self.inputs()

        def checkpoint(result: ResidualResult) -> None:
            if self.checkpoint_path is not None:
                result.inputs = inputs
                write_json(self.checkpoint_path, result.to_json())

        result = residual_loop(self.method, train, test, budget_s=self.budget_s, steps=self.steps, seed=self.seed,
                               hyperparameters=self.hyperparameters, report=report, device=self.device,
                               checkpoint=checkpoint, on_phase=on_phase)
        result.inputs = inputs
        if test is not None and result.models is not None:
            logged = None if self.train_path else system.logged_torque("test")
            result.per_joint = {name: per_joint(model.predict_torque(test), test, logged)
                                for name, model in zip(("before", "after"), result.models)}
            for line in per_joint_lines(result.per_joint["before"], result.per_joint["after"]):
                report(line)
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
        return job.run(print_now, on_phase).to_json()
    except UserError as exc:
        return {"user_error": str(exc)}


def evaluation_limit(budget_s: float | None) -> float:
    """Seconds the driven rollouts after the rounds may take before the loop's
    process is killed: their work is the data's and the models', not the
    budget's, so a generous multiple of the budget, at least
    :data:`EVALUATION_MIN_S` (none under a work budget without a ceiling)."""
    return math.inf if budget_s is None else max(EVALUATION_MIN_S, EVALUATION_FACTOR * budget_s)


def run_residual(job: ResidualJob, report: Report = print_now) -> ResidualResult:
    """Run ``job`` in its own process, forked from the runner's fork server,
    showing its progress lines through ``report``. The loop stops itself at
    its time budget with the rounds that finished; its process is killed only
    where one step runs far past it (at :data:`KILL_FACTOR` x the budget, or
    a work budget's ceiling) or the driven rollouts after the rounds run past
    :func:`evaluation_limit`. Then the result is the loop's last checkpoint,
    the rounds that finished, with ``stopped`` saying where it was killed,
    and this process writes the JSON and a report without plots. Only a loop
    killed before its first round ended raises :class:`CallFailed`. Bad
    input raises :class:`UserError` with the loop's one-line message."""
    if job.steps is None:
        limit, what = KILL_FACTOR * job.budget_s, f"{KILL_FACTOR} x its budget of {job.budget_s:g} s"
    else:
        limit, what = (math.inf, "") if job.budget_s is None else (job.budget_s, f"its ceiling of {job.budget_s:g} s")
    after = evaluation_limit(job.budget_s)
    with tempfile.TemporaryDirectory(prefix="bench-residual-") as work:
        result_file, checkpoint = Path(work) / "result.json", Path(work) / "checkpoint.json"
        job = dataclasses.replace(job, checkpoint_path=str(checkpoint))
        call = Call("bench.residual.job:run_payload", dataclasses.asdict(job))
        outcome = run_call(call, result_file, work, "residual", {"loop": limit, "evaluate": after}, echo=report)
        saved = json.loads(checkpoint.read_text()) if outcome.killed and checkpoint.is_file() else None
    if outcome.killed:
        if saved is None:
            raise CallFailed(f"the residual loop was still running at {what}, in round 0; killed")
        result = ResidualResult.from_json(saved)
        last = result.rounds[-1]["round"] if result.rounds else 0
        if outcome.phase == "evaluate":
            result.stopped = (f"the driven rollouts after the rounds were still running after {after:g} s; killed: "
                              f"the result has every round and no rollouts")
        else:
            result.stopped = (f"the loop was still running at {what}, in round {last + 1}, and was killed: "
                              f"the rounds up to round {last} are kept")
        report(f"stopped: {result.stopped}")
        write_outputs(result, None, None, job.json_path, job.report_path)
        return result
    if outcome.result is None:
        raise CallFailed(f"the residual loop's process exited with code {outcome.exit_code}: {outcome.log_tail}")
    if "user_error" in outcome.result:
        raise UserError(outcome.result["user_error"])
    return ResidualResult.from_json(outcome.result)
