"""One run of the matrix as a job (:mod:`bench.runner.job`).

* :class:`RunJob` is one :class:`~bench.runner.spec.RunSpec` run in its own
  process with torch and BLAS threads pinned, which writes its record. Its
  fit is killed at :func:`~bench.runner.job.fit_limit`, and what follows the
  fit (scores on the full data, variants, the exact-recovery judgement, the
  rollout) at :func:`~bench.runner.job.evaluation_limit`; either gives status
  ``timeout``. A crash or a non-finite result gives status ``failed`` with the
  reason.
* :func:`run_one` runs one spec so, by itself (``bench fit``); a matrix
  (:mod:`bench.runner.matrix`) hands many to the scheduler,
  :func:`~bench.runner.job.run_jobs`.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
from dataclasses import dataclass
from pathlib import Path

from bench.core.fileio import atomic_write
from bench.runner.code import code_hash
from bench.runner.execute import execute, preflight
from bench.runner.isolation import STARTUP_TIMEOUT_S, Outcome
from bench.runner.ledger import suite_code
from bench.runner.job import PREPARE_MIN_S, Job, evaluation_limit, fit_limit, fit_limit_words, run_isolated
from bench.runner.records import Record, record_path, write_record
from bench.runner.spec import RunSpec
from methods.hybrid import share_priors


def phase_limits(spec: RunSpec) -> dict[str, float]:
    """Seconds a run may spend in each phase: preparing, fitting
    (:func:`~bench.runner.job.fit_limit`) and after the fit
    (:func:`~bench.runner.job.evaluation_limit`)."""
    return {"prepare": max(PREPARE_MIN_S, spec.budget_s or 0.0), "fit": fit_limit(spec.budget),
            "evaluate": evaluation_limit(spec.budget_s)}


def log_path(out_dir: str | os.PathLike, rid: str) -> Path:
    """Where a run's output goes: ``OUT/logs/<run id>.log`` (a failed run's traceback among it)."""
    return Path(out_dir) / "logs" / f"{rid}.log"


@dataclass(frozen=True)
class RunJob(Job):
    """One run of the matrix as a :class:`~bench.runner.job.Job`: its spec,
    and the folder its record goes to (``OUT/records/<run id>.json``, its
    output to ``OUT/logs/``).

    From the start of its fit the run has :func:`~bench.runner.job.fit_limit`
    seconds to finish the fit, then :func:`~bench.runner.job.evaluation_limit`
    seconds for what follows; past either it is killed and recorded as
    ``timeout``. A child that dies without writing a record is recorded as
    ``failed`` with the tail of its log. :meth:`finish` writes the record.
    """

    spec: dict
    out_dir: str
    data_file: str | None = None
    #: a folder through which the run shares the priors it identifies with the other runs (:func:`share_priors`)
    priors: str | None = None

    @classmethod
    def of(cls, spec: RunSpec, out_dir: str | os.PathLike, data_file: str | None = None,
           priors: str | os.PathLike | None = None) -> "RunJob":
        return cls(spec.to_dict(), str(out_dir), data_file, None if priors is None else str(priors))

    @property
    def run_spec(self) -> RunSpec:
        return RunSpec.from_dict(self.spec)

    @property
    def threads(self) -> int:
        return self.run_spec.threads

    def check(self) -> Record | None:
        """The record of a run that cannot start (:func:`~bench.runner.execute.preflight`), written; else ``None``."""
        spec = self.run_spec
        early = preflight(spec)
        if early is None:
            return None
        early = early.replace(code=self.code_entry())
        write_record(record_path(self.out_dir, spec.run_id), early)
        return early

    def limits(self) -> dict[str, float]:
        return phase_limits(self.run_spec)

    def run(self, on_phase) -> dict:
        """The run, in the child: its record, with the code it ran (:func:`~bench.runner.code.code_hash`), is what
        the child writes, once, to the record's path (:meth:`result_file`)."""
        data = None
        if self.data_file:
            with open(self.data_file, "rb") as f:
                data = pickle.load(f)
        spec = self.run_spec
        if self.priors:
            share_priors(self.priors, suite_code)
        record = execute(spec, on_phase, data=data, checked=True)
        return record.replace(code=self.code_entry()).to_json()

    def result_file(self, work: Path, name: str) -> Path:
        return record_path(self.out_dir, name)

    def folder(self) -> Path:
        """``OUT/logs``: the run's call, phases and output (a failed run's traceback among it)."""
        return Path(self.out_dir) / "logs"

    def code_entry(self) -> dict | None:
        """The record's ``code``: the files that define the run's method and system, and their hash
        (:func:`~bench.runner.code.code_hash`)."""
        spec = self.run_spec
        return code_hash(spec.method, spec.system, spec.plugins)

    def code(self) -> str | None:
        """The hash of :meth:`code_entry`."""
        return (self.code_entry() or {}).get("hash")

    def identity(self) -> dict:
        """The run's spec, as JSON (wherever its record goes)."""
        return self.run_spec.to_dict()

    def elsewhere(self, scratch: Path) -> "RunJob":
        """On a cluster's worker the run writes its record, its log and its model file under ``scratch``, and
        shares no prior (the workers need no shared file system)."""
        spec = self.run_spec
        if spec.save:
            spec = dataclasses.replace(spec, save=str(Path(scratch) / "models" / Path(spec.save).name))
        return dataclasses.replace(self, spec=spec.to_dict(), out_dir=str(scratch), priors=None)

    def packed(self, record: Record) -> tuple[Record, bytes | None]:
        """On the worker, the record with the model file it wrote (``None`` where none was written)."""
        saved = Path(self.run_spec.save) if self.run_spec.save else None
        return record, saved.read_bytes() if saved is not None and saved.is_file() else None

    def land(self, result: tuple[Record, bytes | None]) -> Record:
        """A record and model file that came back from a cluster's worker (:meth:`packed`), written where this
        job writes them, the record naming this job's spec and model file."""
        record, model = result
        details = dict(record.details or {})
        if model is not None and self.run_spec.save:
            atomic_write(self.run_spec.save, lambda f: f.write(model), binary=True)
            details["saved"] = {**details.get("saved", {}), "path": self.run_spec.save}
        record = record.replace(spec=self.identity(), details=details)
        write_record(record_path(self.out_dir, record.run_id), record)
        return record

    def finish(self, outcome: Outcome, report) -> Record:
        """The record the child wrote; where it wrote none (it failed or was killed), the one written here."""
        spec = self.run_spec
        path = record_path(self.out_dir, spec.run_id)
        if outcome.result is not None:
            return Record.from_json(outcome.result, str(path))
        limits = self.limits()
        code = self.code_entry()
        if not outcome.killed:
            error = f"worker exited with code {outcome.exit_code} and wrote no record: {outcome.log_tail}"
            record = Record.new(spec, "failed", elsewhere=True, error=error, code=code)
        elif outcome.phase == "fit":
            record = Record.new(spec, "timeout", elsewhere=True, code=code,
                                error=f"fit still running at {fit_limit_words(spec.budget)}; killed")
        elif outcome.phase in ("evaluate", "prepare"):
            what = "evaluation after the fit" if outcome.phase == "evaluate" else \
                "one-time work before the fit (compiling; a hybrid's prior)"
            record = Record.new(spec, "timeout", elsewhere=True,
                                error=f"{what} still running after {limits[outcome.phase]:g} s; killed", code=code)
        else:
            record = Record.new(spec, "failed", elsewhere=True, code=code,
                                error=f"did not start its fit within {STARTUP_TIMEOUT_S:g} s; killed")
        write_record(path, record)
        return record


def run_one(spec: RunSpec, out_dir: str | os.PathLike, *, checked: bool = False, fresh: bool = False,
            data: tuple | None = None) -> Record:
    """``spec`` run as a :class:`RunJob` by :func:`~bench.runner.job.run_isolated`; its record, written.

    ``data``: the spec's ``(train, test)`` pair, already read (and checked) by
    the caller; the run's process is handed it through a file in
    ``out_dir``, removed after the run, instead of reading the spec's files again."""
    data_file = None
    if data is not None:
        data_file = Path(out_dir) / f"{spec.run_id}.data.pickle"
        data_file.parent.mkdir(parents=True, exist_ok=True)
        with open(data_file, "wb") as f:
            pickle.dump(data, f, protocol=pickle.HIGHEST_PROTOCOL)
    try:
        return run_isolated(RunJob.of(spec, out_dir, data_file and str(data_file)), Path(out_dir) / "logs",
                            spec.run_id, checked=checked, fresh=fresh)
    finally:
        if data_file is not None:
            data_file.unlink(missing_ok=True)
