"""The foundation every other part of the suite stands on.

Nothing here imports from the rest of the suite; ``methods/`` and
``systems/`` import from ``bench`` only what is here.

* :mod:`~bench.core.errors`: errors caused by the user's input;
* :mod:`~bench.core.fileio`: atomic writes;
* :mod:`~bench.core.registry`: named registries with tags;
* :mod:`~bench.core.data`: the one data format, :class:`~bench.core.data.Dataset`;
* :mod:`~bench.core.dynamics`: the one Euler–Lagrange transform;
* :mod:`~bench.core.symbolic`: the coordinate symbols and sympy compilation;
* :mod:`~bench.core.terms`: the one term-library type;
* :mod:`~bench.core.regression`: least squares over terms;
* :mod:`~bench.core.effects`: the joint effects a rigid-body model lacks;
* :mod:`~bench.core.models`: the one fitted-model interface and the
  expression-backed and parametric models;
* :mod:`~bench.core.system`: what a physical system is, and the system
  registry (here, below ``methods/``, because a method reads a system's
  declared form and coordinate kinds);
* :mod:`~bench.core.timeouts`: a hard time limit for pure-Python work.
"""
