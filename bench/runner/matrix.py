"""The matrix: systems x methods x experiments x seeds under a wall-clock budget.

* :class:`RunJob` is one :class:`~bench.runner.spec.RunSpec` as a job
  (:mod:`bench.runner.job`), run in its own process with torch and BLAS
  threads pinned (:func:`run_one`), which writes its record. Its fit is
  killed at :func:`~bench.runner.job.fit_limit`, and what follows the fit
  (scores on the full data, variants, the exact-recovery judgement, the
  rollout) at :func:`~bench.runner.job.evaluation_limit`; either gives
  status ``timeout``. A crash or a non-finite result gives status
  ``failed`` with the reason.
* :func:`run_matrix` runs many specs on a pool of worker processes, or on
  Dask distributed, writes one record per run atomically, and skips runs that
  already have a valid record, so a killed matrix loses no finished run and
  re-running it resumes. A corrupt record is moved aside
  (:func:`~bench.runner.records.quarantine`) and its run redone. One matrix
  at a time may write into a folder (:class:`FolderLock`).
"""

from __future__ import annotations

import fcntl
import os
import pickle
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from bench.core.errors import UserError
from bench.core.processes import process_alive
from bench.runner.code import code_hash
from bench.runner.execute import execute, preflight
from bench.runner.isolation import STARTUP_TIMEOUT_S, Outcome, map_interruptibly
from bench.runner.job import PREPARE_MIN_S, Job, evaluation_limit, fit_limit, fit_limit_words, run_isolated
from bench.runner.plugins import import_plugins
from bench.runner.progress import MatrixProgress, Report, print_now
from bench.runner.provenance import CODE_FOLDERS, code_state
from bench.runner.records import Record, RecordError, quarantine, read_record, record_path, write_record
from bench.runner.spec import RunSpec
from bench.runner.stacked import groups, run_stacked, stack_name

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

    @classmethod
    def of(cls, spec: RunSpec, out_dir: str | os.PathLike, data_file: str | None = None) -> "RunJob":
        return cls(spec.to_dict(), str(out_dir), data_file)

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
        early = early.replace(code=code_hash(spec.method, spec.system, spec.plugins))
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
        record = execute(spec, on_phase, data=data, checked=True)
        return record.replace(code=code_hash(spec.method, spec.system, spec.plugins)).to_json()

    def result_file(self, work: Path, name: str) -> Path:
        return record_path(self.out_dir, name)

    def finish(self, outcome: Outcome, report) -> Record:
        """The record the child wrote; where it wrote none (it failed or was killed), the one written here."""
        spec = self.run_spec
        path = record_path(self.out_dir, spec.run_id)
        if outcome.result is not None:
            return Record.from_json(outcome.result, str(path))
        limits = self.limits()
        code = code_hash(spec.method, spec.system, spec.plugins)
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
) -> list[Record]:
    """Run every spec, ``workers`` at a time, each in its own process.

    Runs that already have a valid record in ``out_dir`` are skipped
    (``resume``), unless the record was made by other code (its ``code``
    hash, :mod:`bench.runner.code`, differs from the code's now) or for
    another configuration (its spec differs), or, with ``retry_failed``,
    the run failed or timed out; each such run is redone, and the report
    says how many and why. A record file that is not valid is reported in
    one line, moved to ``records/corrupt/`` and its run redone. Unavailable and
    not-applicable runs are recorded without starting a process. Returns the
    records in the order of ``specs``. Holds :class:`FolderLock` on
    ``out_dir`` throughout; an interrupted matrix kills its running children.

    ``cluster`` hands the runs to Dask distributed instead of the local pool:
    ``"local"`` starts a ``LocalCluster`` of ``workers`` single-threaded
    processes; a scheduler address (``"tcp://host:8786"``), a Dask cluster
    object (``dask_jobqueue.SLURMCluster(...)``) or a ``Client`` uses that.
    Each Dask task runs :func:`run_one` on its worker, in a scratch
    directory there, and returns the record, which is written here; workers
    need the suite installed, not a shared file system.

    ``stack`` trains the seeds of a stackable method's runs that differ only
    in their seed as one model, in one process (:mod:`bench.runner.stacked`),
    on the local pool.
    """
    import_plugins({p for s in specs for p in s.plugins})
    report = report if report is not None else print_now
    workers = workers or default_workers()
    out_dir = Path(out_dir)
    with FolderLock(out_dir):
        return _run_matrix(specs, out_dir, workers, resume, report, cluster, retry_failed, stack)


