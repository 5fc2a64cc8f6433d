"""The matrix: systems x methods x experiments x seeds under a wall-clock budget.

* Each run is a :class:`~bench.runner.run.RunJob`, run in its own process,
  which writes its record (:mod:`bench.runner.run`).
* :func:`run_matrix` runs many specs through the one scheduler,
  :func:`~bench.runner.schedule.run_jobs`, each stacked group of seeds as one
  :class:`~bench.runner.stacked.StackedJob` (``stack``), or on Dask
  distributed, writes one record per run atomically, and skips runs that
  already have a valid record, so a killed matrix loses no finished run and
  re-running it resumes. A corrupt record is moved aside
  (:func:`~bench.runner.records.quarantine`) and its run redone. One matrix
  at a time may write into a folder (:class:`FolderLock`).
"""

from __future__ import annotations

import fcntl
import os
import time
from pathlib import Path

from bench.core.errors import UserError
from bench.core.processes import process_alive
from bench.runner.job import Job
from bench.runner.schedule import run_jobs
from bench.runner.ledger import rerun_reason
from bench.runner.plugins import import_plugins
from bench.runner.progress import MatrixProgress, Report, print_now
from bench.runner.provenance import CODE_FOLDERS, code_state
from bench.runner.records import Record, RecordError, quarantine, read_record, record_path
from bench.runner.run import RunJob, log_path
from bench.runner.spec import UNNAMED, RunSpec
from bench.runner.stacked import StackedJob, groups

class FolderLock:
    """One matrix at a time writes into a folder: an exclusive ``flock`` on
    ``OUT/.lock``, which the kernel releases when its holder ends, however it
    ends, so a killed matrix leaves no stale lock. The file holds the
    holder's process id and start time, for the message to a second matrix."""

    def __init__(self, folder: str | os.PathLike):
        self.path = Path(folder) / ".lock"
        self.fd: int | None = None

    def __enter__(self) -> "FolderLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 200).decode(errors="replace").split()
            os.close(fd)
            who = f"process {holder[0]}, started {holder[1]}" if len(holder) >= 2 and process_alive(int(holder[0])) \
                else "another process"
            raise UserError(f"{self.path.parent}: another matrix is writing here ({who}); "
                            "wait for it to end or choose another --out") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {time.strftime('%Y-%m-%dT%H:%M:%S')}\n".encode())
        self.fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            os.close(self.fd)  # releases the lock
            self.fd = None


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


def run_matrix(
    specs: list[RunSpec],
    out_dir: str | os.PathLike,
    *,
    workers: int | None = None,
    resume: bool = True,
    report: Report | None = None,
    cluster=None,
    retry_failed: bool = False,
    stack: bool = False,
    share_priors: bool = False,
) -> list[Record]:
    """Run every spec, ``workers`` at a time, each in its own process.

    Runs that already have a valid record in ``out_dir`` are skipped
    (``resume``), unless the record was made by other code (its ``code``
    hash, :func:`bench.runner.sources.code_hash`, differs from the code's now) or for
    another configuration (its spec differs), or, with ``retry_failed``,
    the run failed or timed out; each such run is redone, and the report
    says how many and why. A record file that is not valid is reported in
    one line, moved to ``records/corrupt/`` and its run redone. Unavailable and
    not-applicable runs are recorded without starting a process. Returns the
    records in the order of ``specs``. Holds :class:`FolderLock` on
    ``out_dir`` throughout; an interrupted matrix kills its running children.

    ``cluster`` hands the runs to Dask distributed instead of the local pool
    (:mod:`bench.runner.cluster`: ``"local"``, a scheduler's address, a Dask
    cluster object or a ``Client``): each run is a task, run on its worker
    in a scratch folder there, and its record is written here; workers need
    the suite installed, not a shared file system.

    ``stack`` trains the seeds of a stackable method's runs that differ only
    in their seed as one model, in one process (:mod:`bench.runner.stacked`),
    on the local pool.

    ``share_priors`` lets the runs share the hybrids' priors they identify through
    ``out_dir/priors`` (:func:`methods.hybrid.share_priors`): a prior identified by
    one run, on the same samples with the same seed, is read by the others.
    """
    import_plugins({p for s in specs for p in s.plugins})
    report = report if report is not None else print_now
    workers = workers or default_workers()
    out_dir = Path(out_dir)
    with FolderLock(out_dir):
        return _run_matrix(specs, out_dir, workers, resume, report, cluster, retry_failed, stack,
                           out_dir / "priors" if share_priors else None)


