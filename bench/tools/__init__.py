"""The engines of the user commands that are neither a run of the matrix nor a
study: ``bench select`` (:mod:`~bench.tools.select`: one model of a measured
arm, chosen by validation on its training data) and ``bench robot-log``
(:mod:`~bench.tools.robot_log`: a simulated robot's logs, as its software
records them). They use the runner, the residual loop and the systems; the
studies (:mod:`bench.studies`) use them."""
