"""Where a cluster cannot serve, the command says so in one line before any job starts."""

from __future__ import annotations

import sys

import pytest

from bench.core.errors import UserError
from bench.runner.cluster import client_for


def test_without_dask_installed_a_cluster_is_refused_in_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed raises ImportError
    with pytest.raises(UserError, match=r"--cluster needs Dask distributed: pip install 'syrenets-bench\[dask\]'") as e:
        with client_for("local", 2):
            pytest.fail("a client without Dask")
    assert "\n" not in str(e.value)


def test_a_scheduler_that_cannot_be_reached_is_named_in_one_line(monkeypatch):
    distributed = pytest.importorskip("distributed")

    class Unreachable(distributed.Client):
        def __init__(self, address, timeout=None):
            raise OSError(f"Timed out trying to connect to {address} after {timeout}")

    monkeypatch.setattr(distributed, "Client", Unreachable)
    with pytest.raises(UserError, match="cannot reach the Dask scheduler tcp://nowhere:8786: Timed out") as e:
        with client_for("tcp://nowhere:8786", 2):
            pytest.fail("a client of an unreachable scheduler")
    assert "\n" not in str(e.value)