def stale(record: Record, job: RunJob, retry_failed: bool = False) -> str | None:
    """Why ``record`` does not stand for ``job`` as it would run now (``None``: it does): the one resume
    rule (:func:`~bench.runner.ledger.rerun_reason`), and, with ``retry_failed``, a run that failed."""
    why = rerun_reason(job, (record.code or {}).get("hash"),
                       RunSpec.from_dict(record.spec).to_dict() if record.spec else None)
    if why is None and retry_failed and record.status in ("failed", "timeout"):
        return record.status
    return why


def _run_matrix(specs: list[RunSpec], out_dir: Path, workers: int, resume: bool, report: Report, cluster,
                retry_failed: bool, stack: bool = False, priors: Path | None = None) -> list[Record]:
    results: dict[str, Record] = {}
    todo: list[RunSpec] = []
    resumed = cannot_run = 0
    redone: dict[str, int] = {}
    for spec in specs:
        path = record_path(out_dir, spec.run_id)
        if resume and path.exists():
            try:
                record = read_record(path)
            except RecordError as exc:
                report(f"warning: {exc}; moved to {quarantine(path)}, and the run is redone")
            else:
                why = stale(record, RunJob.of(spec, out_dir), retry_failed)
                if why is None:
                    results[spec.run_id] = record
                    resumed += 1
                    continue
                redone[why] = redone.get(why, 0) + 1
        early = RunJob.of(spec, out_dir).check()
        if early:
            results[spec.run_id] = early
            cannot_run += 1
            continue
        todo.append(spec)
    if report and redone:
        report("redoing " + ", ".join(f"{n} run(s) whose record was {why}" if why.startswith("made") else
                                      f"{n} run(s) that {'failed' if why == 'failed' else 'timed out'}"
                                      for why, n in sorted(redone.items())))
    if report and cannot_run:
        report(f"{cannot_run} run(s) recorded without running (method unavailable here or not applicable)")
    tracker = MatrixProgress(len(todo), resumed, workers, report)
    started = code_state()

    def unchanged(spec: RunSpec) -> RunSpec:
        """``spec``, where the code is still the code the matrix started with; else
        :class:`UserError`: a run started now would record the new files' hash
        beside the old commit, in a process whose code is partly the old."""
        if started is not None and code_state() != started:
            raise UserError(f"{out_dir}: the code changed while this matrix ran (a commit, a merge or an edit in "
                            f"{', '.join(CODE_FOLDERS)}); stopped before {spec.run_id}: run the command again, "
                            f"and it redoes on the new code the runs whose record was made by other code")
        return spec

    def done(record: Record, log: Path | None = None) -> Record:
        tracker.done(record.status == "ok", _describe(record, log))
        return record

    if todo:
        jobs: dict[str, Job] = {}
        first: dict[str, RunSpec] = {}
        for group in groups(todo, report) if stack else [[s] for s in todo]:
            job = RunJob.of(group[0], out_dir, priors=priors) if len(group) == 1 else StackedJob.of(group, out_dir)
            name = group[0].run_id if len(group) == 1 else job.name
            jobs[name], first[name] = job, group[0]

        def finished(name: str, result) -> None:
            for r in result if isinstance(result, list) else [result]:
                log = None if cluster is not None else log_path(out_dir, name if r.details.get("stacked") else r.run_id)
                results[r.run_id] = done(r, log)

        run_jobs(jobs, workers, None, report, checked=True, before=lambda name: unchanged(first[name]),
                 on_done=finished, cluster=cluster)
    tracker.summary()
    return [results[s.run_id] for s in specs]


def _describe(record: Record, log: Path | None = None) -> str:
    if record.status == "ok":
        tuning = (record.details or {}).get("tuning")
        if tuning:  # a tuned run's line gives the figure it was validated by; its test MSE waits for the table or
            # the page, after any choice among the runs (``bench select``'s) is made
            validation = tuning.get("validation_mse")
            outcome = f"ok train {record.train_mse:.3g} validation {'-' if validation is None else f'{validation:.3g}'}"
        else:
            test = record.test_mse
            outcome = f"ok train {record.train_mse:.3g} test {'-' if test is None else f'{test:.3g}'}"
        if record.failed_stages:
            outcome += f" (failed after the fit: {', '.join(record.failed_stages)}{f'; log {log}' if log else ''})"
    else:
        outcome = f"{record.status} ({record.error}{f'; log {log}' if log else ''})"
    profile = (record.spec or {}).get("profile", "default")
    named = "" if profile in UNNAMED else f" ({profile})"  # two configurations of one method are two runs
    return f"{record.system} {record.method}{named} {record.experiment} seed={record.seed}: {outcome}"
