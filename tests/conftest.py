"""Shared fixtures: a private data cache and small datasets."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# One BLAS and torch thread in each test process, set before numpy or torch is imported: the suite
# runs on every core at once (pytest-xdist), and a process per core that also spreads its own
# arithmetic over every core slows them all (runs pin their own threads in their own processes).
from bench.runner.threads import pin_threads, pin_torch  # noqa: E402  (imports neither numpy nor torch)

pin_threads(1)

from hypothesis import settings  # noqa: E402

# The same examples on every run and machine: a generated input that finds a fault finds it every time, and
# the suite's work does not change from one run to the next (a stored example database would make it depend
# on the runs before)
settings.register_profile("suite", derandomize=True, database=None)
settings.load_profile("suite")


def pytest_configure(config):
    pin_torch(1)
    # generated data goes to a cache private to this test session
    cache = Path(config.rootpath) / ".pytest_cache" / "data-cache"
    os.environ["SYRENETS_BENCH_CACHE"] = str(cache)


def pytest_collection_modifyitems(config, items):
    """The tests marked ``long`` first, in their order, then the rest: the workers start on the long ones
    instead of meeting one at the end while the other worker has finished."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)


@pytest.fixture(scope="session")
def double_pendulum():
    from systems import get_system

    return get_system("double_pendulum")


@pytest.fixture(scope="session")
def small_data(double_pendulum):
    """(train, test) with 512 and 256 samples, from different seeds."""
    from bench.core.data import generate

    return generate(double_pendulum, 512, 0), generate(double_pendulum, 256, 1000)


# Where the suite's workers wait: with BENCH_TIMELINE=FILE each test process appends a line a test to FILE.jsonl
# (its worker, the test, when it started and ended, and the CPU seconds it and the processes it waited for used),
# which tests/timeline.py sums into each worker's busy, waiting and idle time.
if os.environ.get("BENCH_TIMELINE"):
    import json
    import resource
    import time

    def _cpu() -> float:
        own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime + _fork_server_cpu()

    def _fork_server_cpu() -> float:
        """The CPU seconds of this process's fork server and of the runs forked from it that it has reaped: a
        test's runs are its children, not the test process's, until the server itself is reaped at exit."""
        from multiprocessing import forkserver

        pid = getattr(getattr(forkserver, "_forkserver", None), "_forkserver_pid", None)
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split() if pid else []
        except OSError:
            return 0.0
        return sum(int(t) for t in fields[11:15]) / os.sysconf("SC_CLK_TCK")  # utime, stime, cutime, cstime

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        start, cpu = time.time(), _cpu()
        yield
        line = {"worker": os.environ.get("PYTEST_XDIST_WORKER", "main"), "test": item.nodeid, "start": start,
                "end": time.time(), "cpu": _cpu() - cpu}
        with open(os.environ["BENCH_TIMELINE"] + ".jsonl", "a") as f:
            f.write(json.dumps(line) + "\n")


@pytest.fixture(scope="session")
def dask_client():
    """A Dask client of a ``LocalCluster`` of two single-threaded worker processes, as ``--cluster local``
    starts one (:func:`bench.runner.cluster.client_for`), started once for the tests that run jobs on a
    cluster (each marks itself ``xdist_group("dask")``, so that one worker starts it)."""
    pytest.importorskip("distributed")
    from bench.runner.cluster import client_for

    with client_for("local", 2) as client:
        yield client


@pytest.fixture
def system_builds(monkeypatch):
    """Every system built in this process from now on, as ``(its name, the split it was asked for)``: for the
    tests that count a command's builds."""
    from bench.physics.system import System

    built = []
    own = System.__init__

    def counted(self, *args, **kwargs):
        built.append((type(self).name, kwargs.get("split")))
        own(self, *args, **kwargs)

    monkeypatch.setattr(System, "__init__", counted)
    return built
