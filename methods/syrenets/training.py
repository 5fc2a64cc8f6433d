"""One SyReNets network's training: its state between steps
(:class:`Network`), the driver of a fit's steps (:func:`run_steps`), the training pass
(:func:`training_pass`, compiled by :func:`compiled_pass`), the frozen
function a batch selects (:class:`Fixed`) and the cosine schedule
(:class:`Cosine`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import torch

from bench.core.compiled import compiled_once
from bench.physics.dynamics import euler_lagrange
from methods.syrenets.network import SyReNet


@dataclass
class Network:
    """One network of a fit and everything it carries from one step to the
    next: its weights, optimiser and schedule, the frozen weights of its
    latest batch, the loss its schedule watches (smoothed with
    ``lr_smoothing``), the plateau schedule's cuts ``[step, seconds into the
    fit, new rate]``, and the worst-fitted samples it replays next."""

    model: SyReNet
    optimizer: torch.optim.Optimizer
    scheduler: Any
    frozen: list[torch.Tensor]
    watched: float | None = None
    lr_drops: list = field(default_factory=list)
    replay: torch.Tensor = field(default_factory=lambda: torch.empty(0, dtype=torch.long))


def run_steps(steps, step) -> None:
    """Drive a fit's generator of steps (:meth:`~methods.syrenets.method.SyReNets.steps`)
    to its end: each batch it yields goes to ``step``, whose squared errors go back."""
    err = None
    try:
        while True:
            err = step(steps.send(err))
    except StopIteration:
        pass


def inputs_of(q, qd, qdd, inputs: str) -> torch.Tensor:
    return torch.cat([q, qd] if inputs == "q_qd" else [q, qd, qdd], dim=1)


def training_pass(model: SyReNet, q, qd, qdd, target, torque: bool, inputs: str, tangent: bool):
    """(loss, each sample's squared error, frozen weights) of one batch, the
    last two detached; ``torque``: the targets are torques
    (:attr:`bench.core.experiment.Experiment.learns_torque`), which with
    ``tangent`` come from derivatives propagated forward."""
    out, weights, aux = model.select(inputs_of(q, qd, qdd, inputs))
    if not torque:
        err = (out - target) ** 2
    else:
        # the torques of the fixed function the batch selected: gradients flow
        # into the selection, not through the batch statistics
        fixed = Fixed(model, inputs, weights, qdd)
        tau = euler_lagrange(fixed if tangent else fixed.__call__, q, qd, qdd, create_graph=True)
        err = ((tau - target) ** 2).mean(dim=1)
    return err.mean() + aux, err.detach(), [w.detach() for w in weights]


def compiled_pass():
    """:func:`training_pass` compiled, one for the process: the model is an
    argument, so each new network reuses the compiled graphs."""
    return compiled_once(training_pass)


class Fixed:
    """The fixed function of ``weights`` as a Lagrangian of ``(q, qd)``, with
    its derivatives propagated forward (``qdd``, where it is an input, is held
    constant, as the transform's reverse passes would hold it)."""

    def __init__(self, model: SyReNet, inputs: str, weights: list[torch.Tensor], qdd: torch.Tensor):
        self.model, self.inputs, self.weights, self.qdd = model, inputs, weights, qdd

    def __call__(self, q, qd):
        return self.model.evaluate(inputs_of(q, qd, self.qdd, self.inputs), self.weights)

    def tangent(self, q, qd, dq, dqd):
        dof = q.shape[1]
        out = self.model.evaluate_tangent(inputs_of(q, qd, self.qdd, self.inputs), self.weights, torch.cat([dq, dqd], dim=1), dof)
        return out[:, 0], out[:, 1:1 + dof], out[:, 1 + dof:1 + 2 * dof], out[:, 1 + 2 * dof:]


class Cosine:
    """Half a cosine from each group's learning rate to its minimum over the
    share of the budget that is left when :meth:`start` is called
    (:meth:`methods.progress.Progress.fraction`: of the steps when the run has a
    step limit, else of the time, as read at the fit's evaluations). :meth:`step` sets the rate of the
    next step, like the plateau schedule's. A warm start calls :meth:`start`
    again, and the rate anneals anew from its highest value."""

    def __init__(self, optimizer: torch.optim.Optimizer, min_lrs: list[float]):
        self.optimizer, self.min_lrs = optimizer, min_lrs
        self.max_lrs = [g["lr"] for g in optimizer.param_groups]
        self.fraction = lambda: 0.0

    def start(self, progress) -> None:
        if progress.max_steps is not None:
            # called after a step's update: the fraction for the next step, so
            # that the first step takes the highest rate and the last the lowest
            first, total = progress.steps, max(progress.max_steps - progress.steps - 1, 1)
            self.fraction = lambda: (progress.steps + 1 - first) / total
        else:  # the share of the budget spent since, as the fit's progress reads it (so a replay repeats it)
            begin = progress.fraction()
            self.fraction = lambda: (progress.fraction() - begin) / max(1.0 - begin, 1e-9)

    def step(self, loss: float) -> None:
        f = min(max(self.fraction(), 0.0), 1.0)
        for group, high, low in zip(self.optimizer.param_groups, self.max_lrs, self.min_lrs):
            group["lr"] = low + (high - low) * 0.5 * (1 + math.cos(math.pi * f))
