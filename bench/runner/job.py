"""One kind of job: work that runs in its own process, under limits per phase.

A :class:`Job` is a frozen dataclass whose fields are what its process needs,
as JSON. Its life has four steps, each a method it may override:

* :meth:`Job.check`, in the caller's process, before any child starts: bad
  input raises :class:`~bench.core.errors.UserError` in one line; a job that
  need not run (a method unavailable here) returns its result;
* :meth:`Job.limits`: the seconds it may spend in each phase it reports;
* :meth:`Job.run`, in the child: the work, returning JSON; it names its
  phases through ``on_phase`` and checks nothing :meth:`Job.check` checked;
* :meth:`Job.finish`, in the caller's process: the job's result from how
  its process ended (:class:`~bench.runner.isolation.Outcome`), a kill or a
  crash included.

:func:`run_isolated` runs one job this way and :func:`run_jobs`, the one
scheduler, runs many side by side: a matrix's runs
(:class:`bench.runner.run.RunJob`) and its stacked groups
(:class:`bench.runner.stacked.StackedJob`), the residual loop
(:class:`bench.residual.job.ResidualJob`) and the studies' cases
(:class:`CaseJob`). The process itself, its fork server and the
killing at a phase's limit are :mod:`bench.runner.isolation`'s.

The limits every job shares are here: a fit is killed at
:data:`KILL_FACTOR` x its time budget (:func:`fit_limit`), and what follows
it has :func:`evaluation_limit`.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Mapping

from bench.core.budget import SECONDS, Budget
from bench.runner.cluster import run_on_cluster
from bench.runner.isolation import Call, CallFailed, Outcome, map_interruptibly, run_call
from bench.runner.ledger import Ledger, suite_code
from bench.runner.progress import print_now

#: A fit is killed at this multiple of its time budget.
KILL_FACTOR = 1.5
#: What follows a fit (evaluation on the full data, variants, exact
#: recovery, rollouts) may take its budget, and at least this many seconds.
EVALUATION_MIN_S = 120.0
#: The method's one-time work before its budget starts (compiling for the
#: data's shapes, :meth:`methods.base.Method.prepare`; a hybrid's prior on
#: each set of samples it fits, :meth:`methods.base.Method.prepare_samples`)
#: may take its budget, and at least this many seconds.
PREPARE_MIN_S = 900.0


def fit_limit(budget: Budget) -> float:
    """Seconds a fit may run before its process is killed: :data:`KILL_FACTOR`
    x a time budget, or a work budget's ceiling (none without one)."""
    return KILL_FACTOR * budget.seconds if budget.kind == SECONDS else budget.ceiling_s


def fit_limit_words(budget: Budget) -> str:
    """:func:`fit_limit` in words, for the message of a job killed there."""
    return (f"{KILL_FACTOR} x its {budget.seconds:g} s budget" if budget.kind == SECONDS
            else f"its ceiling of {budget.ceiling_s:g} s")


def evaluation_limit(budget_s: float | None, factor: float = 1.0) -> float:
    """Seconds a job may take after its fit: ``max(EVALUATION_MIN_S, factor *
    budget_s)``, none for a work budget without a ceiling (``budget_s`` ``None``)."""
    return math.inf if budget_s is None else max(EVALUATION_MIN_S, factor * budget_s)


