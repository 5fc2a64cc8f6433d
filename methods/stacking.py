"""Several seeds of one torch method trained as one model: the S networks'
parameters stacked along a first axis, each step's batches of the S seeds
evaluated by one vectorised call (``torch.func.vmap`` of ``functional_call``
over the stacked parameters), the one Euler–Lagrange transform and one
backward pass on the concatenated batch.

Each seed's fit is the one it makes alone (:meth:`Method.fit`), as
:func:`fit_stacked` arranges it:

* its own method object, data, generators (seeded as its fit seeds them,
  :meth:`~methods.base.Method.begin_fit`, before its network is built),
  evaluation subset, :class:`~methods.progress.Progress` (schedule of
  evaluations, best state, curve) and feed of batches;
* its network's parameters are views of its slice of the stack, so its
  evaluations and its best state read the stack as it stands;
* its own optimiser and schedule (torch's Adam and the method's
  :meth:`make_scheduler`) step its slice, on the slice of the stack's
  gradient: the gradient of the sum of the seeds' losses is each seed's
  own, since no seed's loss depends on another's parameters.

The torques of a seed's samples come from its own network only, so the
transform's derivatives of the batch sum are each sample's; on a CPU the
stacked torques and gradients equal the seeds' own to the last bit for the
MLP (``tests/methods/test_stacking.py`` states the tolerance it checks).

A CPU gains nothing from this: one step of S seeds costs S steps' work. A
GPU runs S small networks' steps in about the time of one, where a single
small network leaves it idle between kernel launches.

Under a work budget (``steps``) every seed does its steps. Under a wall-clock
budget the seeds share it: the stack stops when the first seed's progress
says so, and each fit's ``fit_info["stacked"]`` says how many seeds shared
its clock.
"""

from __future__ import annotations

import copy

import torch
from torch.func import functional_call, stack_module_state, vmap

from bench.core.data import Dataset
from bench.core.dynamics import euler_lagrange
from bench.core.errors import ConfigError
from methods.base import gc_frozen


class _Tangent(torch.nn.Module):
    """``base.tangent`` as a module's forward, so that ``functional_call`` can call it."""

    def __init__(self, base: torch.nn.Module):
        super().__init__()
        self.base = base

    def forward(self, q, qd, dq, dqd):
        return self.base.tangent(q, qd, dq, dqd)


class StackedLagrangian:
    """``(q, qd) -> L`` of S networks of one shape on S seeds' samples,
    concatenated seed by seed (each seed ``rows`` samples); with a
    ``tangent`` where the networks give their own derivatives
    (:class:`~bench.core.dynamics.TangentLagrangian`).

    The stack's parameters are leaves of their own; each network's parameters
    become views of its slice (:meth:`__init__`), and :meth:`share_grads`
    gives each network the slice of the stack's gradient."""

    def __init__(self, networks: list[torch.nn.Module]):
        self.networks, self.size = networks, len(networks)
        self.params, self.buffers = stack_module_state(networks)
        for s, net in enumerate(networks):  # each network reads (and its optimiser steps) its slice of the stack
            for name, p in net.named_parameters():
                p.data = self.params[name].data[s]
            for name, b in net.named_buffers():
                b.data = self.buffers[name].data[s]
        self.base = copy.deepcopy(networks[0]).to("meta")
        self._forward = vmap(lambda p, b, q, qd: functional_call(self.base, (p, b), (q, qd)))
        if hasattr(self.base, "tangent"):
            tangent = _Tangent(self.base)

            def one(p, b, q, qd, dq, dqd):
                return functional_call(tangent, ({"base." + k: v for k, v in p.items()},
                                                 {"base." + k: v for k, v in b.items()}), (q, qd, dq, dqd))

            self._tangent = vmap(one)
            self.tangent = self._tangent_of_rows

    def _split(self, *xs: torch.Tensor):
        return tuple(x.reshape(self.size, -1, *x.shape[1:]) for x in xs)

    def __call__(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self._forward(self.params, self.buffers, *self._split(q, qd)).reshape(-1)

    def _tangent_of_rows(self, q, qd, dq, dqd):
        out = self._tangent(self.params, self.buffers, *self._split(q, qd, dq, dqd))
        return tuple(x.reshape(-1, *x.shape[2:]) for x in out)

    def zero_grad(self) -> None:
        for p in self.params.values():
            p.grad = None

    def share_grads(self) -> None:
        """Each network's parameters' gradients: views of its slice of the stack's (zero where none flowed)."""
        for s, net in enumerate(self.networks):
            for name, p in net.named_parameters():
                g = self.params[name].grad
                p.grad = torch.zeros_like(p) if g is None else g[s]


def fit_stacked(methods: list, datasets: list[Dataset], experiment: str, seeds: list[int], budget_s=None, *,
                steps: int | None = None, system=None) -> list:
    """Fit ``methods`` (instances of one stackable torch method, one configuration)
    on ``datasets`` with ``seeds``, one each, as one stacked model (see the module
    docstring); returns them fitted, each as :meth:`~methods.base.Method.fit`
    leaves it."""
    if not methods or not (len(methods) == len(datasets) == len(seeds)):
        raise ConfigError("fit_stacked needs one dataset and one seed per method")
    kind = type(methods[0])
    if not kind.stackable or any(type(m) is not kind or m.config != methods[0].config for m in methods):
        raise ConfigError(f"only fits of one stackable method in one configuration stack; got "
                          f"{sorted({type(m).name for m in methods})}")
    starts, loops = [], []
    for method, data, seed in zip(methods, datasets, seeds):
        # no one-time work: what a method prepares (DeLaN's compiled loss) is for its own step, not the stack's
        starts.append(method.begin_fit(data, experiment, seed, budget_s, steps=steps, system=system, prepare=False))
        loops.append(method.start_loop(data))  # its network from its own seeded generators, as alone
    stack = StackedLagrangian([m.model for m in methods])
    direct = experiment == "direct"
    with gc_frozen():
        while True:
            going = [s.progress.step() for s in starts]
            if not all(going):
                for s, g in zip(starts, going):
                    if g:
                        s.progress.stop("another seed of the stack used up the shared budget")
                break
            batches = []
            for tensors, feed in loops:
                idx = feed.next()
                batches.append({k: v[idx] for k, v in tensors.items()})
            q, qd, qdd = (torch.cat([b[k] for b in batches]) for k in ("q", "qd", "qdd"))
            pred = stack(q, qd) if direct else euler_lagrange(stack, q, qd, qdd, create_graph=True)
            losses, row = [], 0
            for method, batch in zip(methods, batches):
                target = batch["L" if direct else "tau"]
                losses.append(method.loss(pred[row:row + len(target)], target, experiment))
                row += len(target)
            stack.zero_grad()
            torch.stack(losses).sum().backward()
            stack.share_grads()
            for method, loss in zip(methods, losses):
                method.apply_step(loss)
    out = []
    for method, start, data in zip(methods, starts, datasets):
        out.append(method.end_fit(start, data))
        method.fit_info["stacked"] = len(methods)
    return out
