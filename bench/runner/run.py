"""One run of a :class:`~bench.runner.spec.RunSpec`: in this process, and in its own process as a job.

* :func:`execute` runs a spec in this process: it resolves the spec's names,
  loads its data, fits within the budget, scores, and returns the
  :class:`~bench.runner.records.Record`. It never raises for a method's
  faults: a crash or a NaN result is a record with status ``failed`` and the
  reason. :func:`preflight` is the record of a run that cannot start.
* :class:`RunJob` is a spec run in its own process (:mod:`bench.runner.job`)
  with torch and BLAS threads pinned, which calls :func:`execute` and writes
  its record. Its fit is killed at :func:`~bench.runner.job.fit_limit`, and
  what follows the fit (scores on the full data, variants, the exact-recovery
  judgement, the rollout) at :func:`~bench.runner.job.evaluation_limit`;
  either gives status ``timeout``.
* :func:`run_one` runs one spec so, by itself (``bench fit``); a matrix
  (:mod:`bench.runner.matrix`) hands many to the scheduler,
  :func:`~bench.runner.schedule.run_jobs`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pickle
import resource
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import torch

from bench.core.budget import STEPS
from bench.core.csv_format import read_csv
from bench.core.data import Dataset, add_noise, generate
from bench.core.fileio import atomic_write
from bench.core.scoring import scoring
from bench.core.sealed import seal
from bench.core.timeouts import Timeout
from bench.evaluation.assessment import assess
from bench.evaluation.scores import Stages, errors, exact_entry, expression_entry, not_judged, scores
from bench.evaluation.tuning import prepare as prepare_search, tune
from bench.physics.models import NoVariant
from bench.physics.system import System
from bench.runner.job import (PREPARE_MIN_S, STARTUP_TIMEOUT_S, Job, Outcome, evaluation_limit, fit_limit,
                              fit_limit_words, run_isolated)
from bench.runner.ledger import suite_code
from bench.runner.plugins import import_plugins
from bench.runner.provenance import device_entry, provenance
from bench.runner.records import Record, record_path, write_record
from bench.runner.spec import TEST_SEED_OFFSET, RunSpec
from methods import METHODS
from methods.base import json_safe
from methods.hybrid import share_priors
from methods.saving import save_model
from systems import SYSTEMS

#: how a failed record's error begins where the fit diverged (its MSE is NaN or inf): an outcome a
#: benchmark records, not an error of the method's code (:func:`raised`)
DIVERGED = "non-finite"


def method_config(spec: RunSpec) -> dict:
    """The method's hyperparameters for ``spec``: its named configuration
    (:attr:`RunSpec.profile`), then the spec's overrides."""
    config = METHODS[spec.method].configuration(spec.profile)
    config.update(spec.hyperparameters)
    return config


def make_method(spec: RunSpec):
    """The spec's method, in its configuration, to train on the spec's device."""
    return METHODS[spec.method](**method_config(spec)).use_device(spec.device)


def make_system(spec: RunSpec) -> System:
    """The spec's system, of the spec's split, with its domain widened where the spec asks."""
    system = SYSTEMS[spec.system](split=spec.split)
    if spec.domain_half_width and system.simulated:
        system = SYSTEMS[spec.system](domain=system.scaled_domain(spec.domain_half_width), split=spec.split)
    return system


def load_data(spec: RunSpec, system: System) -> tuple[Dataset, Dataset | None]:
    """Train and test data for ``spec`` (test is ``None`` when unavailable);
    the training targets carry ``spec.noise``."""
    train, test = _clean_data(spec, system)
    if spec.noise:
        train = add_noise(train, spec.experiment, spec.noise, spec.seed)
    return train, test


def _clean_data(spec: RunSpec, system: System):
    given = given_data(system, spec.train_path, spec.test_path)
    if given is not None:
        return given
    return generate(system, spec.n_train, spec.seed), generate(system, spec.n_test, spec.seed + TEST_SEED_OFFSET)


