"""The studies: measurement scripts, each a subcommand of ``python -m bench study``
(an *experiment*, by contrast, is what is learned: :mod:`bench.core.experiment`).
Their index is :data:`bench.cli.study.STUDIES`, from which ``python -m bench
study --help`` lists each with its ``HELP`` line and the page it writes; this
package also holds the user commands ``robot-log`` (:mod:`~bench.studies.robot_log`)
and ``select``'s engine (:mod:`~bench.studies.selection`), and the modules
some studies share (``acceptance_cases``, ``acceptance_scoring``,
``scaling_systems``, ``device_profile``).

Each study gives ``add_arguments(parser)``, ``main(args)`` and ``HELP``; what it
measures is also callable from Python.
"""
