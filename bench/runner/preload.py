"""Imported once by the fork server (:func:`bench.runner.isolation.fork_server`):
torch with one thread, the suite's run path (both registries, the core, the
evaluation), torch's lazy one-time work and the imports of the suite's files
(what a run's code identity is computed from), so that every run forked from
the server starts with them done.

Runs forked from the server run the code as it was when the server started,
and the checkout's commit is read once here, for the runs' provenance. The
server ends when the process that started it ends (its pipe from that
process closes), and each run forked from it ends with it
(:func:`bench.core.processes.die_with_parent`)."""

from bench.runner.threads import pin_threads, pin_torch

pin_threads(1)
pin_torch(1)

from bench.runner import provenance, run, sources  # noqa: E402
import sklearn.model_selection  # noqa: E402,F401  (imported where folds or a search need it: once here, for every run)

provenance.git_state()  # cached: the forked runs' provenance
provenance.package_versions()
run.warm_up_torch()
sources.read_all_imports()
