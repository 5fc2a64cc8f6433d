"""Methods whose model is a torch module ``(q, qd) -> L``, trained by
mini-batch Adam on the direct or the indirect loss.

A subclass of :class:`TorchLagrangianMethod` writes :meth:`~TorchLagrangianMethod.build_model`
and, optionally, a learning-rate schedule and an extra loss; the base class
(:class:`methods.base.Method`) owns the budget, the evaluations and the best state.
"""

from __future__ import annotations

import abc
import typing
from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
import torch

from bench.core.experiment import Experiment
from bench.core.data import Dataset
from bench.physics.dynamics import euler_lagrange
from bench.core.modelfile import ModelFileError, Packer, Unpacker, loader
from bench.physics.models import LagrangianFunction
from methods.base import Method, restored, saved_hyperparameters
from methods.config import POSITIVE, MethodConfig, Range
from methods.progress import Progress
from methods.stacking import prepare_lagrangians, train_lagrangians


@dataclass(frozen=True)
class TorchConfig(MethodConfig):
    """Hyperparameters shared by mini-batch torch methods.

    Attributes
    ----------
    lr
        Adam learning rate.
    betas
        Adam's moment coefficients.
    batch_size
        Mini-batch size; batches are drawn without replacement, reshuffled
        every epoch.
    dtype
        ``"float64"`` or ``"float32"``.
    """

    lr: Annotated[float, POSITIVE] = 1e-3
    betas: Annotated[tuple[float, float], Range(0, 1, high_open=True)] = (0.9, 0.999)
    batch_size: Annotated[int, Range(1)] = 32
    dtype: typing.Literal["float64", "float32"] = "float64"


@dataclass
class Feed:
    """A fit's mini-batches of ``bs`` of the ``n`` samples: a random order
    from the fit's seed, drawn without replacement and reshuffled when fewer
    than ``bs`` are left (SyReNets' networks of a multi-start fit share one)."""

    n: int
    bs: int
    generator: torch.Generator
    order: torch.Tensor
    cursor: int = 0

    @classmethod
    def start(cls, n: int, bs: int, seed: int) -> "Feed":
        generator = torch.Generator().manual_seed(seed)
        return cls(n, bs, generator, torch.randperm(n, generator=generator))

    def next(self) -> torch.Tensor:
        """The next batch's sample indices."""
        if self.cursor + self.bs > self.n:
            self.order, self.cursor = torch.randperm(self.n, generator=self.generator), 0
        idx = self.order[self.cursor:self.cursor + self.bs]
        self.cursor += self.bs
        return idx


class Warmup:
    """The learning rate of each group raised linearly over the first
    ``steps`` steps, from ``1/steps`` of its value to its value, then held.
    It counts steps, not time, so a replay repeats it."""

    def __init__(self, optimizer: torch.optim.Optimizer, steps: int):
        self.optimizer, self.steps, self.done = optimizer, max(int(steps), 1), 0
        self.lrs = [g["lr"] for g in optimizer.param_groups]
        self._set()

    def _set(self) -> None:
        scale = min(1.0, (self.done + 1) / self.steps)
        for group, lr in zip(self.optimizer.param_groups, self.lrs):
            group["lr"] = lr * scale

    def step(self, loss: float) -> None:
        self.done += 1
        self._set()


