"""Parametric system identification (SysId), as in the paper.

The model is the system's own symbolic Lagrangian with its physical
parameters unknown (for the double pendulum m1, l1, m2, l2; g is known).
Following Valle & Haddadin (2021), Section IV, the unknowns are the outputs
of a small network whose input is a constant vector of ones: one hidden layer
of 64 softplus units without bias and a linear output layer with one unit per
unknown. It is trained with Adam at a constant learning rate of 1e-3, in
mini-batches of 32, keeping the best state.

Choices the paper leaves open
-----------------------------
* The constant input has one element.
* The output layer keeps its bias.
* The parametric form comes from the system (:meth:`bench.core.system.System.parametric_form`),
  so any registered system that declares one can be identified.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import sympy
import torch

from bench.core.errors import DataError
from bench.core.models import ParametricModel
from methods.base import METHODS, Range, TorchConfig, TorchLagrangianMethod


@dataclass(frozen=True)
class SysIdConfig(TorchConfig):
    """Attributes: ``hidden`` softplus units of the parameter network."""

    hidden: Annotated[int, Range(1)] = 64


class ParameterNetwork(torch.nn.Module):
    """ones -> Linear(no bias) -> softplus -> Linear -> theta; then L(q, qd; theta)."""

    def __init__(self, form, hidden: int):
        super().__init__()
        self.form = form
        self.register_buffer("ones", torch.ones(1))
        self.hidden = torch.nn.Linear(1, hidden, bias=False)
        self.out = torch.nn.Linear(hidden, len(form.unknowns))

    def theta(self) -> torch.Tensor:
        return self.out(torch.nn.functional.softplus(self.hidden(self.ones)))

    def forward(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return self.form.torch_fn(q, qd, self.theta())


@METHODS.add("sysid", "symbolic", "parametric", "baseline", "paper")
class SysId(TorchLagrangianMethod):
    Config = SysIdConfig
    smoke = {"max_steps": 20, "eval_samples": 256}

    def build_model(self, train):
        if self.system is None:
            raise DataError(f"{train.source}: sysid needs to know the data's system (got none) for its parametric form")
        self.form = self.system.parametric_form()
        return ParameterNetwork(self.form, self.config.hidden)

    def parametric(self) -> ParametricModel:
        """The form at the identified parameter values."""
        with torch.no_grad():
            return ParametricModel(self.form, self.model.theta().double().tolist())

    def identified_parameters(self) -> dict[str, float]:
        """The identified parameter values, by name."""
        return self.parametric().parameters()

    def expression(self) -> sympy.Expr:
        return self.parametric().expression()
