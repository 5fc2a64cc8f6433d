"""Several seeds' SyReNets fits trained as one (:mod:`methods.stacking`):
each seed's loop is its own generator of steps
(:meth:`~methods.syrenets.method.SyReNets.steps`: its selection, replay,
schedule and multi-start turns), and each step of all of them is one
vectorised pass.

The pass: the networks in place (one a seed; in a multi-start fit, the one
whose turn it is) stacked (:class:`~methods.stacking.Stack`, built again when
a turn hands a seed another network), their selections on the seeds'
batches by one ``vmap`` of :meth:`~methods.syrenets.network.SyReNet.select`,
the torques of the fixed functions they select by the one Euler–Lagrange
transform on :class:`StackedFixed`, and one backward pass of the sum of the
seeds' losses. The contractive penalty's random vectors are drawn for each
seed from its own generators, as its pass draws them alone.

Each seed's loss, gradients and frozen weights are its own fit's up to the
order of floating-point reductions (``tests/methods/test_stacking.py``
states the tolerance it checks).
"""

from __future__ import annotations

import torch

from bench.core.experiment import Experiment
from bench.physics.dynamics import euler_lagrange
from methods.stacking import SHARED_BUDGET, Stack
from methods.syrenets.training import Fixed, inputs_of


class StackedFixed:
    """The fixed functions of S seeds' selected ``weights`` (each ``(S, heads, C)``)
    as one Lagrangian of ``(q, qd)`` on rows concatenated seed by seed: each
    seed's :class:`~methods.syrenets.training.Fixed`, mapped over the seeds."""

    def __init__(self, stack: Stack, model, inputs: str, weights: list[torch.Tensor], qdd: torch.Tensor):
        self.stack, self.weights, self.qdd = stack, weights, qdd
        self._value = torch.vmap(lambda ws, qdd, q, qd: Fixed(model, inputs, ws, qdd)(q, qd))
        self._tangent = torch.vmap(lambda ws, qdd, *rows: Fixed(model, inputs, ws, qdd).tangent(*rows))

    def __call__(self, q, qd):
        return self._value(self.weights, *self.stack.split(self.qdd, q, qd)).reshape(-1)

    def tangent(self, q, qd, dq, dqd):
        out = self._tangent(self.weights, *self.stack.split(self.qdd, q, qd, dq, dqd))
        return tuple(x.reshape(-1, *x.shape[2:]) for x in out)


def stacked_pass(stack: Stack, batches: list[dict], experiment: str, inputs: str, probes: torch.Tensor | None):
    """Each seed's (loss, squared errors, frozen weights) of its batch, as
    :func:`~methods.syrenets.training.training_pass` gives them for one network."""
    q, qd, qdd = (torch.cat([b[k] for b in batches]) for k in ("q", "qd", "qdd"))
    experiment = Experiment.of(experiment)
    target = torch.cat([b[experiment.target] for b in batches])
    x = stack.split(inputs_of(q, qd, qdd, inputs))[0]
    if probes is None:
        out, weights, aux = stack.vmapped("select", (0, None))(x, None)
    else:
        out, weights, aux = stack.vmapped("select")(x, probes)
    if not experiment.learns_torque:
        err = (out.reshape(-1) - target) ** 2
    else:
        tau = euler_lagrange(StackedFixed(stack, stack.networks[0], inputs, weights, qdd), q, qd, qdd, create_graph=True)
        err = ((tau - target) ** 2).mean(dim=1)
    err = err.reshape(stack.size, -1)
    losses = err.mean(dim=1) + aux
    detached = [w.detach() for w in weights]
    return losses, err.detach(), [[w[s] for w in detached] for s in range(stack.size)]


def train_syrenets(methods: list, starts: list, datasets: list, experiment: str, slots: list) -> None:
    """The steps of the seeds' loops, all at once (see the module docstring)."""
    loops = []
    for method, data, start, slot in zip(methods, datasets, starts, slots):
        with slot:
            loops.append(method.steps(data, experiment, start.progress))
    sent: list = [None] * len(methods)
    stack, cfg = None, methods[0].config
    while True:
        batches, ended = [], False
        for loop, slot, err in zip(loops, slots, sent):
            with slot:
                batches.append(_advance(loop, err))
            ended = ended or batches[-1] is None
        if ended:  # one seed's loop ended (a wall-clock budget): the others end with it
            for loop, start, slot, batch in zip(loops, starts, slots, batches):
                if batch is not None:
                    start.progress.stop(SHARED_BUDGET)
                    with slot:
                        _finish(loop)
            return
        models = [m.net.model for m in methods]
        if stack is None or any(a is not b for a, b in zip(stack.networks, models)):
            stack = Stack(models)  # a multi-start turn handed a seed another network
        probes = None
        if cfg.lambda_contractive and cfg.contractive_probes:
            draws = []
            for model, slot in zip(models, slots):
                with slot:
                    draws.append(model.probe_vectors(cfg.layers, cfg.contractive_probes))
            probes = torch.stack(draws)
        losses, errs, weights = stacked_pass(stack, batches, experiment, cfg.inputs, probes)
        for method in methods:
            method.net.optimizer.zero_grad(set_to_none=True)
        stack.zero_grad()
        losses.sum().backward()
        stack.share_grads()
        sent = list(errs)
        for method, err, w in zip(methods, sent, weights):
            method.finish_step(err, w)


def _advance(loop, err):
    """The loop's next batch after sending it ``err``; ``None`` once it has ended."""
    try:
        return loop.send(err)
    except StopIteration:
        return None


def _finish(loop) -> None:
    """Tell a loop that its step was not done, until it ends."""
    while _advance(loop, None) is not None:
        pass
