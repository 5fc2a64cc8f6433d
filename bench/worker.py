"""Entry points of one isolated run.

* ``python -m bench.worker SPEC RECORD PHASE`` runs it in a fresh
  interpreter (:func:`main`);
* :func:`forked_main` runs it in a process forked from the harness's fork
  server, which has imported torch, the suite and both registries once, so a
  run does not pay for those imports (about 4 s on a laptop core).

Thread counts are pinned before numpy or torch is imported (in the fork
server, before it imports them), so that parallel runs do not oversubscribe
the cores. The worker appends its phase (``fit``, then ``evaluate``) to the
``PHASE`` file, from which the harness times the budget, and writes the
record atomically to ``RECORD``.
"""

from __future__ import annotations

import json
import os
import sys

THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def pin_threads(threads: int) -> None:
    """Set the thread variables; call before numpy or torch is imported."""
    for var in THREAD_VARS:
        os.environ[var] = str(threads)


def run(spec_file: str, record_file: str, phase_file: str) -> None:
    with open(spec_file) as f:
        spec_dict = json.load(f)
    threads = int(spec_dict.get("threads", 1))
    pin_threads(threads)

    import torch

    torch.set_num_threads(threads)
    if torch.get_num_interop_threads() != 1:
        try:
            torch.set_num_interop_threads(1)
        except RuntimeError:  # already fixed in this process (a forked one)
            pass

    from bench.harness import RunSpec, execute
    from bench.records import write_record

    spec = RunSpec.from_dict(spec_dict)

    def on_phase(phase: str) -> None:
        with open(phase_file, "a") as f:
            f.write(phase + "\n")

    record = execute(spec, on_phase=on_phase)
    write_record(record_file, record)


def forked_main(spec_file: str, record_file: str, phase_file: str, log_file: str, cwd: str) -> None:
    """The target of a process forked from the fork server: its own session
    (so the harness can kill its whole process group), the harness's working
    directory (the server keeps the one it started in), output to ``log_file``."""
    os.setsid()
    os.chdir(cwd)
    fd = os.open(log_file, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    run(spec_file, record_file, phase_file)


def main(argv: list[str]) -> int:
    run(*argv)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
