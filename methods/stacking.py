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

The loop is the method's (:meth:`~methods.base.Method.train_stacked`):
:func:`train_lagrangians` for a :class:`~methods.torch_method.TorchLagrangianMethod`,
:mod:`methods.syrenets.stacked` for SyReNets. Each seed's random draws come
from its own generators (:class:`RngSlot`). Where a method compiles its own
step (DeLaN's ``compile=True``), the stack's Euler–Lagrange torques are
compiled too (:func:`compiled_stacked_torques`), once, before the budgets
start (:meth:`~methods.base.Method.prepare_stacked`).

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
import dataclasses
import functools
import random
import time
from typing import Callable

import numpy as np
import torch
from torch.func import functional_call, stack_module_state, vmap

from bench.core.budget import Budget
from bench.core.experiment import Experiment
from bench.core.compiled import compiled_once
from bench.core.data import Dataset
from bench.physics.dynamics import euler_lagrange
from bench.core.errors import ConfigError
from methods.base import gc_frozen


class _Call(torch.nn.Module):
    """``base``'s method ``name`` as a module's forward, so that ``functional_call`` can call it."""

    def __init__(self, base: torch.nn.Module, name: str):
        super().__init__()
        self.base, self.name = base, name

    def forward(self, *args):
        return getattr(self.base, self.name)(*args)


def _per_network(base: torch.nn.Module, name: str, keys) -> Callable:
    """``(params, buffers, *args) -> base.name(*args)`` with one network's
    parameters and buffers (named ``keys``) in place of ``base``'s: what
    ``vmap`` maps over a stack."""
    call = _Call(base, name)
    prefixed = {k: "base." + k for k in keys}

    def one(p, b, *args):
        return functional_call(call, ({prefixed[k]: v for k, v in p.items()}, {prefixed[k]: v for k, v in b.items()}), args)

    return one


class Stack:
    """The parameters and buffers of S networks of one shape, stacked along a
    first axis (``torch.func.stack_module_state``), and any of the networks'
    methods over S inputs at once (:meth:`vmapped`).

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
        self._calls: dict = {}

    def vmapped(self, name: str, in_dims=0):
        """The networks' method ``name``, each on its slice of the stacked
        arguments (``in_dims`` as :func:`torch.func.vmap` takes them, for the
        arguments after the parameters)."""
        key = (name, in_dims if not isinstance(in_dims, list) else tuple(in_dims))
        if key not in self._calls:
            dims = (0, 0, *in_dims) if isinstance(in_dims, (tuple, list)) else 0
            self._calls[key] = vmap(_per_network(self.base, name, (*self.params, *self.buffers)), in_dims=dims)
        return functools.partial(self._calls[key], self.params, self.buffers)

    def split(self, *xs: torch.Tensor):
        """Rows concatenated seed by seed, each seed's its own block: ``(S, rows, ...)``."""
        return tuple(x.reshape(self.size, -1, *x.shape[1:]) for x in xs)

    def zero_grad(self) -> None:
        for p in self.params.values():
            p.grad = None

    def share_grads(self) -> None:
        """Each network's parameters' gradients: views of its slice of the stack's (zero where none flowed)."""
        for s, net in enumerate(self.networks):
            for name, p in net.named_parameters():
                g = self.params[name].grad
                p.grad = torch.zeros_like(p) if g is None else g[s]


def _rows_tangent(base: torch.nn.Module, params: dict, buffers: dict, q, qd, dq, dqd) -> tuple:
    """``tangent`` of the stacked networks (``base``'s shape, the stack's
    ``params`` and ``buffers``) on rows concatenated seed by seed."""
    size = next(iter(params.values())).shape[0]
    rows = (x.reshape(size, -1, *x.shape[1:]) for x in (q, qd, dq, dqd))
    out = vmap(_per_network(base, "tangent", (*params, *buffers)))(params, buffers, *rows)
    return tuple(x.reshape(-1, *x.shape[2:]) for x in out)


class _TangentRows:
    """The stacked networks as the Euler–Lagrange transform takes a Lagrangian
    that gives its own derivatives (its ``tangent`` is all the transform calls)."""

    def __init__(self, base: torch.nn.Module, params: dict, buffers: dict):
        self.state = (base, params, buffers)

    def tangent(self, q, qd, dq, dqd):
        return _rows_tangent(*self.state, q, qd, dq, dqd)


def _stacked_torques(base: torch.nn.Module, params: dict, buffers: dict, q, qd, qdd) -> torch.Tensor:
    """The Euler–Lagrange torques of the stacked networks, for networks with
    their own derivatives (``tangent``): no ``autograd.grad``, so the whole of
    it compiles."""
    return euler_lagrange(_TangentRows(base, params, buffers), q, qd, qdd, create_graph=True)


def compiled_stacked_torques():
    """:func:`_stacked_torques` compiled, one for the process: the networks are
    arguments, so every stack of one shape and size reuses the compiled graphs."""
    return compiled_once(_stacked_torques)


class StackedLagrangian(Stack):
    """``(q, qd) -> L`` of S networks of one shape on S seeds' samples,
    concatenated seed by seed (each seed ``rows`` samples); with a
    ``tangent`` where the networks give their own derivatives
    (:class:`~bench.physics.dynamics.TangentLagrangian`)."""

    def __init__(self, networks: list[torch.nn.Module]):
        super().__init__(networks)
        if hasattr(self.base, "tangent"):
            self.tangent = self._tangent_of_rows

    def __call__(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self.vmapped("forward")(*self.split(q, qd)).reshape(-1)

    def _tangent_of_rows(self, q, qd, dq, dqd):
        return _rows_tangent(self.base, self.params, self.buffers, q, qd, dq, dqd)

    def compiled_torques(self, q, qd, qdd) -> torch.Tensor:
        """The transform's torques, for networks with a ``tangent``, by the compiled :func:`_stacked_torques`."""
        return compiled_stacked_torques()(self.base, self.params, self.buffers, q, qd, qdd)


class RngSlot:
    """One seed's generators (Python's, NumPy's and torch's, the CPU's and
    the device's) while several seeds' fits share one process: entering
    puts the seed's states in place, leaving keeps them and puts back what
    was there, so that each fit draws the numbers it draws alone."""

    def __init__(self, device: str = "cpu"):
        self.cuda = torch.device(device).type == "cuda"
        self.mine = self.saved = None

    def _state(self):
        return (random.getstate(), np.random.get_state(), torch.get_rng_state(),
                torch.cuda.get_rng_state() if self.cuda else None)

    @staticmethod
    def _put(state) -> None:
        py, nump, cpu, cuda = state
        random.setstate(py)
        np.random.set_state(nump)
        torch.set_rng_state(cpu)
        if cuda is not None:
            torch.cuda.set_rng_state(cuda)

    def __enter__(self):
        self.saved = self._state()
        if self.mine is not None:
            self._put(self.mine)
        return self

    def __exit__(self, *exc) -> None:
        self.mine = self._state()
        self._put(self.saved)


def prepare_lagrangians(methods: list, datasets: list[Dataset], experiment: str) -> None:
    """Compile the stacked step of ``methods`` (where they ask for it,
    :meth:`~methods.torch_method.TorchLagrangianMethod.compiles_stacked_step`) for
    their number, networks' shapes and batch, on networks of their own that are
    then discarded, before any fit's budget starts."""
    method = methods[0]
    if not method.compiles_stacked_step(experiment):
        return
    dtype, device = getattr(torch, method.config.dtype), torch.device(method.train_device)
    rows = min(method.config.batch_size, *(len(d) for d in datasets))
    with torch.random.fork_rng(devices=[device] if device.type == "cuda" else []):
        torch.manual_seed(0)
        stack = StackedLagrangian([method.build_model(d).to(device, dtype) for d in datasets])
    t = [d.tensors(dtype, device) for d in datasets]
    q, qd, qdd = (torch.cat([x[k][:rows] for x in t]) for k in ("q", "qd", "qdd"))
    stack.compiled_torques(q, qd, qdd).sum().backward()


def train_lagrangians(methods: list, starts: list, datasets: list[Dataset], experiment: str, slots: list[RngSlot]) -> None:
    """The stacked loop of :class:`~methods.torch_method.TorchLagrangianMethod`'s
    own: mini-batch steps of the loss :meth:`loss` on the stack's predictions
    (a :class:`StackedLagrangian`), each seed's step by its :meth:`apply_step`."""
    loops = []
    for method, data, slot in zip(methods, datasets, slots):
        with slot:
            loops.append(method.start_loop(data))  # its network from its own seeded generators, as alone
    stack = StackedLagrangian([m.model for m in methods])
    experiment = Experiment.of(experiment)
    compiled = methods[0].compiles_stacked_step(experiment)
    while True:
        going = [s.progress.step() for s in starts]
        if not all(going):
            for s, g in zip(starts, going):
                if g:
                    s.progress.stop(SHARED_BUDGET)
            break
        batches = []
        for tensors, feed in loops:
            idx = feed.next()
            batches.append({k: v[idx] for k, v in tensors.items()})
        q, qd, qdd = (torch.cat([b[k] for b in batches]) for k in ("q", "qd", "qdd"))
        if experiment.learns_torque:
            pred = stack.compiled_torques(q, qd, qdd) if compiled else euler_lagrange(stack, q, qd, qdd, create_graph=True)
        else:
            pred = stack(q, qd)
        losses, row = [], 0
        for method, batch in zip(methods, batches):
            target = batch[experiment.target]
            losses.append(method.loss(pred[row:row + len(target)], target, experiment))
            row += len(target)
        stack.zero_grad()
        torch.stack(losses).sum().backward()
        stack.share_grads()
        for method, loss in zip(methods, losses):
            method.apply_step(loss)


#: why a stacked seed's loop ended before its own budget did
SHARED_BUDGET = "another seed of the stack used up the shared budget"


def fit_stacked(methods: list, datasets: list[Dataset], experiment: str, seeds: list[int], budget: Budget, *,
                system=None, on_fit=None) -> list:
    """Fit ``methods`` (instances of one stackable torch method, one configuration)
    on ``datasets`` with ``seeds``, one each, as one stacked model (see the module
    docstring); returns them fitted, each as :meth:`~methods.base.Method.fit`
    leaves it. The loop is the method's :meth:`~methods.base.Method.train_stacked`;
    its one-time work (:meth:`~methods.base.Method.prepare_stacked`) comes first,
    before the budgets start and ``on_fit()`` is called, and each fit's
    ``prepare_seconds`` is its time."""
    if not methods or not (len(methods) == len(datasets) == len(seeds)):
        raise ConfigError("fit_stacked needs one dataset and one seed per method")
    kind = type(methods[0])
    if any(type(m) is not kind or m.config != methods[0].config for m in methods):
        raise ConfigError(f"only fits of one stackable method in one configuration stack; got "
                          f"{sorted({type(m).name for m in methods})}")
    reason = methods[0].stacking_unavailable_reason()
    if reason:
        raise ConfigError(reason)
    experiment = Experiment.of(experiment)
    began = time.perf_counter()
    kind.prepare_stacked(methods, datasets, experiment)
    prepared = round(time.perf_counter() - began, 3)
    if on_fit is not None:
        on_fit()
    slots = [RngSlot(m.train_device) for m in methods]
    starts = []
    for method, data, seed, slot in zip(methods, datasets, seeds, slots):
        with slot:  # no one-time work of its own: what a method prepares for its own step is not the stack's
            start = method.begin_fit(data, experiment, seed, budget, system=system, prepare=False)
            starts.append(dataclasses.replace(start, prepare_seconds=prepared))
    with gc_frozen():
        kind.train_stacked(methods, starts, datasets, experiment, slots)
    out = []
    for method, start, data, slot in zip(methods, starts, datasets, slots):
        with slot:
            out.append(method.end_fit(start, data))
        method.fit_info["stacked"] = len(methods)
    return out
