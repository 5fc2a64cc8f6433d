"""The studies: measurement scripts, each a subcommand of ``python -m bench study``
(an *experiment*, by contrast, is what is learned: :mod:`bench.core.experiment`):

* :mod:`~bench.studies.adaptation`: adapting to a change in the system;
* :mod:`~bench.studies.residual_acceptance`: the residual loop on known undeclared effects;
* :mod:`~bench.studies.overhead`: the harness's own overhead and speed-up;
* :mod:`~bench.studies.dfki_filter`: the DFKI pre-processing filter's cut-off;
* :mod:`~bench.studies.selection_benchmark`: how well each validation protocol and rule chooses a model.

Each module gives ``add_arguments(parser)`` and ``main(args)``; what it
measures is also callable from Python.
"""
