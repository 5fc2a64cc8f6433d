"""The one scheduler: every job of the suite (:mod:`bench.runner.job`), many at a time.

:func:`run_jobs` runs a matrix's runs, its stacked groups, the residual loop's
jobs, the studies' cases and ``bench select``'s candidates: ``workers`` at a
time here, each in its own process (:func:`~bench.runner.job.run_isolated`),
or each as a task of a Dask cluster (:mod:`bench.runner.cluster`), with one
rule to resume from a :class:`~bench.runner.ledger.Ledger`.
"""

from __future__ import annotations

import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

from bench.runner.cluster import run_on_cluster
from bench.runner.isolation import kill_children
from bench.core.errors import CallFailed
from bench.runner.job import Job, run_isolated
from bench.runner.ledger import Ledger


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
    :class:`~bench.core.errors.CallFailed`, named, once all have ended. A job's call, phases and output
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


def map_interruptibly(fn: Callable, items: list, workers: int) -> Iterator:
    """``fn`` over ``items`` on ``workers`` threads, results in order, like
    ``ThreadPoolExecutor.map``; if the caller is interrupted (Ctrl-C, or any
    error), queued items are dropped and running children killed at once
    instead of being waited for."""
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        yield from pool.map(fn, items)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        kill_children()
        raise
    finally:
        pool.shutdown(wait=True)
