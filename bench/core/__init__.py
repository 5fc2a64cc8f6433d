"""The foundation every other part of the suite stands on: its infrastructure.

Nothing here imports from the rest of the suite.

* :mod:`~bench.core.errors`: errors caused by the user's input;
* :mod:`~bench.core.fileio`: atomic writes;
* :mod:`~bench.core.registry`: named registries with tags;
* :mod:`~bench.core.processes`, :mod:`~bench.core.timeouts`: child processes and
  a hard time limit for pure-Python work;
* :mod:`~bench.core.budget`: budgets of time or work, and the one clock they read;
* :mod:`~bench.core.names`: a method's name, parsed once;
* :mod:`~bench.core.data`: the one data format, :class:`~bench.core.data.Dataset`,
  its CSV form (:mod:`~bench.core.csv_format`) and measured recordings
  (:mod:`~bench.core.recordings`);
* :mod:`~bench.core.folds`: the one validation protocol;
* :mod:`~bench.core.symbolic`: the coordinate symbols and sympy compilation;
* :mod:`~bench.core.modelfile`: the model file.

The physics built on it is :mod:`bench.physics`.
"""
