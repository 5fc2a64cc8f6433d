"""Measurement scripts, each a subcommand of ``python -m bench``:

* :mod:`~bench.experiments.adaptation`: adapting to a change in the system;
* :mod:`~bench.experiments.residual_acceptance`: the residual loop on known undeclared effects;
* :mod:`~bench.experiments.overhead`: the harness's own overhead and speed-up;
* :mod:`~bench.experiments.dfki_filter`: the DFKI pre-processing filter's cut-off.

Each module gives ``add_arguments(parser)`` and ``main(args)``; what it
measures is also callable from Python.
"""
