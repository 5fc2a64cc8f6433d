"""Processes that end with the one that started them.

:func:`die_with_parent` asks the kernel (Linux's ``PR_SET_PDEATHSIG``) to
kill this process when its parent ends, however the parent ends, even by
``kill -9``; every child process the suite starts calls it first. Where the
call is not available (another platform), children still end when their
parent's pipe to them closes, or at their own limits.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal

PR_SET_PDEATHSIG = 1


def die_with_parent() -> bool:
    """Be killed (SIGKILL) when the parent process ends; exit now if it
    already has. Returns whether the kernel took the request."""
    parent = os.getppid()
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        ok = libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False
    if ok and os.getppid() != parent:  # the parent ended before the request was made
        os._exit(1)
    return ok


def process_alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this machine (zombies count as ended)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True