class Job:
    """Work run in its own process by :func:`run_isolated`; subclasses are
    frozen dataclasses, their fields JSON (tuples travel as lists)."""

    #: torch and BLAS threads the child pins
    threads: int = 1

    def check(self) -> Any:
        """Checks made once, in the caller's process, before the child starts:
        raise :class:`~bench.core.errors.UserError` for bad input; return the
        job's result where it need not run; ``None`` to run it."""
        return None

    def limits(self) -> dict[str, float]:
        """Seconds allowed in each phase the child reports (a phase not named has no limit)."""
        return {}

    def run(self, on_phase: Callable[[str], None]) -> dict:
        """The work, in the child; returns JSON."""
        raise NotImplementedError

    def finish(self, outcome: Outcome, report: Callable[[str], None]) -> Any:
        """The job's result from how its process ended, saying through ``report``
        what the caller should hear of it: by default the JSON it returned,
        else :class:`~bench.runner.isolation.CallFailed`."""
        if outcome.result is None:
            raise CallFailed(f"killed in its {outcome.phase} phase" if outcome.killed else outcome.log_tail)
        return outcome.result

    def result_file(self, work: Path, name: str) -> Path:
        """Where the child writes what :meth:`run` returns."""
        return work / f"{name}.result.json"

    def folder(self) -> Path | None:
        """Where :func:`run_jobs` keeps the job's call, phases and output (``None``: a scratch folder, removed
        once every job has ended)."""
        return None

    def elsewhere(self, scratch: Path) -> "Job":
        """The job as it runs on a cluster's worker (:mod:`bench.runner.cluster`), which may not share the
        caller's files: what it writes goes under ``scratch`` instead. By default the job itself."""
        return self

    def packed(self, result: Any) -> Any:
        """On a cluster's worker, the result of the job :meth:`elsewhere` made, as it travels back: with the
        files the caller keeps that it wrote under the scratch folder (a run's model file). By default the
        result itself."""
        return result

    def land(self, result: Any) -> Any:
        """In the caller, what :meth:`packed` sent back from a cluster's worker, with what the job keeps
        written where it would have written it here (a run's record and model file). By default the result
        itself."""
        return result

    def code(self) -> str | None:
        """The code the job's result depends on, as a digest: a stored result made by other code does not
        stand for the job (:func:`~bench.runner.ledger.rerun_reason`). By default the whole suite's, taken
        once a process (:func:`~bench.runner.ledger.suite_code`); a run of a method names its method's and
        its system's files (:meth:`bench.runner.run.RunJob.code`). ``None``: not known (outside a git
        checkout)."""
        return suite_code()

    def identity(self) -> dict:
        """What the job is, as a stored result is compared with it (:func:`~bench.runner.ledger.rerun_reason`):
        by default its class and fields (:func:`job_fields`)."""
        return job_fields(self)

    def payload(self) -> dict:
        """The job as JSON, from which :meth:`from_payload` makes it again in the child."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_payload(cls, obj: dict) -> "Job":
        fields = {f.name: f for f in dataclasses.fields(cls)}
        return cls(**{k: tuple(v) if isinstance(v, list) and "tuple" in str(fields[k].type) else v
                      for k, v in obj.items()})


class CaseJob(Job):
    """A study's case: all one phase, ``"run"``, killed at :meth:`run_limit`
    seconds in it; :meth:`compute` does the work in the child."""

    def run_limit(self) -> float:
        raise NotImplementedError

    def compute(self) -> dict:
        raise NotImplementedError

    def limits(self) -> dict[str, float]:
        return {"run": self.run_limit()}

    def run(self, on_phase: Callable[[str], None]) -> dict:
        on_phase("run")
        return self.compute()


def run_job(payload: dict, on_phase: Callable[[str], None]) -> dict:
    """The one entry point of a job's process: ``payload`` names the job's
    class (``"module:Class"``) and gives its fields."""
    module, _, name = payload["job"].partition(":")
    cls = getattr(importlib.import_module(module), name)
    return cls.from_payload(payload["fields"]).run(on_phase)


def run_isolated(job: Job, work: str | Path | None = None, name: str = "job", *, checked: bool = False,
                 fresh: bool = False, poll_s: float = 0.05, echo: Callable[[str], None] | None = None) -> Any:
    """Run ``job`` in its own process and return :meth:`Job.finish`'s result.

    :meth:`Job.check` runs first, in this process, unless the caller did
    (``checked``). The child's call, phases and output go to
    ``work/<name>.*`` (a temporary folder where ``work`` is ``None``);
    ``echo`` receives each line the child prints; ``fresh=True`` starts a
    fresh interpreter instead of forking from the fork server. An interrupted
    caller (:func:`~bench.runner.isolation.kill_children`) gets
    :class:`KeyboardInterrupt`. :meth:`Job.finish` reports through ``echo``,
    else prints.
    """
    if not checked:
        early = job.check()
        if early is not None:
            return early
    if work is None:
        with tempfile.TemporaryDirectory(prefix="bench-job-") as scratch:
            return run_isolated(job, scratch, name, checked=True, fresh=fresh, poll_s=poll_s, echo=echo)
    work = Path(work)
    call = Call("bench.runner.job:run_job", {"job": f"{type(job).__module__}:{type(job).__qualname__}",
                                             "fields": job.payload()}, job.threads)
    outcome = run_call(call, job.result_file(work, name), work, name, job.limits(), fresh=fresh, poll_s=poll_s,
                       echo=echo)
    if outcome.interrupted:
        raise KeyboardInterrupt(f"{name} interrupted")
    return job.finish(outcome, echo or print_now)


def run_remote(job: Job, name: str) -> tuple[bool, Any]:
    """A cluster's task (:mod:`bench.runner.cluster`): ``job`` in its own process on the worker, in a
    scratch folder there (:meth:`Job.elsewhere`); ``(True, result)`` (:meth:`Job.packed`), or
    ``(False, why)`` where it did not finish."""
    with tempfile.TemporaryDirectory(prefix="syrenets-bench-") as scratch:
        there = job.elsewhere(Path(scratch))
        try:
            return True, there.packed(run_isolated(there, scratch, name, checked=True))
        except CallFailed as exc:
            return False, str(exc)


def job_fields(job: Job) -> dict:
    """What a job is, as its ledger compares it: its class and its fields, as JSON reads them back."""
    return json.loads(json.dumps({"job": f"{type(job).__module__}:{type(job).__qualname__}",
                                  "fields": job.payload()}))


def run_jobs(jobs: Mapping[str, Job], workers: int, describe: Callable[[Any], str] | None,
             report: Callable[[str], None], ledger: Ledger | None = None, *, checked: bool = False,
             before: Callable[[str], None] | None = None,
             on_done: Callable[[str, Any], None] | None = None, cluster=None) -> dict[str, Any]:
    """The one scheduler: run each named job with :func:`run_isolated`, ``workers`` at a time, in the order
    given, or each as a task of a Dask ``cluster`` (:mod:`bench.runner.cluster`); returns the results by
    name, in the order given.

    Every job is checked before any starts (unless the caller did: ``checked``). ``before(name)`` is called
    as each starts, or is handed to the cluster (it may raise to stop the rest). Each finished job is
    reported in one line, ``[k/n, t s] name: describe(result)``, or handed to ``on_done(name, result)``
    instead; jobs that did not finish raise
    :class:`~bench.runner.isolation.CallFailed`, named, once all have ended. A job's call, phases and output
    go to its :meth:`Job.folder`, else to a scratch folder. With a ``ledger``, each job that finishes is kept
    in it as it finishes, and a job it already holds is not run again where its result stands
    (:func:`~bench.runner.ledger.rerun_reason`): the studies' cases resume so; a matrix resumes
    from its records by the same rule (:mod:`bench.runner.matrix`) and gives only the runs left.
    """
    early = {name: None if checked else job.check() for name, job in jobs.items()}
    kept, other = ledger.finished(jobs) if ledger else ({}, 0)
    if kept:
        report(f"{len(kept)} of {len(jobs)} job(s) finished before, by this code: taken from {ledger.path}")
    if other:
        report(f"{other} job(s) in {ledger.path} were made by other code or with other fields: they run again")
    start = time.monotonic()
    finished: list[str] = []
    todo = [name for name in jobs if name not in kept]

    def ended(name: str, ok: bool, result: Any) -> tuple[bool, Any]:
        if ok and ledger:
            ledger.add(name, jobs[name], result)
        finished.append(name)
        if ok and on_done is not None:
            on_done(name, result)
        else:
            what = (describe(result) if describe else "done") if ok else f"did not finish ({result})"
            report(f"[{len(finished)}/{len(todo)}, {time.monotonic() - start:.0f} s] {name}: {what}")
        return ok, result

    def one(item: tuple[str, Path]) -> tuple[bool, Any]:
        name, work = item
        if before is not None:
            before(name)
        try:
            result, ok = (early[name] if early[name] is not None
                          else run_isolated(jobs[name], work, name, checked=True)), True
        except CallFailed as exc:
            result, ok = str(exc), False
        return ended(name, ok, result)

    outcomes = {name: (True, result) for name, result in kept.items()}
    if cluster is not None:
        remote = {}
        for name in todo:
            if early[name] is not None:
                outcomes[name] = ended(name, True, early[name])
                continue
            if before is not None:
                before(name)
            remote[name] = jobs[name]
        for name, ok, result in run_on_cluster(remote, cluster, workers, run_remote):
            outcomes[name] = ended(name, ok, result)
    else:
        with tempfile.TemporaryDirectory(prefix="bench-jobs-") as work:
            items = [(name, jobs[name].folder() or Path(work) / str(i)) for i, name in enumerate(todo)]
            outcomes.update(zip(todo, map_interruptibly(one, items, workers)))
    outcomes = {name: outcomes[name] for name in jobs}
    failed = [name for name, (ok, _) in outcomes.items() if not ok]
    if failed:
        raise CallFailed(f"{len(failed)} of {len(jobs)} job(s) did not finish: {', '.join(failed)}")
    return {name: result for name, (_, result) in outcomes.items()}
