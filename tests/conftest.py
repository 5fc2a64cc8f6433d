"""Shared fixtures: a private data cache and small datasets."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def pytest_configure(config):
    # generated data goes to a cache private to this test session
    cache = Path(config.rootpath) / ".pytest_cache" / "data-cache"
    os.environ["SYRENETS_BENCH_CACHE"] = str(cache)


@pytest.fixture(scope="session")
def double_pendulum():
    from systems import get_system

    return get_system("double_pendulum")


@pytest.fixture(scope="session")
def small_data(double_pendulum):
    """(train, test) with 512 and 256 samples, from different seeds."""
    from bench.core.data import generate

    return generate(double_pendulum, 512, 0), generate(double_pendulum, 256, 1000)
