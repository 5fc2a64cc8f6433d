"""The studies: measurement scripts, each a subcommand of ``python -m bench study``
(an *experiment*, by contrast, is what is learned: :mod:`bench.core.experiment`).
Their index is :data:`bench.cli.study.STUDIES`, from which ``python -m bench
study --help`` lists each with its line of help and the page it writes; this
package also holds the modules some studies share (``acceptance_cases``,
``acceptance_scoring``, ``scaling_systems``, ``device_profile``). The user
commands ``select`` and ``robot-log`` have their engines in :mod:`bench.tools`.

Each study gives ``add_arguments(parser)`` and ``main(args)``, and is imported
only when its command is parsed; what it measures is also callable from Python.
"""
