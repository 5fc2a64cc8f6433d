"""Run a pure-Python computation with a hard time limit.

Symbolic algebra (sympy's expand or simplify) can take far longer than
expected and cannot be interrupted from inside. :func:`call_with_timeout`
runs such a computation in a forked child process and kills it when the time
is up, so that a method's wall-clock budget holds.
"""

from __future__ import annotations

import math
import multiprocessing
import pickle
from typing import Any, Callable

from bench.core.processes import die_with_parent


class Timeout(Exception):
    """The computation did not finish in time (it was killed)."""


def call_with_timeout(fn: Callable[[], Any], seconds: float) -> Any:
    """Return ``fn()``, computed in a forked child, or raise :class:`Timeout`.

    ``fn`` must return something picklable. Exceptions raised by ``fn`` are
    re-raised here. Where ``fork`` is unavailable, ``fn`` runs in this process
    without a limit.
    """
    if seconds <= 0:
        raise Timeout("no time left")
    try:
        ctx = multiprocessing.get_context("fork")
    except ValueError:
        return fn()
    reader, writer = ctx.Pipe(duplex=False)

    def child() -> None:
        die_with_parent()
        try:
            payload = (True, fn())
        except BaseException as exc:  # report any failure to the parent
            payload = (False, exc)
        try:
            writer.send_bytes(pickle.dumps(payload))
        except Exception as exc:  # an unpicklable result or exception
            writer.send_bytes(pickle.dumps((False, RuntimeError(f"{type(exc).__name__}: {exc}"))))
        writer.close()

    proc = ctx.Process(target=child, daemon=True)
    proc.start()
    writer.close()
    try:
        if not reader.poll(None if math.isinf(seconds) else seconds):
            raise Timeout(f"not done after {seconds:.1f} s")
        ok, value = pickle.loads(reader.recv_bytes())
    except EOFError:
        raise RuntimeError(f"the child computing {getattr(fn, '__name__', 'the result')} died (exit code {proc.exitcode})") from None
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()
        reader.close()
    if not ok:
        raise value
    return value
