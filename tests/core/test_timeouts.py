"""Hard time limits for symbolic work."""

from __future__ import annotations

import time

import pytest
import sympy

from bench.core.timeouts import Timeout, call_with_timeout


def test_returns_the_result():
    x = sympy.Symbol("x")
    assert call_with_timeout(lambda: sympy.expand((x + 1) ** 3), 10) == x**3 + 3 * x**2 + 3 * x + 1


def test_kills_a_computation_that_runs_over():
    with pytest.raises(Timeout):  # a computation left to run would return None after 30 s
        call_with_timeout(lambda: time.sleep(30), 0.5)


def test_reraises_the_childs_exception():
    def boom():
        raise ValueError("bad algebra")

    with pytest.raises(ValueError, match="bad algebra"):
        call_with_timeout(boom, 10)