def given_data(system: System, train_path: str | None, test_path: str | None, *,
               check_limits: bool = False) -> tuple[Dataset, Dataset | None] | None:
    """Train and test data that need no generating: CSV files in the suite's
    format (checked against the system), else a measured system's own splits,
    the test split sealed (:mod:`bench.core.sealed`); ``None`` for a simulated
    system without files. With ``check_limits``, their
    positions are checked against the system's position limits
    (:meth:`~bench.physics.system.System.check_positions`)."""
    if train_path:
        train = read_csv(train_path, dof=system.dof, system=system.name)
        test = read_csv(test_path, dof=system.dof, system=system.name) if test_path else None
    elif not system.simulated:
        train, test = system.load("train"), system.load("test")
    else:
        return None
    if check_limits:
        for part in (train, test):
            system.check_positions(part)
    return train, seal(test)


def preflight(spec: RunSpec, system: System | None = None) -> Record | None:
    """A record for a run that cannot start (unavailable or not applicable), else ``None``; ``system`` is the
    spec's (:func:`make_system`), where the caller has built it."""
    entry = METHODS.entry(spec.method)
    reason = entry.unavailable_reason()
    if reason:
        return Record.new(spec, "unavailable", elsewhere=True, error=reason)
    reason = entry.obj.not_applicable_reason(spec.experiment, system or make_system(spec))
    if reason:
        return Record.new(spec, "not_applicable", elsewhere=True, error=reason)
    declared = SYSTEMS[spec.system]
    if spec.experiment not in declared.experiments and not spec.train_path:
        reason = declared.not_applicable or f"{spec.system} has no data for the {spec.experiment} experiment"
        return Record.new(spec, "not_applicable", elsewhere=True, error=reason)
    return None


