"""Entry point of one isolated run: ``python -m bench.worker SPEC RECORD PHASE``.

Thread counts are pinned from the spec before numpy or torch is imported, so
that parallel runs do not oversubscribe the cores. The worker appends its
phase (``fit``, then ``evaluate``) to the ``PHASE`` file, from which the
harness times the budget, and writes the record atomically to ``RECORD``.
"""

from __future__ import annotations

import json
import os
import sys


def main(argv: list[str]) -> int:
    spec_file, record_file, phase_file = argv
    with open(spec_file) as f:
        spec_dict = json.load(f)
    threads = str(int(spec_dict.get("threads", 1)))
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
        os.environ[var] = threads

    import torch

    torch.set_num_threads(int(threads))
    torch.set_num_interop_threads(1)

    from bench.harness import RunSpec, execute
    from bench.records import write_record

    spec = RunSpec.from_dict(spec_dict)

    def on_phase(phase: str) -> None:
        with open(phase_file, "a") as f:
            f.write(phase + "\n")

    record = execute(spec, on_phase=on_phase)
    write_record(record_file, record)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
