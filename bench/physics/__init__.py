"""The physics of the suite, on :mod:`bench.core` and below ``methods/`` and ``systems/``.

* :mod:`~bench.physics.dynamics`: the one Euler–Lagrange transform;
* :mod:`~bench.physics.terms`: the one term-library type;
* :mod:`~bench.physics.regression`: least squares over terms;
* :mod:`~bench.physics.effects`: the joint effects a rigid-body model lacks;
* :mod:`~bench.physics.laws`: the one registry of laws (:data:`~bench.physics.laws.LAWS`):
  the arm's laws on one joint, made of those effects, and the laws between the
  arm's torque and the measured one (:mod:`~bench.physics.sensor_laws`), each
  one class that serves the data generator and the residual loop;
* :mod:`~bench.physics.undeclared`: what the data generator adds;
* :mod:`~bench.physics.feasible`: physically feasible identification;
* :mod:`~bench.physics.models`: the one fitted-model interface and the
  expression-backed and parametric models;
* :mod:`~bench.physics.linear`: the models linear in their coefficients (a
  linear form at its base parameters, terms at their coefficients);
* :mod:`~bench.physics.system`: what a physical system is, and the system
  registry (below ``methods/``, because a method reads a system's declared
  form and coordinate kinds).

Importing the package registers the sensor's and the drive's laws beside the
arm's, so that :data:`~bench.physics.laws.LAWS` is whole wherever any of it is used.
"""

from bench.physics import sensor_laws  # noqa: F401  (registers the sensor's and the drive's laws in LAWS)