def execute(spec: RunSpec, on_phase: Callable[[str], None] | None = None, data: tuple | None = None,
            fitted=None, checked: bool = False) -> Record:
    """Run ``spec`` in this process and return its record (never raises for the method's faults).

    Variants a method derives from its fit (:meth:`methods.base.Method.variants`)
    are scored on the same data and stored under ``details["variants"]``.

    ``on_phase`` is called with ``"prepare"`` before the method's one-time
    work that its budget does not cover (:meth:`methods.base.Method.prepare`),
    with ``"fit"`` when the fit starts and with ``"evaluate"`` when it has
    ended. ``data`` is an already loaded ``(train, test)`` pair, else it is
    loaded from the spec. ``fitted`` is the spec's method already fitted on
    ``data`` (one seed of a stack, :mod:`bench.runner.stacked`): the run then
    evaluates it. ``checked``: the caller has made :func:`preflight`'s checks
    (:meth:`RunJob.check`), which are then not repeated.

    Which scores apply beyond the train and test MSE (rollouts, references, the
    force decomposition) is the policy of :func:`bench.evaluation.assessment.assess`.
    What follows the fit runs in stages (:class:`~bench.evaluation.scores.Stages`):
    a stage that fails (the expression, exact recovery, a variant, the
    rollout, the force decomposition (:mod:`bench.evaluation.forces`), the
    method's details) is named in ``failed_stages`` with its error, its
    traceback goes to the run's log, and the run keeps its fit's train and
    test MSE, steps and curve, with status ``ok``. A fit that
    fails, or whose MSE cannot be computed, gives status ``failed``; its
    traceback is printed too.
    """
    phase = on_phase or (lambda name: None)
    fields: dict = {}
    try:
        import_plugins(spec.plugins)
        clock = time.perf_counter()
        system = make_system(spec)
        early = None if checked else preflight(spec, system)
        if early:
            return early
        train, test = data if data is not None else load_data(spec, system)
        test = seal(test)  # its targets are read only to score, in the evaluate phase below
        budget = spec.budget
        if fitted is None:
            method = make_method(spec)
            warm_up_torch()
        else:
            method = fitted
        timing = {"load_s": time.perf_counter() - clock}
        memory = {"start_mb": resident_mb()}
        prepared = None
        tuning = held_out = None
        if fitted is None:
            phase("prepare")
            prepared = method.prepare(train, spec.experiment)
            if spec.tune:
                prepared += prepare_search(METHODS[spec.method], method_config(spec), train, spec.experiment,
                                           spec.device, seed=spec.seed, system=system, protocol=spec.folds)
            else:
                prepared += method.prepare_samples(train, spec.experiment, spec.seed, system)
            phase("fit")
            if spec.tune:
                tuned = tune(METHODS[spec.method], method_config(spec), train, spec.experiment, spec.seed, budget,
                             system=system, device=spec.device, report=lambda line: print(line, flush=True),
                             protocol=spec.folds)
                method, tuning, held_out = tuned.method, tuned.details, tuned.held_out
            else:
                method.fit(train, spec.experiment, spec.seed, budget, system=system)
        phase("evaluate")
        info = method.fit_info
        fields.update(
            steps=info.get("steps"), fit_seconds=info.get("fit_seconds"), stop_reason=info.get("stop_reason"),
            curve=_thin(info.get("curve", [])), hyperparameters=method.hyperparameters(), replay=info.get("schedule"),
        )
        clock = time.perf_counter()
        with scoring():  # the test split is read here, once, to score
            test_prediction = None if test is None else method.predict(test, spec.experiment)
            fields.update(errors(method, spec.experiment, train, test, test_prediction))
            stages = Stages()
            fields["expression"] = stages.run("expression", expression_entry, method)
            exact = stages.run("exact", exact_entry, method, spec.experiment, system, default={"exact": None})
            fields["exact"] = exact.pop("exact")
            variants = {}
            for name, model in stages.run("variants", method.variants, default={}).items():
                if isinstance(model, NoVariant):  # why there is none, and its outcome
                    variants[name] = {"status": model.status, "error": model.reason}
                    continue
                variant = Stages(prefix=f"variant {name}: ")
                scored = variant.run("scores", scores, model, spec.experiment, train, test, system, variant)
                variants[name] = {"status": "failed", "error": variant.failed[variant.prefix + "scores"]} if scored is None \
                    else {"status": "ok", **scored}
                stages.failed.update(variant.failed)
            timing["evaluate_s"] = time.perf_counter() - clock
            fields["details"] = {
                "train_source": train.source,
                "test_source": None if test is None else test.source,
                "n_train": len(train),
                "n_test": None if test is None else len(test),
                "domain": dataclasses.asdict(system.domain),
                "device": device_entry(method.trained_on()),
                **{k: v for k, v in info.items() if k not in ("curve", "steps", "fit_seconds", "stop_reason", "schedule")},
                "prepare_seconds": prepared or info.get("prepare_seconds", 0.0),
                **stages.run("details", method.record_details, default={}),
                "variants": variants,
                **({"exact_not_judged": not_judged(system)} if not_judged(system) else {}),
                **({"tuning": tuning} if tuning is not None else {}),
                **exact,
            }
            fields["rollout"], assessed = assess(method, spec.experiment, system, train, test, test_prediction, stages,
                                                 rollout=spec.rollout, timed=budget.kind != STEPS, timing=timing,
                                                 own_data=not spec.train_path)
            fields["details"].update(assessed)
        if spec.save:
            fields["details"]["saved"] = stages.run("save", save_fitted, method, spec, train, system, held_out)
        fields["details"]["timing"] = {k: round(v, 3) for k, v in timing.items()}
        memory["peak_mb"] = peak_resident_mb()
        fields["details"]["memory"] = {k: round(v, 1) for k, v in memory.items()}
        fields["failed_stages"] = stages.failed
        bad = [k for k in ("train_mse", "test_mse") if fields[k] is not None and not math.isfinite(fields[k])]
        if bad:
            return Record.new(spec, "failed", error=f"{DIVERGED} {' and '.join(bad)} (the model produced NaN or inf)", **fields)
        return Record.new(spec, "ok", **fields)
    except Timeout as exc:  # the method's own work ran out of its budget and stopped itself
        return Record.new(spec, "timeout", error=f"out of budget: {exc}", **_kept(fields))
    except Exception as exc:
        traceback.print_exc()  # to the run's log
        tb = traceback.format_exc(limit=-6)
        kept = _kept(fields)
        kept["details"] = {**kept.get("details", {}), "traceback": tb}
        return Record.new(spec, "failed", error=f"{type(exc).__name__}: {exc}", **kept)


