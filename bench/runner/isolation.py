"""Process isolation: a call runs in its own process, under time limits per phase.

Every job of the suite (:mod:`bench.runner.job`) runs through :func:`run_call`.
A :class:`Call` names a function by its import path and
gives it a JSON payload; the child reports the phases it enters, and the
parent kills its whole process group when it stays in a phase longer than
that phase's limit.

The child is forked from a fork server (:func:`fork_server`) that has
imported torch, the suite and both registries once (:mod:`bench.runner.preload`),
so a run does not pay for those imports; where the server cannot be used (no
``fork`` on the platform, inside a daemonic process such as a Dask worker
started as Dask starts them by default, a call with more than one thread, or
``fresh=True``) the child is a fresh
interpreter started with the thread variables set (:data:`_FRESH_CHILD`).

The child's side (:func:`run_target`): a call is a JSON file ``{"target":
"module:function", "payload": {...}, "threads": n}``. The child first asks
to be killed when its parent ends (:func:`bench.core.processes.die_with_parent`),
pins its threads, imports the target by name, calls ``target(payload,
on_phase)``, and writes the JSON it returns to the result file, atomically.
``on_phase(name)`` appends the phase's name to the phase file, from which the
parent times its limits.
"""

from __future__ import annotations

import atexit
import importlib
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Mapping

from bench.core.fileio import write_json
from bench.core.processes import die_with_parent
from bench.runner.provenance import PROJECT_ROOT
from bench.runner.threads import THREAD_VARS, pin_threads, pin_torch, thread_env

#: the phase a child is in until it reports another
STARTUP = "startup"
#: seconds a child may take to import and load its data before its first phase
STARTUP_TIMEOUT_S = 300.0


@dataclass(frozen=True)
class Call:
    """``target(payload, on_phase) -> JSON``, run in a child process.

    ``target`` is ``"module:function"``; ``payload`` must be JSON; the
    child pins ``threads`` torch and BLAS threads.
    """

    target: str
    payload: dict
    threads: int = 1

    def to_json(self) -> dict:
        return {"target": self.target, "payload": self.payload, "threads": self.threads}


class CallFailed(RuntimeError):
    """A call that did not return: killed at its limit, or its process died."""


@dataclass(frozen=True)
class Outcome:
    """How a call ended.

    Attributes
    ----------
    result
        The JSON the target returned; ``None`` when it did not return.
    phase
        The last phase the child reported (``"startup"`` if none).
    killed
        The child stayed in ``phase`` past its limit and was killed.
    exit_code
        The child's exit code (``None`` when killed).
    log_tail
        The last lines of the child's output, for a child that died.
    interrupted
        The caller was interrupted and killed the child (:func:`kill_children`):
        the call neither finished nor failed.
    """

    result: dict | None
    phase: str
    killed: bool = False
    exit_code: int | None = None
    log_tail: str = ""
    interrupted: bool = False


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
_RUNNING: set["_Child"] = set()
_RUNNING_LOCK = threading.Lock()


def kill_children() -> int:
    """Kill every child still running (for an interrupted caller); returns how many."""
    with _RUNNING_LOCK:
        children = list(_RUNNING)
    for child in children:
        child.interrupted = True
        child.kill()
    return len(children)


