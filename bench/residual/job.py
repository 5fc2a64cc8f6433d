"""The residual loop through the runner: one :class:`ResidualJob`, a
:class:`~bench.runner.job.Job`, in its own process (:func:`run_residual`), as
``python -m bench residual`` runs it."""

from __future__ import annotations

import dataclasses
import json
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from bench.core.budget import DEFAULT_BUDGET_S, Budget
from bench.core.data import Dataset
from bench.physics.system import System
from bench.core.errors import UserError
from bench.core.fileio import file_digest, read_settings, write_json
from bench.core.scoring import scoring
from bench.evaluation.per_joint import logged_test_torque, per_joint, per_joint_lines
from bench.residual.loop import residual_loop
from bench.residual.report import write_outputs
from bench.residual.result import ResidualResult
from bench.runner.run import given_data, make_system, method_config, preflight
from bench.core.errors import CallFailed
from bench.runner.job import Job, Outcome, evaluation_limit, fit_limit, fit_limit_words, run_isolated
from bench.runner.plugins import import_plugins
from bench.runner.progress import Report, print_now
from bench.runner.spec import RunSpec
from methods import METHODS
from systems import SYSTEMS

#: the driven rollouts after the rounds may take this multiple of the loop's budget (:meth:`ResidualJob.limits`)
EVALUATION_FACTOR = 5.0


