"""Thread pinning: parallel runs must not oversubscribe the cores.

The variables are read by numpy's and torch's BLAS when they are first
imported, so :func:`pin_threads` is called before that, in the process that
runs (or, for the fork server, before the server imports them).
"""

from __future__ import annotations

import os

THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def pin_threads(threads: int) -> None:
    """Set the thread variables in this process; call before numpy or torch is imported."""
    os.environ.update(thread_env(threads, {}))


def thread_env(threads: int, base: dict | None = None) -> dict:
    """``base`` (default: this process's environment) with the thread variables set."""
    env = dict(os.environ if base is None else base)
    for var in THREAD_VARS:
        env[var] = str(threads)
    return env


def pin_torch(threads: int) -> None:
    """torch's intra-op threads, and one inter-op thread where torch still allows setting it."""
    import torch

    torch.set_num_threads(threads)
    if torch.get_num_interop_threads() != 1:
        try:
            torch.set_num_interop_threads(1)
        except RuntimeError:  # already fixed in this process (a forked one)
            pass
