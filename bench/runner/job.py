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
  its process ended (:class:`Outcome`), a kill or a crash included.

:func:`run_isolated` runs one job this way; :func:`bench.runner.schedule.run_jobs`,
the one scheduler, runs many side by side. Jobs are a matrix's runs
(:class:`bench.runner.run.RunJob`) and its stacked groups
(:class:`bench.runner.stacked.StackedJob`), the residual loop
(:class:`bench.residual.job.ResidualJob`) and the studies' cases
(:class:`CaseJob`).

How a job travels (:func:`run_watched`): its call, a JSON file ``{"job":
"module:Class", "fields": {...}, "threads": n}``, is written to the job's
folder; a child process (:class:`bench.runner.isolation.Child`) runs
:func:`run_in_child` on it, which pins the threads, makes the job again from
its fields, runs it and writes the JSON it returns to the result file,
atomically. ``on_phase(name)`` appends the phase's name to the phase file,
from which the parent times each phase's limit, and kills the child's whole
process group when it stays in a phase longer than that.

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from bench.core.budget import SECONDS, Budget
from bench.core.errors import CallFailed
from bench.core.fileio import write_json
from bench.runner.isolation import Child
from bench.runner.ledger import suite_code
from bench.runner.progress import print_now
from bench.runner.threads import pin_threads, pin_torch

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


#: the phase a child is in until it reports another
STARTUP = "startup"
#: seconds a child may take to import and load its data before its first phase
STARTUP_TIMEOUT_S = 300.0


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


@dataclass(frozen=True)
class Outcome:
    """How a job's process ended.

    Attributes
    ----------
    result
        The JSON the job's :meth:`~Job.run` returned; ``None`` when it did not return.
    phase
        The last phase the child reported (``"startup"`` if none).
    killed
        The child stayed in ``phase`` past its limit and was killed.
    exit_code
        The child's exit code (``None`` when killed).
    log_tail
        The last lines of the child's output, for a child that died.
    interrupted
        The caller was interrupted and killed the child (:func:`~bench.runner.isolation.kill_children`):
        the call neither finished nor failed.
    """

    result: dict | None
    phase: str
    killed: bool = False
    exit_code: int | None = None
    log_tail: str = ""
    interrupted: bool = False


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
        else :class:`CallFailed`."""
        if outcome.result is None:
            raise CallFailed(f"killed in its {outcome.phase} phase" if outcome.killed else outcome.log_tail)
        return outcome.result

    def result_file(self, work: Path, name: str) -> Path:
        """Where the child writes what :meth:`run` returns."""
        return work / f"{name}.result.json"

    def folder(self) -> Path | None:
        """Where :func:`~bench.runner.schedule.run_jobs` keeps the job's call, phases and output (``None``: a scratch folder, removed
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


def job_fields(job: Job) -> dict:
    """What a job is, as its ledger compares it: its class and its fields, as JSON reads them back."""
    return json.loads(json.dumps({"job": f"{type(job).__module__}:{type(job).__qualname__}",
                                  "fields": job.payload()}))


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
    outcome = run_watched(job, Path(work), name, fresh=fresh, poll_s=poll_s, echo=echo)
    if outcome.interrupted:
        raise KeyboardInterrupt(f"{name} interrupted")
    return job.finish(outcome, echo or print_now)


def run_watched(job: Job, work: Path, name: str, *, fresh: bool = False, poll_s: float = 0.05,
                echo: Callable[[str], None] | None = None) -> Outcome:
    """Run ``job`` in its own process and wait for it: how its process ended.

    The child writes what :meth:`Job.run` returns to :meth:`Job.result_file`; the job's call, phases and
    output go to ``work/<name>.*``. :meth:`Job.limits` gives the seconds allowed in each phase, counted
    from the phase's start; the start-up phase has :data:`STARTUP_TIMEOUT_S` unless the job says
    otherwise, and a phase without a limit has none. ``echo``, if given, receives each line the child
    prints, as it prints it.
    """
    result_file = job.result_file(work, name)
    work.mkdir(parents=True, exist_ok=True)
    call_file, phase_file, log_file = (work / f"{name}{s}" for s in (".call.json", ".phase", ".log"))
    for f in (phase_file, result_file, log_file):
        f.unlink(missing_ok=True)
    write_json(call_file, {**job_fields(job), "threads": job.threads})
    limits = {STARTUP: STARTUP_TIMEOUT_S, **job.limits()}
    child = Child("bench.runner.job:run_in_child", tuple(map(str, (call_file, result_file, phase_file))),
                  job.threads, log_file, fresh)
    phase = STARTUP
    kill_at = time.monotonic() + limits[STARTUP]
    output = _Lines(log_file, echo)
    while not child.wait(poll_s):
        output.read()
        now = time.monotonic()
        new_phase = _read_phase(phase_file) or phase
        if new_phase != phase:
            phase = new_phase
            kill_at = now + limits.get(phase, float("inf"))
        if now >= kill_at:
            child.kill()
            output.read(final=True)
            return Outcome(None, phase, killed=True)
    output.read(final=True)
    if child.interrupted:
        return Outcome(None, phase, interrupted=True)
    phase = _read_phase(phase_file) or phase
    result = _read_result(result_file)
    if result is None:
        return Outcome(None, phase, exit_code=child.returncode, log_tail=_tail(log_file))
    return Outcome(result, phase, exit_code=child.returncode)


class _Lines:
    """The lines a child has added to its log since the last read, passed to ``echo``."""

    def __init__(self, path: Path, echo: Callable[[str], None] | None):
        self.path, self.echo, self.offset, self.partial = path, echo, 0, b""

    def read(self, final: bool = False) -> None:
        if self.echo is None:
            return
        try:
            with open(self.path, "rb") as f:
                f.seek(self.offset)
                chunk = f.read()
        except OSError:
            return
        self.offset += len(chunk)
        *lines, self.partial = (self.partial + chunk).split(b"\n")
        if final and self.partial:
            lines.append(self.partial)
            self.partial = b""
        for line in lines:
            self.echo(line.decode(errors="replace"))


def _read_result(path: Path) -> dict | None:
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _read_phase(path: Path) -> str | None:
    try:
        lines = path.read_text().split()
    except OSError:
        return None
    return lines[-1] if lines else None


def _tail(path: Path, lines: int = 3) -> str:
    try:
        text = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return "(no log)"
    return " | ".join(text[-lines:]) or "(empty log)"


# The child's side.

def run_in_child(call_file: str, result_file: str, phase_file: str) -> None:
    """The job in ``call_file``, made again from its fields and run in this (child) process; what it returns
    goes to ``result_file``, the phases it enters to ``phase_file``. The thread variables numpy's and torch's
    BLAS read were set before they were imported: in a fresh interpreter's environment by the parent
    (:func:`~bench.runner.threads.thread_env`), in the fork server by the server; torch's own thread counts
    are set here."""
    with open(call_file) as f:
        call = json.load(f)
    threads = int(call.get("threads", 1))
    pin_threads(threads)
    pin_torch(threads)
    module, _, name = call["job"].partition(":")
    job = getattr(importlib.import_module(module), name).from_payload(call["fields"])

    def on_phase(phase: str) -> None:
        with open(phase_file, "a") as f:
            f.write(phase + "\n")

    write_json(result_file, job.run(on_phase))