class TorchLagrangianMethod(Method, LagrangianFunction):
    """A method whose model is a ``torch.nn.Module`` mapping ``(q, qd) -> L``.

    The loop is mini-batch Adam on the direct loss ``MSE(L_hat, L)`` or the
    indirect loss ``MSE(g(L_hat), tau)``; subclasses write :meth:`build_model`
    and optionally :meth:`make_scheduler`, :meth:`extra_loss` and
    :meth:`optimizer_options`.
    """

    Config: ClassVar[type] = TorchConfig
    supports_warm_start: ClassVar[bool] = True
    uses_device: ClassVar[bool] = True
    #: whether several seeds' fits can train as one stacked model (:mod:`methods.stacking`): a method
    #: whose loop is this class's and whose loss is :meth:`loss` (see :meth:`stacking_unavailable_reason`)
    stackable: ClassVar[bool] = True
    #: set ``True`` in the class body that overrides :meth:`batch_loss` or :meth:`extra_loss` where
    #: what they compute is still the stacked loop's loss (:meth:`loss` of the batch's predictions);
    #: a subclass that overrides them again must say so again
    stacked_loss_is_batch_loss: ClassVar[bool] = False
    model: torch.nn.Module

    @abc.abstractmethod
    def build_model(self, train: Dataset) -> torch.nn.Module:
        """The network, for data of ``train``'s shape."""

    @classmethod
    def prepare_stacked(cls, methods, datasets, experiment) -> None:
        prepare_lagrangians(methods, datasets, experiment)

    @classmethod
    def train_stacked(cls, methods, starts, datasets, experiment, slots) -> None:
        train_lagrangians(methods, starts, datasets, experiment, slots)

    def compiles_stacked_step(self, experiment: str) -> bool:
        """Whether a stacked fit (:mod:`methods.stacking`) compiles its step, the
        Euler–Lagrange torques of the stack: for a network with its own
        derivatives (``tangent``) whose method compiles its own step."""
        return False

    def stacking_unavailable_reason(self) -> str | None:
        """Why this method's seeds cannot train as one stacked model, or ``None``.
        The stacked loop (:func:`methods.stacking.train_lagrangians`) computes
        :meth:`loss` of each seed's predictions and never calls :meth:`batch_loss`
        or :meth:`extra_loss`: a class that overrides either stacks only where its
        own class body says that its loss is still :meth:`loss`
        (:attr:`stacked_loss_is_batch_loss`)."""
        reason = super().stacking_unavailable_reason()
        if reason:
            return reason
        unsaid = []
        for hook in ("batch_loss", "extra_loss"):
            owner = next(k for k in type(self).__mro__ if hook in vars(k))
            if owner is not TorchLagrangianMethod and not vars(owner).get("stacked_loss_is_batch_loss", False):
                unsaid.append(f"{owner.__name__}.{hook}")
        if unsaid:
            return (f"{self.name} overrides {' and '.join(unsaid)}, which the stacked loop does not call: it trains "
                    f"alone (a class whose loss is still its loss(), stacked, says so with "
                    f"stacked_loss_is_batch_loss = True)")
        return None

    def make_scheduler(self, optimizer: torch.optim.Optimizer):
        """Return an object with ``step(loss: float)``, or ``None``."""
        return None

    def extra_loss(self) -> torch.Tensor | float:
        return 0.0

    def optimizer_options(self) -> dict:
        """Further keywords of ``torch.optim.Adam`` (``weight_decay``, ``amsgrad``)."""
        return {}

    @property
    def dtype(self) -> torch.dtype:
        """``config.dtype`` while the network trains; float64 once the fit is
        done. A float32 network's torques carry rounding noise that an
        adaptive integrator takes for stiffness: a rollout evaluated in
        float32 needs many times the right-hand sides."""
        return torch.float64 if getattr(self, "_trained", False) else getattr(torch, self.config.dtype)

    @property
    def device(self) -> torch.device:
        """:attr:`~methods.base.Method.train_device` while the network trains; the
        CPU once the fit is done, where every method's fit is evaluated."""
        return torch.device("cpu" if getattr(self, "_trained", False) else self.train_device)

    @property
    def lagrangian(self):
        """The model: a module ``(q, qd) -> L``. One with a ``tangent`` method
        (:class:`bench.physics.dynamics.TangentLagrangian`) gives the
        Euler–Lagrange transform its own derivatives."""
        return self.model

    def loss(self, prediction: torch.Tensor, target: torch.Tensor, experiment: str) -> torch.Tensor:
        """The training loss of a batch's predictions (``L``, or the torques): the mean squared error."""
        return torch.mean((prediction - target) ** 2)

    def batch_loss(self, batch: dict[str, torch.Tensor], experiment: str) -> torch.Tensor:
        experiment = Experiment.of(experiment)
        if experiment.learns_torque:
            pred = euler_lagrange(self.lagrangian, batch["q"], batch["qd"], batch["qdd"], create_graph=True)
        else:
            pred = self.lagrangian(batch["q"], batch["qd"])
        target = batch[experiment.target]
        return self.loss(pred, target, experiment) + self.extra_loss()

    def _start_training(self) -> None:
        """Back to ``config.dtype`` for a fit: a warm start's network returns
        to the arithmetic its optimiser's state has."""
        self._trained = False
        if self.warm_start:
            self.model.to(self.device, self.dtype)

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        tensors, feed = self.start_loop(train)
        while progress.step():
            idx = feed.next()
            batch = {k: v[idx] for k, v in tensors.items()}
            loss = self.batch_loss(batch, experiment)
            self._optimizer.zero_grad(set_to_none=True)
            loss.backward()
            self.apply_step(loss)

    def start_loop(self, train: Dataset) -> tuple[dict[str, torch.Tensor], Feed]:
        """The loop's start: the network (built from the generators as the fit
        seeded them), its optimiser and schedule unless a warm start keeps
        them, the data's tensors on the device and the fit's feed of batches."""
        self._start_training()
        if not self.warm_start:
            self.model = self.build_model(train).to(self.device, self.dtype)
            self._optimizer = torch.optim.Adam(
                self.model.parameters(), lr=self.config.lr, betas=self.config.betas, **self.optimizer_options(),
                **({"fused": True} if fused_adam_ok(self.dtype, self.device) else {}),
            )
            self._scheduler = self.make_scheduler(self._optimizer)
        tensors = train.tensors(self.dtype, self.device)
        return tensors, Feed.start(len(train), min(self.config.batch_size, len(train)), self.seed)

    def apply_step(self, loss: torch.Tensor) -> None:
        """The optimiser's step on the gradients of ``loss`` (already back-propagated), and the schedule's."""
        self._optimizer.step()
        if self._scheduler is not None:
            self._scheduler.step(loss.item())

    def _post_fit(self, train: Dataset, experiment: str, seconds_left: float) -> None:
        self._trained = True  # the fitted function is evaluated in float64, on the CPU, from here on
        if getattr(self, "model", None) is not None:  # a method may fit without a network (SysId's linear form)
            self.model.to("cpu", torch.float64)

    def size(self) -> dict:
        model = getattr(self, "model", None)
        return {} if model is None else {"parameters": sum(p.numel() for p in model.parameters())}

    def _get_state(self):
        return {k: v.detach().clone() for k, v in self.model.state_dict().items()}

    def _set_state(self, state) -> None:
        self.model.load_state_dict(state)

    def saved(self, packer: Packer) -> dict:
        """The network's weights, with the method and hyperparameters that build it (:func:`_load_network`)."""
        return {"kind": "network", "method": self.name, "hyperparameters": saved_hyperparameters(self),
                "state": packer.tensors(self.model.state_dict())}