def save_fitted(method, spec: RunSpec, train: Dataset, system: System, held_out: dict | None = None) -> dict:
    """Write the run's fitted model to ``spec.save`` (:func:`methods.saving.save_model`),
    its header saying how it was fitted (with a tuned run's held-out predictions,
    :attr:`bench.evaluation.tuning.Tuned.held_out`); returns the record's ``details.saved``."""
    header = {"method": spec.method, "system": spec.system, "plugins": list(spec.plugins), "split": spec.split,
              "experiment": spec.experiment, "seed": spec.seed, "hyperparameters": json_safe(method.hyperparameters()),
              "budget": spec.budget.to_json(), "train_source": train.source, "n_train": len(train),
              "tuned": spec.tune, "provenance": provenance(spec.threads)}
    return {"path": str(spec.save), **save_model(method, spec.save, header, train, system, held_out)}


def raised(record: Record) -> bool:
    """Whether ``record``'s run ended in an error (an exception in the method or
    a plugin, a crashed worker) rather than in an outcome a benchmark records
    (ok, its budget or time limit, a diverged fit, a method unavailable here
    or not applicable)."""
    return record.status == "failed" and not (record.error or "").startswith(DIVERGED)


def _kept(fields: dict) -> dict:
    """What a run that failed after its fit keeps of it: steps, curve and
    whatever MSE was computed (a record of status ``failed`` or ``timeout``)."""
    return {k: v for k, v in fields.items() if k in ("steps", "fit_seconds", "stop_reason", "curve", "hyperparameters",
                                                      "replay", "train_mse", "test_mse", "details")}


def resident_mb() -> float:
    """This process's resident memory now, MB (Linux; NaN elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return math.nan


def peak_resident_mb() -> float:
    """This process's peak resident memory so far, MB: with :func:`resident_mb`
    at the start of the fit, what the run itself took (the rest is what the
    process started with: torch and the suite, shared with the fork server)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def warm_up_torch() -> None:
    """Do torch's lazy one-time work before a budget starts: constructing the
    first optimiser imports ``torch._dynamo`` (about 1 s on a laptop core),
    which would otherwise be charged to the first run's fit."""
    torch.optim.Adam([torch.zeros(1, requires_grad=True)])


def _thin(curve: list, keep: int = 300) -> list:
    """Keep at most ``keep`` curve points, always the first and last."""
    if len(curve) <= keep:
        return [list(p) for p in curve]
    step = (len(curve) - 1) / (keep - 1)
    return [list(curve[round(i * step)]) for i in range(keep)]


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
        """The record of a run that cannot start (:func:`preflight`), written; else ``None``."""
        spec = self.run_spec
        early = preflight(spec)
        if early is None:
            return None
        early = early.replace(code=spec.code())
        write_record(record_path(self.out_dir, spec.run_id), early)
        return early

    def limits(self) -> dict[str, float]:
        return phase_limits(self.run_spec)

    def run(self, on_phase) -> dict:
        """The run, in the child: its record, with the code it ran (:meth:`~bench.runner.spec.RunSpec.code`), is what
        the child writes, once, to the record's path (:meth:`result_file`)."""
        data = None
        if self.data_file:
            with open(self.data_file, "rb") as f:
                data = pickle.load(f)
        spec = self.run_spec
        if self.priors:
            share_priors(self.priors, suite_code)
        record = execute(spec, on_phase, data=data, checked=True)
        return record.replace(code=spec.code()).to_json()

    def result_file(self, work: Path, name: str) -> Path:
        return record_path(self.out_dir, name)

    def folder(self) -> Path:
        """``OUT/logs``: the run's call, phases and output (a failed run's traceback among it)."""
        return Path(self.out_dir) / "logs"

    def code(self) -> str | None:
        """The hash of the code that defines the run (:meth:`~bench.runner.spec.RunSpec.code`)."""
        return (self.run_spec.code() or {}).get("hash")

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
        code = spec.code()
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
