"""Jobs on Dask distributed: where :func:`bench.runner.schedule.run_jobs` runs its
jobs when it is given a cluster instead of its local pool.

``cluster`` is ``"local"`` (a ``LocalCluster`` of ``workers`` single-threaded
processes started here), a scheduler's address (``"tcp://host:8786"``), a
Dask cluster object (``dask_jobqueue.SLURMCluster(...)``) or a ``Client``.
Each job is one task: on its worker it runs as :func:`~bench.runner.job.run_isolated`
runs it locally, in its own process, in a scratch folder there
(:meth:`~bench.runner.job.Job.elsewhere`), and its result comes back
(:meth:`~bench.runner.job.Job.packed`) to be kept here
(:meth:`~bench.runner.job.Job.land`: a run's record and model file are written
where the caller asked). Workers need the suite installed, not a shared file system.
"""

from __future__ import annotations

import contextlib
import time
from typing import Any, Callable, Iterator

from bench.core.errors import UserError


@contextlib.contextmanager
def client_for(cluster, workers: int):
    """A Dask ``Client`` for ``cluster`` (module docstring), closed on leaving
    unless the caller gave it; :class:`UserError` in one line where Dask is
    not installed or the scheduler cannot be reached."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise UserError("--cluster needs Dask distributed: pip install 'syrenets-bench[dask]'") from None
    own = None
    if cluster == "local":
        import dask

        # workers that are not daemonic processes may start the fork server that jobs fork from
        # (bench.runner.isolation.fork_server), instead of a fresh interpreter for each job
        with dask.config.set({"distributed.worker.daemon": False}):
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
        yield client
    finally:
        if client is not cluster:
            client.close()
        if own is not None:
            own.close()


def run_on_cluster(jobs: dict, cluster, workers: int, task: Callable) -> Iterator[tuple[str, bool, Any]]:
    """Each of ``jobs`` (``{name: job}``) as a task of ``cluster``, ``task(job, name)`` on its worker
    returning ``(finished, result)``; ``(name, finished, result)`` as each ends, its result landed here
    (:meth:`~bench.runner.job.Job.land`)."""
    from distributed import as_completed

    with client_for(cluster, workers) as client:
        names = {client.submit(task, job, name, key=f"bench-{name}-{time.time_ns()}", pure=False): name
                 for name, job in jobs.items()}
        for future in as_completed(list(names)):
            name = names[future]
            ok, result = future.result()
            yield name, ok, jobs[name].land(result) if ok else result
