"""Imported once by the harness's fork server (:func:`bench.harness.fork_server`):
torch with one thread, the suite, both registries, and torch's lazy one-time
work, so that every run forked from the server starts with them done.

Runs forked from the server run the code as it was when the server started;
so the modules a run imports lazily are imported here too, and the
checkout's commit is frozen for the runs' provenance."""

from bench.worker import pin_threads

pin_threads(1)

import torch  # noqa: E402

torch.set_num_threads(1)
torch.set_num_interop_threads(1)

import methods  # noqa: E402,F401
import systems  # noqa: E402,F401
from bench import data, dynamics, harness, records, recovery, regression, rollout, timeouts  # noqa: E402,F401

records.git_state()  # cached: the forked runs' provenance
harness.warm_up_torch()
