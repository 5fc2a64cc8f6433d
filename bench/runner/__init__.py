"""How runs are run: their specification and the code that defines them
(:mod:`~bench.runner.spec`), one run in this process and in its own
(:mod:`~bench.runner.run`), its typed record (:mod:`~bench.runner.records`)
and provenance (:mod:`~bench.runner.provenance`), thread pinning
(:mod:`~bench.runner.threads`), the one kind of job run in its own process
and the limits jobs share (:mod:`~bench.runner.job`), the one scheduler of
jobs (:mod:`~bench.runner.schedule`), process isolation and the fork server
(:mod:`~bench.runner.isolation`, :mod:`~bench.runner.preload`), and the
matrix, locally or on Dask (:mod:`~bench.runner.matrix`,
:mod:`~bench.runner.cluster`, :mod:`~bench.runner.progress`).

The package itself imports nothing, so that a child process can pin its
threads before numpy or torch is imported.
"""
