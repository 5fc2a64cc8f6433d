"""A function is compiled once per process, whoever asks for it."""

from __future__ import annotations

import pytest
import torch

from bench.core.compiled import compiled_once

# with the suite's other compiling tests, in one test process (see tests/methods/test_delan.py)
pytestmark = pytest.mark.xdist_group("torch.compile")


def _square_sum(x):
    return (x ** 2).sum()


def test_a_function_is_compiled_once_and_computes_what_it_computed():
    first = compiled_once(_square_sum)
    assert compiled_once(_square_sum) is first
    x = torch.arange(4.0)
    assert torch.equal(first(x), _square_sum(x))