@loader("network")
def _load_network(tree: dict, unpacker: Unpacker, context: dict):
    """A torch method's network, built for the joints and given its saved weights, evaluated in float64 on the CPU."""
    method = restored(tree, context)
    dof = method.dof
    zeros = np.zeros((1, dof))
    shape = Dataset(zeros, zeros, zeros, zeros, system=getattr(method.system, "name", None))
    state = unpacker.tensors(tree["state"])
    with torch.device("meta"):  # the network the file's hyperparameters describe, without memory: its shapes
        probe = method.build_model(shape)
    wanted = {k: tuple(v.shape) for k, v in probe.state_dict().items()}
    if wanted != {k: tuple(v.shape) for k, v in state.items()}:
        raise ModelFileError(f"{unpacker.source}: its {method.name} network's hyperparameters describe weights "
                             f"other than the {len(state)} arrays the file holds")
    method.model = method.build_model(shape)
    method.model.to("cpu", torch.float64)
    method.model.load_state_dict(state)
    method._trained = True
    return method


def fused_adam_ok(dtype: torch.dtype, device: torch.device = torch.device("cpu")) -> bool:
    """Whether torch's fused Adam takes parameters of ``dtype`` on ``device``
    (on a CPU from torch 2.4, where it is about 3x faster for a 5x300 MLP)."""
    major, minor = (int(x) for x in torch.__version__.split(".")[:2])
    return (major, minor) >= (2, 4) and dtype in (torch.float32, torch.float64) and device.type in ("cpu", "cuda")
