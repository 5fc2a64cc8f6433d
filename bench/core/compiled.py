"""A function compiled by ``torch.compile`` once per process.

A training step that takes its network as an argument compiles to graphs that
every network of the same shapes reuses, so each such function is compiled
once in a process (:func:`compiled_once`), with static shapes, and its
compiler runs in the process itself: a run has one core, and a pool of
compiling processes would only compete for it.
"""

from __future__ import annotations

import functools
from typing import Callable

import torch


@functools.cache
def compiled_once(function: Callable) -> Callable:
    """``torch.compile(function, dynamic=False)``, the same object on every call for ``function``."""
    import torch._inductor.config  # torch's compiler, loaded only by a run that compiles

    torch._inductor.config.compile_threads = 1
    return torch.compile(function, dynamic=False)