class _Child:
    """A running child: a process forked from the fork server, or a fresh interpreter."""

    def __init__(self, threads: int, files: tuple[Path, Path, Path], log_file: Path, fresh: bool):
        ctx = None if fresh or threads != 1 else fork_server()
        self.proc = self.popen = None
        self.interrupted = False
        if ctx is not None:
            self.proc = ctx.Process(target=forked_main, args=(*map(str, files), str(log_file), os.getcwd()))
            self.proc.start()
            self._register()
            return
        env = thread_env(threads)
        root = str(PROJECT_ROOT)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        with open(log_file, "wb") as log:
            self.popen = subprocess.Popen(
                [sys.executable, "-c", _FRESH_CHILD, *map(str, files)],
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


def run_call(call: Call, result_file: str | os.PathLike, log_dir: str | os.PathLike, name: str,
             limits: Mapping[str, float], *, fresh: bool = False, poll_s: float = 0.05,
             echo: Callable[[str], None] | None = None) -> Outcome:
    """Run ``call`` in its own process and wait for it.

    The child writes what the target returns to ``result_file``; its call,
    phases and output go to ``log_dir/<name>.*``. ``limits`` gives the
    seconds allowed in each phase, counted from the phase's start; the
    start-up phase has :data:`STARTUP_TIMEOUT_S` unless ``limits`` says
    otherwise, and a phase without a limit has none. ``echo``, if given,
    receives each line the child prints, as it prints it.
    """
    result_file, log_dir = Path(result_file), Path(log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    call_file, phase_file, log_file = (log_dir / f"{name}{s}" for s in (".call.json", ".phase", ".log"))
    for f in (phase_file, result_file, log_file):
        f.unlink(missing_ok=True)
    write_json(call_file, call.to_json())
    limits = {STARTUP: STARTUP_TIMEOUT_S, **limits}
    child = _Child(call.threads, (call_file, result_file, phase_file), log_file, fresh)
    phase = STARTUP
    kill_at = time.monotonic() + limits[STARTUP]
    output = _Lines(log_file, echo)
    while not child.wait(poll_s):
        output.read()
        now = time.monotonic()
        new_phase = _read_phase(phase_file) or phase
        if new_phase != phase:
            phase = new_phase
            kill_at = now + limits.get(phase, float("inf"))
        if now >= kill_at:
            child.kill()
            output.read(final=True)
            return Outcome(None, phase, killed=True)
    output.read(final=True)
    if child.interrupted:
        return Outcome(None, phase, interrupted=True)
    phase = _read_phase(phase_file) or phase
    result = _read_result(result_file)
    if result is None:
        return Outcome(None, phase, exit_code=child.returncode, log_tail=_tail(log_file))
    return Outcome(result, phase, exit_code=child.returncode)


def map_interruptibly(fn: Callable, items: list, workers: int) -> Iterator:
    """``fn`` over ``items`` on ``workers`` threads, results in order, like
    ``ThreadPoolExecutor.map``; if the caller is interrupted (Ctrl-C, or any
    error), queued items are dropped and running children killed at once
    instead of being waited for."""
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        yield from pool.map(fn, items)
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        kill_children()
        raise
    finally:
        pool.shutdown(wait=True)


class _Lines:
    """The lines a child has added to its log since the last read, passed to ``echo``."""

    def __init__(self, path: Path, echo: Callable[[str], None] | None):
        self.path, self.echo, self.offset, self.partial = path, echo, 0, b""

    def read(self, final: bool = False) -> None:
        if self.echo is None:
            return
        try:
            with open(self.path, "rb") as f:
                f.seek(self.offset)
                chunk = f.read()
        except OSError:
            return
        self.offset += len(chunk)
        *lines, self.partial = (self.partial + chunk).split(b"\n")
        if final and self.partial:
            lines.append(self.partial)
            self.partial = b""
        for line in lines:
            self.echo(line.decode(errors="replace"))


def _read_result(path: Path) -> dict | None:
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _read_phase(path: Path) -> str | None:
    try:
        lines = path.read_text().split()
    except OSError:
        return None
    return lines[-1] if lines else None


def _tail(path: Path, lines: int = 3) -> str:
    try:
        text = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return "(no log)"
    return " | ".join(text[-lines:]) or "(empty log)"


# The child's side.

#: what a fresh interpreter runs: :func:`run_target` on the three files it is given, having asked to die with its
#: parent before anything slow is imported (this module imports torch)
_FRESH_CHILD = ("import sys; from bench.core.processes import die_with_parent; die_with_parent(); "
                "from bench.runner.isolation import run_target; run_target(*sys.argv[1:])")


def run_target(call_file: str, result_file: str, phase_file: str) -> None:
    """The call in ``call_file``, run in this (child) process; what it returns goes to ``result_file``, the
    phases it enters to ``phase_file``. The thread variables numpy's and torch's BLAS read were set before
    they were imported: in a fresh interpreter's environment by the parent (:func:`thread_env`), in the fork
    server by the server; torch's own thread counts are set here."""
    die_with_parent()
    with open(call_file) as f:
        call = json.load(f)
    threads = int(call.get("threads", 1))
    pin_threads(threads)
    pin_torch(threads)
    module, _, name = call["target"].partition(":")
    target = getattr(importlib.import_module(module), name)

    def on_phase(phase: str) -> None:
        with open(phase_file, "a") as f:
            f.write(phase + "\n")

    write_json(result_file, target(call["payload"], on_phase))


def forked_main(call_file: str, result_file: str, phase_file: str, log_file: str, cwd: str) -> None:
    """The target of a process forked from the fork server: its own session
    (so the parent can kill its whole process group), the parent's working
    directory (the server keeps the one it started in), output to ``log_file``.

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
    run_target(call_file, result_file, phase_file)


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
