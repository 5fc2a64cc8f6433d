"""How a fitted model is judged: its scores on the data (:mod:`~bench.evaluation.scores`),
whether its equation is exactly the truth (:mod:`~bench.evaluation.recovery`),
and how its motion compares with the true system's (:mod:`~bench.evaluation.rollout`)."""
