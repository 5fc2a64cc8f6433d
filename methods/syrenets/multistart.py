"""Several SyReNets networks in one fit, one kept by successive halving
(Jamieson & Talwalkar, 2016): what the paper's "Best" row does across seeds,
inside one run's budget.

Each network is a :class:`~methods.syrenets.training.Network`, its own
weights, optimiser, schedule and replayed samples; the method trains the one
it holds (``method.net``), and :func:`halve` hands it each network in turn.
"""

from __future__ import annotations

import math

from methods.syrenets.training import Network
from methods.torch_method import Feed


def halve(method, networks: list[Network], t, experiment: str, progress, feed: Feed) -> dict:
    """Successive halving over ``networks`` (a generator of the fit's steps,
    :meth:`~methods.syrenets.method.SyReNets.steps`); leaves the survivor in
    ``method.net`` and returns the record's entry: the networks, each round's
    ``[network, score]`` (``None`` for a score that is not finite) and the
    network kept.

    ``start_share`` of the loop is split into ceil(log2 k) rounds of equal
    length; in each, the networks still in train in turns for equal shares
    of the round, then the half with the higher score is dropped. A
    network's score is the lowest training MSE (on the evaluation subset, as
    the best-state tracking measures it) of all its evaluations so far, the
    scheduled ones during its turns and one at the end of each turn: at the
    high learning rates of the selection, the MSE of a network's current
    state swings by an order of magnitude from one evaluation to the next,
    and ranking by the current state drops networks that have found the
    structure.
    """
    alive, rounds = list(range(len(networks))), math.ceil(math.log2(len(networks)))
    begin = progress.fraction()
    length = method.config.start_share * (1 - begin) / rounds
    entry = {"networks": len(networks), "rounds": []}
    best = {k: math.inf for k in alive}
    for r in range(rounds):
        scores, turn = {}, length / len(alive)
        for i, k in enumerate(alive):
            method.net = networks[k]
            seen = len(progress.measured)
            more = yield from method._train(t, experiment, progress, feed, until=begin + r * length + (i + 1) * turn)
            if math.isfinite(progress.measure()):
                best[k] = scores[k] = min(v for v in [best[k], *progress.measured[seen:]] if not math.isnan(v))
            else:  # a network whose state is no longer finite is dropped first
                best[k] = scores[k] = math.inf
            if not more:
                break
        ranked = sorted(scores, key=lambda k: scores[k] if math.isfinite(scores[k]) else math.inf)
        entry["rounds"].append([[k, scores[k] if math.isfinite(scores[k]) else None] for k in sorted(scores)])
        alive = ranked[: max(1, math.ceil(len(alive) / 2))] if more else ranked[:1]
        if len(alive) == 1:
            break
    entry["kept"] = alive[0]
    method.net = networks[alive[0]]
    return entry
