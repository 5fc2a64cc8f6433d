"""SyReNets' hyperparameters; the defaults are the paper's."""

from __future__ import annotations

import typing
from dataclasses import dataclass
from typing import Annotated

from bench.core.errors import ConfigError
from methods.config import Range
from methods.torch_method import TorchConfig

#: the operators a layer may use
BINARY = ("sum", "prod", "diff")
UNARY = ("sin", "cos", "exp")


@dataclass(frozen=True)
class SyReNetsConfig(TorchConfig):
    """Hyperparameters; the defaults are the paper's.

    Attributes
    ----------
    layers, heads
        Symbolic layers and selection heads per layer.
    inputs
        ``"q_qd"`` (default, consistent) or ``"q_qd_qdd"`` (the public code's).
    operators
        Operators, a subset of ``sum, prod, diff, sin, cos, exp``.
    latent, ae_hidden, head_hidden
        Auto-encoder latent (d) and hidden widths; head hidden units.
    lambda_contractive, lambda_entropy, lambda_diversity
        lambda1, lambda2, lambda3.
    contractive_probes
        0: the exact closed-form contractive penalty; k > 0: Hutchinson's
        unbiased estimate with k Rademacher probes (cheaper, stochastic).
    lr_schedule
        ``"plateau"`` (the paper's): divide the learning rate by
        ``1 / lr_factor`` after ``lr_patience`` steps without improvement of
        the mini-batch loss, down to ``lr_min``. ``"cosine"``: anneal it from
        ``lr`` to ``lr_min`` along half a cosine over the training time (over
        the steps when ``max_steps`` is set).
    lr_patience, lr_factor, lr_min
        The plateau schedule; ``lr_min`` is the cosine's end too.
    lr_smoothing
        What the plateau schedule watches: 0 (the paper's) the loss of each
        mini-batch; ``a`` in (0, 1) an exponential moving average of it,
        ``a * previous + (1 - a) * batch`` (a window of about ``1 / (1 - a)``
        steps), so that one lucky batch does not start the patience count.
    replay
        Worst-fitted samples of the previous batch replayed each step
        (public code: 16; paper: 0).
    starts, start_share
        ``starts`` k > 1 initialises k networks and keeps one by successive
        halving within ``start_share`` of the training time (see
        :meth:`SyReNets._halve`); 1 (the paper's) trains one network.
    compile
        Compile the training pass (selection, transform and loss) with
        ``torch.compile``; see the package docstring.
    refine
        Run the exact-recovery refinement at the end (a separate variant).
    post_fraction
        Share of the budget reserved for pruning and refinement after training.
    """

    layers: Annotated[int, Range(1)] = 3
    heads: Annotated[int, Range(1)] = 12
    inputs: typing.Literal["q_qd", "q_qd_qdd"] = "q_qd"
    operators: tuple[str, ...] = ("sum", "prod", "sin", "cos")
    latent: Annotated[int, Range(1)] = 16
    ae_hidden: Annotated[int, Range(1)] = 128
    head_hidden: Annotated[int, Range(1)] = 64
    lambda_contractive: Annotated[float, Range(0)] = 1.0
    lambda_entropy: Annotated[float, Range(0)] = 1e-3
    lambda_diversity: Annotated[float, Range(0)] = 1.0
    contractive_probes: Annotated[int, Range(0)] = 1
    lr_schedule: typing.Literal["plateau", "cosine"] = "plateau"
    lr_patience: Annotated[int, Range(0)] = 1000
    lr_factor: Annotated[float, Range(0, 1, low_open=True, high_open=True)] = 0.1
    lr_min: Annotated[float, Range(0)] = 1e-5
    lr_smoothing: Annotated[float, Range(0, 1, high_open=True)] = 0.0
    replay: Annotated[int, Range(0)] = 0
    starts: Annotated[int, Range(1)] = 1
    start_share: Annotated[float, Range(0, 1, low_open=True, high_open=True)] = 0.5
    compile: bool = False
    refine: bool = True
    post_fraction: Annotated[float, Range(0, 1, high_open=True)] = 0.1

    def validate(self) -> None:
        bad = [op for op in self.operators if op not in BINARY + UNARY]
        if bad or not self.operators:
            raise ConfigError(f"syrenets: unknown operator(s) {bad}; choose from {', '.join(BINARY + UNARY)}")
        if len(set(self.operators)) != len(self.operators):
            raise ConfigError("syrenets: operators must not repeat")