def stale(record: Record, spec: RunSpec, retry_failed: bool = False) -> str | None:
    """Why ``record`` does not stand for ``spec`` as it would run now (``None``: it does)."""
    now = code_hash(spec.method, spec.system, spec.plugins)
    if record.code is not None and now is not None and record.code.get("hash") != now["hash"]:
        return "made by other code"
    if record.spec and RunSpec.from_dict(record.spec).to_dict() != spec.to_dict():
        return "made with another configuration"
    if retry_failed and record.status in ("failed", "timeout"):
        return record.status
    return None


def _run_matrix(specs: list[RunSpec], out_dir: Path, workers: int, resume: bool, report: Report, cluster,
                retry_failed: bool, stack: bool = False) -> list[Record]:
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
                why = stale(record, spec, retry_failed)
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

    if todo and cluster is not None:
        for record in _run_on_dask(todo, out_dir, cluster, workers):
            results[record.run_id] = done(record)
    elif todo and stack:
        def job(group: list[RunSpec]) -> list[Record]:
            unchanged(group[0])
            out = run_stacked(group, out_dir, lambda s: run_one(s, out_dir, checked=True), phase_limits(group[0]))
            return [done(r, log_path(out_dir, stack_name(group) if r.details.get("stacked") else r.run_id)) for r in out]

        for records in map_interruptibly(job, groups(todo, report), workers):
            results.update((r.run_id, r) for r in records)
    elif todo:
        for record in map_interruptibly(lambda s: done(run_one(unchanged(s), out_dir, checked=True), log_path(out_dir, s.run_id)),
                                        todo, workers):
            results[record.run_id] = record
    tracker.summary()
    return [results[s.run_id] for s in specs]


def _describe(record: Record, log: Path | None = None) -> str:
    if record.status == "ok":
        test = record.test_mse
        outcome = f"ok train {record.train_mse:.3g} test {'-' if test is None else f'{test:.3g}'}"
        if record.failed_stages:
            outcome += f" (failed after the fit: {', '.join(record.failed_stages)}{f'; log {log}' if log else ''})"
    else:
        outcome = f"{record.status} ({record.error}{f'; log {log}' if log else ''})"
    return f"{record.system} {record.method} {record.experiment} seed={record.seed}: {outcome}"


def run_remote(spec_dict: dict) -> dict:
    """A Dask task: :func:`run_one` in a scratch directory; returns the record's JSON."""
    with tempfile.TemporaryDirectory(prefix="syrenets-bench-") as scratch:
        return run_one(RunSpec.from_dict(spec_dict), scratch, checked=True).to_json()


def _run_on_dask(todo: list[RunSpec], out_dir: Path, cluster, workers: int) -> Iterable[Record]:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UserError("--cluster needs Dask distributed: pip install 'syrenets-bench[dask]'") from None
    own = None
    if cluster == "local":
        own = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(own)
    elif isinstance(cluster, Client):
        client = cluster
    else:
        try:
            client = Client(cluster, timeout="30s")
        except OSError as exc:
            raise UserError(f"cannot reach the Dask scheduler {cluster}: {exc}") from None
    try:
        futures = [client.submit(run_remote, s.to_dict(), key=f"bench-{s.run_id}-{time.time_ns()}", pure=False) for s in todo]
        for future in as_completed(futures):
            record = Record.from_json(future.result(), "a Dask worker's record")
            write_record(record_path(out_dir, record.run_id), record)
            yield record
    finally:
        if client is not cluster:
            client.close()
        if own is not None:
            own.close()
