"""The residual loop's bounds: its rounds and the shares of its budget each
phase has (:mod:`bench.residual.loop` spends them; its default seconds are a
run's, :data:`bench.core.budget.DEFAULT_BUDGET_S`). A module of numbers alone,
so that the command line's help states them without importing the loop."""

#: a loop runs at most this many rounds
MAX_ROUNDS = 6
#: the share of the loop's budget its method's fit has
FIT_SHARE = 0.5
#: the polish starts no new start after this share of the loop's budget
POLISH_SHARE = 0.75
#: tracing starts no new step after this share of the loop's budget (the joint
#: refit, pruning and the held-out check follow)
TRACE_SHARE = 0.85
#: the share of the loop's budget each of the two cross-fits of a kept fit has
#: (see :func:`~bench.residual.strategies.cross_fit`)
CROSS_FIT_SHARE = 0.15