@dataclass(frozen=True)
class ResidualJob(Job):
    """One run of the loop, as the command line gives it, as a
    :class:`~bench.runner.job.Job`: the run's :class:`~bench.runner.spec.RunSpec`
    (``spec``, as JSON: the system, the method in its named configuration
    (``profile``) with the user's ``--set`` values (``hyperparameters``), the
    data (``train_path`` / ``test_path``, CSV files in the suite's format; a
    measured system without them uses its own ``split``), the budget, the seed,
    the plugins and the device) and what the loop adds to a run:
    ``json_path`` and ``report_path``, written by the loop's process,
    atomically; ``check_limits``, which stops the loop where the files'
    positions leave the arm's joint limits
    (:meth:`~bench.physics.system.System.check_positions`); and the command
    line, for the result's inputs.
    """

    spec: dict
    json_path: str | None = None
    report_path: str | None = None
    check_limits: bool = True
    command: str = ""
    #: where the loop's process keeps the result as it stands after each round (set by :func:`run_residual`)
    checkpoint_path: str | None = None

    @classmethod
    def of(cls, system: str, method: str, *, budget_s: float | None = DEFAULT_BUDGET_S, steps: int | None = None,
           seed: int = 0, **fields) -> "ResidualJob":
        """The loop of ``method`` on ``system``: ``fields`` are the job's own and the spec's (``train_path``,
        ``hyperparameters``, ``profile``, ``split``, ``plugins``, ``device``, ...)."""
        own = {f.name for f in dataclasses.fields(cls)} - {"spec"}
        spec = RunSpec(system=system, method=method, experiment="indirect", seed=seed, budget_s=budget_s, steps=steps,
                       **{k: v for k, v in fields.items() if k not in own})
        return cls(spec.to_dict(), **{k: v for k, v in fields.items() if k in own})

    @property
    def run_spec(self) -> RunSpec:
        return RunSpec.from_dict(self.spec)

    @property
    def settings(self) -> dict:
        """The method's hyperparameters: its named configuration, then the ``--set`` values
        (:func:`~bench.runner.run.method_config`)."""
        return method_config(self.run_spec)

    def check(self, system: System | None = None) -> None:
        """The method can run here and fits torques (:func:`~bench.runner.run.preflight`), its
        hyperparameters are valid, and a simulated system has data given; else one line. ``system``: the
        spec's, where the caller has built it."""
        spec = self.run_spec
        early = preflight(spec, system)
        if early is not None:
            raise UserError(f"method {spec.method} is unavailable: {early.error}" if early.status == "unavailable"
                            else f"method {spec.method} cannot run the loop, which fits torques: {early.error}")
        METHODS[spec.method](**self.settings)
        if not spec.train_path and SYSTEMS[spec.system].simulated:
            raise UserError(f"{spec.system} is simulated: give --train (and --test) CSV files, e.g. from python -m bench data")

    def limits(self) -> dict[str, float]:
        """The loop (its fit and rounds) is killed at :func:`~bench.runner.job.fit_limit`
        of its budget, the driven rollouts after the rounds at
        :func:`~bench.runner.job.evaluation_limit` with :data:`EVALUATION_FACTOR`:
        their work is the data's and the models', not the budget's."""
        spec = self.run_spec
        return {"loop": fit_limit(spec.budget), "evaluate": evaluation_limit(spec.budget_s, EVALUATION_FACTOR)}

    @property
    def budget(self) -> Budget:
        return self.run_spec.budget

    def data(self, system: System) -> tuple[Dataset, Dataset | None]:
        """The train and test data: the given CSVs, else ``system``'s own split."""
        spec = self.run_spec
        return given_data(system, spec.train_path, spec.test_path, check_limits=self.check_limits)

    def run(self, on_phase: Callable[[str], None], report: Report = print_now) -> dict:
        """The loop in this process, with its outputs written; ``on_phase`` hears
        the loop begin (``"loop"``) and its driven rollouts begin (``"evaluate"``).
        Bad input in the data files gives ``{"user_error": line}``."""
        on_phase("loop")
        try:
            return self.fit(report, on_phase).to_json()
        except UserError as exc:
            return {"user_error": str(exc)}

    def fit(self, report: Report = print_now, on_phase: Callable[[str], None] | None = None) -> ResidualResult:
        """The loop in this process, with its outputs written."""
        spec = self.run_spec
        import_plugins(spec.plugins)
        system = make_system(spec)
        train, test = self.data(system)
        own = {"inputs": self.inputs(), "spec": self.spec, "code": spec.code(runs_in=(__name__,))}

        def checkpoint(result: ResidualResult) -> None:
            if self.checkpoint_path is not None:
                write_json(self.checkpoint_path, dataclasses.replace(result, **own).to_json())

        result = residual_loop(spec.method, train, test, budget=spec.budget, seed=spec.seed,
                               hyperparameters=self.settings, report=report, device=spec.device,
                               checkpoint=checkpoint, on_phase=on_phase)
        per_joint_errors = None
        with scoring():  # the loop's figures on the test split, to report
            if test is not None and result.models is not None:
                logged = logged_test_torque(system, own_data=not spec.train_path)
                per_joint_errors = {name: per_joint(model.predict_torque(test), test, logged)
                                    for name, model in zip(("before", "after"), result.models)}
                for line in per_joint_lines(per_joint_errors["before"], per_joint_errors["after"]):
                    report(line)
            result = dataclasses.replace(result, per_joint=per_joint_errors, **own)
            write_outputs(result, train, test, self.json_path, self.report_path)
        return result

    def finish(self, outcome: Outcome, report: Report) -> ResidualResult:
        """The loop's result; where its process was killed, or failed after a
        round had ended (an error in the outputs after the rounds, say), its
        last checkpoint, the rounds that finished, with ``stopped`` saying
        where (written here, the report without plots); a loop killed before
        its first round ended raises :class:`CallFailed`, as does a process
        that failed without a checkpoint."""
        path = Path(self.checkpoint_path) if self.checkpoint_path else None
        saved = path is not None and path.is_file()
        failed = outcome.result is None and not outcome.killed and saved
        if outcome.killed and not saved:
            raise CallFailed(f"the residual loop was still running at {fit_limit_words(self.budget)}, "
                             f"in round 0; killed")
        if outcome.killed or failed:
            result = ResidualResult.from_json(json.loads(path.read_text()), str(path))
            last = result.rounds[-1]["round"] if result.rounds else 0
            if failed:
                why = (outcome.log_tail or "").strip().splitlines()[-1:] or [f"exit code {outcome.exit_code}"]
                stopped = (f"the loop's process failed after round {last} ({why[0][:200]}): the rounds up to "
                           f"round {last} are kept")
            elif outcome.phase == "evaluate":
                stopped = (f"the driven rollouts after the rounds were still running after "
                           f"{self.limits()['evaluate']:g} s; killed: the result has every round and no rollouts")
            else:
                stopped = (f"the loop was still running at {fit_limit_words(self.budget)}, in round {last + 1}, "
                           f"and was killed: the rounds up to round {last} are kept")
            result = dataclasses.replace(result, stopped=stopped)
            report(f"stopped: {stopped}")
            write_outputs(result, None, None, self.json_path, self.report_path)
            return result
        if outcome.result is None:
            raise CallFailed(f"the residual loop's process exited with code {outcome.exit_code}: {outcome.log_tail}")
        if "user_error" in outcome.result:
            raise UserError(outcome.result["user_error"])
        return ResidualResult.from_json(outcome.result)

    def inputs(self) -> dict:
        """What the result is made from: the command line, the ``--set``
        values, the named configuration and the method's whole configuration,
        and each data file (the given CSVs, else the measured system's own
        files) with its sha256 and the settings ``convert`` wrote beside it."""
        spec = self.run_spec
        paths = [p for p in (spec.train_path, spec.test_path) if p] or SYSTEMS[spec.system].source_files()
        files = {}
        for path in paths:
            files[str(path)] = {"sha256": file_digest(path)}
            settings = read_settings(path)
            if settings is not None:
                files[str(path)]["convert"] = settings
        method = METHODS[spec.method](**self.settings)
        return {"command": self.command, "set": dict(spec.hyperparameters), "configuration": spec.profile,
                "hyperparameters": method.hyperparameters(), "files": files}


def run_residual(job: ResidualJob, report: Report = print_now, *, checked: bool = False) -> ResidualResult:
    """Run ``job`` in its own process (:func:`~bench.runner.job.run_isolated`),
    showing its progress lines through ``report``. The loop stops itself at
    its time budget with the rounds that finished; its process is killed only
    where one step runs far past it or the driven rollouts after the rounds
    run past their limit (:meth:`ResidualJob.limits`): then the result is the
    loop's last checkpoint (:meth:`ResidualJob.finish`). Bad input raises
    :class:`UserError` in one line before the process starts (:meth:`ResidualJob.check`,
    unless the caller made it: ``checked``)."""
    with tempfile.TemporaryDirectory(prefix="bench-residual-") as work:
        job = dataclasses.replace(job, checkpoint_path=str(Path(work) / "checkpoint.json"))
        return run_isolated(job, work, "residual", checked=checked, echo=report)
