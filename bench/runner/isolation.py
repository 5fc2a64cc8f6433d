"""Process isolation: the processes jobs run in (:mod:`bench.runner.job`).

A :class:`Child` calls a function, named by its import path (``"module:function"``), with string
arguments, in a process of its own session, so that its whole process group can be killed
(:meth:`Child.kill`, and :func:`kill_children` for an interrupted caller). It first asks to be killed
when its parent ends (:func:`bench.core.processes.die_with_parent`).

The child is forked from a fork server (:func:`fork_server`) that has
imported torch, the suite and both registries once (:mod:`bench.runner.preload`),
so a run does not pay for those imports; where the server cannot be used (no
``fork`` on the platform, inside a daemonic process such as a Dask worker
started as Dask starts them by default, a child with more than one thread, or
``fresh=True``) the child is a fresh interpreter started with the thread
variables set (:data:`_FRESH_CHILD`). What the function is given and returns,
and the limits it runs under, are the job's (:func:`bench.runner.job.run_watched`).
"""

from __future__ import annotations

import atexit
import importlib
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Sequence

from bench.core.processes import die_with_parent
from bench.runner.provenance import PROJECT_ROOT
from bench.runner.threads import THREAD_VARS, thread_env

_FORK_SERVER = {"context": None, "failed": None}


def fork_server():
    """The multiprocessing fork server that calls are forked from, started on
    first use with :mod:`bench.runner.preload` imported, or ``None`` where it
    cannot be used: no ``fork`` on this platform, inside a daemonic process (a
    Dask worker, unless started otherwise as ``--cluster local`` starts them:
    :func:`bench.runner.cluster.client_for`), or it failed to start."""
    if _FORK_SERVER["context"] is not None or _FORK_SERVER["failed"]:
        return _FORK_SERVER["context"]
    if "forkserver" not in multiprocessing.get_all_start_methods() or multiprocessing.current_process().daemon:
        _FORK_SERVER["failed"] = "unsupported here"
        return None
    from multiprocessing import forkserver

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["bench.runner.preload"])
    saved = {var: os.environ.get(var) for var in THREAD_VARS}
    try:
        os.environ.update({var: "1" for var in THREAD_VARS})  # read by the server before it imports torch
        forkserver.ensure_running()
    except Exception as exc:
        _FORK_SERVER["failed"] = f"{type(exc).__name__}: {exc}"
        return None
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value
    _FORK_SERVER["context"] = ctx
    atexit.register(stop_fork_server, os.getpid())
    return ctx


def stop_fork_server(owner: int, server=None, wait_s: float = 10.0) -> None:
    """At the exit of the process that started the fork server: ask the
    server to end (close the pipe that keeps it alive) and reap it, so that it
    does not outlive its caller and the CPU it and the processes forked from it
    used counts as the caller's children's (``getrusage``, ``time``), as a
    fresh child's does. Waits at most ``wait_s`` seconds: a forked process
    still running holds a copy of the pipe, and the server then ends after it.
    ``server``: multiprocessing's (the default) or another ``ForkServer``."""
    from multiprocessing import forkserver

    server = server or getattr(forkserver, "_forkserver", None)
    pid, fd = getattr(server, "_forkserver_pid", None), getattr(server, "_forkserver_alive_fd", None)
    if os.getpid() != owner or pid is None or fd is None:
        return
    os.close(fd)
    server._forkserver_alive_fd = None
    deadline = time.monotonic() + wait_s
    while time.monotonic() < deadline:
        try:
            if os.waitpid(pid, os.WNOHANG)[0]:
                break
        except ChildProcessError:
            break
        time.sleep(0.01)
    else:
        return
    server._forkserver_pid = None


#: the children running now, killed by :func:`kill_children` when their caller is interrupted
_RUNNING: set["Child"] = set()
_RUNNING_LOCK = threading.Lock()


def kill_children() -> int:
    """Kill every child still running (for an interrupted caller); returns how many."""
    with _RUNNING_LOCK:
        children = list(_RUNNING)
    for child in children:
        child.interrupted = True
        child.kill()
    return len(children)


class Child:
    """A running child: ``entry(*args)`` (``entry`` is ``"module:function"``) in a process forked from the
    fork server, or in a fresh interpreter, with ``threads`` torch and BLAS threads; its output goes to
    ``log_file``."""

    def __init__(self, entry: str, args: Sequence[str], threads: int, log_file: Path, fresh: bool):
        ctx = None if fresh or threads != 1 else fork_server()
        self.proc = self.popen = None
        self.interrupted = False
        if ctx is not None:
            self.proc = ctx.Process(target=forked_main, args=(entry, tuple(args), str(log_file), os.getcwd()))
            self.proc.start()
            self._register()
            return
        env = thread_env(threads)
        root = str(PROJECT_ROOT)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        with open(log_file, "wb") as log:
            self.popen = subprocess.Popen(
                [sys.executable, "-c", _FRESH_CHILD, entry, *args],
                env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
            )
        self._register()

    def _register(self) -> None:
        with _RUNNING_LOCK:
            _RUNNING.add(self)

    @property
    def pid(self) -> int:
        return self.proc.pid if self.proc is not None else self.popen.pid

    def wait(self, timeout: float | None) -> bool:
        """Wait up to ``timeout`` seconds; whether the process has ended."""
        if self.proc is not None:
            self.proc.join(timeout)
            ended = self.proc.exitcode is not None
        else:
            try:
                self.popen.wait(timeout=timeout)
                ended = True
            except subprocess.TimeoutExpired:
                ended = False
        if ended:
            with _RUNNING_LOCK:
                _RUNNING.discard(self)
        return ended

    @property
    def returncode(self) -> int | None:
        return self.proc.exitcode if self.proc is not None else self.popen.returncode

    def kill(self) -> None:
        """Kill the child's whole process group (it runs in its own session)."""
        try:
            os.killpg(self.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            if self.proc is not None:
                self.proc.kill()
            else:
                self.popen.kill()
        self.wait(None)


# The child's side.

#: what a fresh interpreter runs: ``entry(*args)`` from its command line, having asked to die with its parent
#: before anything slow is imported (this module imports torch)
_FRESH_CHILD = ("import sys; from bench.core.processes import die_with_parent; die_with_parent(); "
                "from bench.runner.isolation import call_entry; call_entry(sys.argv[1], sys.argv[2:])")


def call_entry(entry: str, args: Sequence[str]) -> None:
    """``entry(*args)``, ``entry`` imported by its name, ``"module:function"``."""
    module, _, name = entry.partition(":")
    getattr(importlib.import_module(module), name)(*args)


def forked_main(entry: str, args: Sequence[str], log_file: str, cwd: str) -> None:
    """The target of a process forked from the fork server: its own session
    (so the parent can kill its whole process group), the parent's working
    directory (the server keeps the one it started in), output to ``log_file``;
    then ``entry(*args)``.

    multiprocessing hands each forked process a copy of the pipe that keeps
    the fork server alive, so that the server outlives the process that
    started it while any forked process runs. Closed here: the server then
    ends with the process that started it, and this process with the server
    (:func:`bench.core.processes.die_with_parent`), even after ``kill -9``.
    """
    _release_fork_server()
    os.setsid()
    os.chdir(cwd)
    fd = os.open(log_file, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    die_with_parent()
    call_entry(entry, args)


def _release_fork_server() -> None:
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    fd = getattr(server, "_forkserver_alive_fd", None)
    if fd is not None:
        try:
            os.close(fd)
        except OSError:
            pass
        server._forkserver_alive_fd = None
