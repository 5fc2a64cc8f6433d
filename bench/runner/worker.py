"""The child side of an isolated call (:mod:`bench.runner.isolation`).

A call is a JSON file ``{"target": "module:function", "payload": {...},
"threads": n}``. The child first asks to be killed when its parent ends
(:func:`bench.core.processes.die_with_parent`), then pins its threads before numpy or torch is
imported (in the fork server, before the server imports them), imports the
target by name, calls ``target(payload, on_phase)``, and writes the JSON it
returns to the result file, atomically. ``on_phase(name)`` appends the
phase's name to the phase file, from which the parent times its limits.

* ``python -m bench.runner.worker CALL RESULT PHASE`` runs a call in a fresh
  interpreter (:func:`main`);
* :func:`forked_main` runs it in a process forked from the fork server,
  which has imported torch, the suite and both registries once, so a call
  does not pay for those imports (about 4 s on a laptop core).
"""

from __future__ import annotations

import importlib
import json
import os
import sys

from bench.core.fileio import write_json
from bench.core.processes import die_with_parent
from bench.runner.threads import pin_threads, pin_torch


def run(call_file: str, result_file: str, phase_file: str) -> None:
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
    run(call_file, result_file, phase_file)


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


def main(argv: list[str]) -> int:
    run(*argv)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
