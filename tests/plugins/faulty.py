"""Toy methods that misbehave in every way the harness must survive.

Imported as a plugin by the harness tests (``--plugin tests/plugins/faulty.py``).
"""

from __future__ import annotations

import os
import time

import numpy as np
import torch

from methods import METHODS, Method, MethodConfig
from methods.torch_method import TorchLagrangianMethod


class _Constant(Method):
    """Predicts the training mean of the target; one 'step'."""

    Config = MethodConfig
    smoke = {"max_steps": 1}

    def _fit(self, train, experiment, progress):
        self.L0 = float(np.mean(train.L)) if train.L is not None else 0.0
        self.tau0 = train.tau.mean(axis=0)
        while progress.step():
            progress.stop("solved")

    def _get_state(self):
        return (self.L0, self.tau0)

    def _set_state(self, state):
        self.L0, self.tau0 = state

    def predict_lagrangian(self, data):
        return np.full(len(data), self.L0)

    def predict_torque(self, data):
        return np.tile(self.tau0, (len(data), 1))


@METHODS.add("toy_constant", "toy")
class ToyConstant(_Constant):
    pass


@METHODS.add("toy_sleeper", "toy")
class ToySleeper(_Constant):
    """Ignores its deadline."""

    def _fit(self, train, experiment, progress):
        super()._fit(train, experiment, progress)
        time.sleep(3600)


@METHODS.add("toy_crasher", "toy")
class ToyCrasher(_Constant):
    def _fit(self, train, experiment, progress):
        raise RuntimeError("the toy fell over")


@METHODS.add("toy_exit", "toy")
class ToyExit(_Constant):
    """Dies without a trace, like a segfault."""

    def _fit(self, train, experiment, progress):
        print("about to vanish", flush=True)
        os._exit(3)


@METHODS.add("toy_nan", "toy")
class ToyNaN(_Constant):
    def predict_torque(self, data):
        return np.full((len(data), data.dof), np.nan)

    predict_lagrangian = lambda self, data: np.full(len(data), np.nan)  # noqa: E731


@METHODS.add("toy_unavailable", "toy")
class ToyUnavailable(_Constant):
    @classmethod
    def unavailable_reason(cls):
        return "needs a runtime this machine lacks"


@METHODS.add("toy_direct_only", "toy")
class ToyDirectOnly(_Constant):
    experiments = ("direct",)


@METHODS.add("toy_slow_judge", "toy")
class ToySlowJudge(_Constant):
    """Fits at once, then hangs in the evaluation after the fit."""

    def readable_expression(self):
        time.sleep(3600)


@METHODS.add("toy_bad_expression", "toy")
class ToyBadExpression(_Constant):
    """Fits, then fails to give its expression: a stage after the fit."""

    def readable_expression(self):
        raise ValueError("no expression today")


@METHODS.add("toy_prepared", "toy")
class ToyPrepared(_Constant):
    """Does one-time work before its budget (as compiling does), and says when."""

    def _prepare(self, train, experiment):
        self.prepared_at = time.perf_counter()

    def _fit(self, train, experiment, progress):
        self.fit_started_at = progress.start
        super()._fit(train, experiment, progress)

    def record_details(self):
        return {"prepared_before_the_budget": self.prepared_at < self.fit_started_at}


class _Unstackable(torch.nn.Module):
    """A network whose forward reads a number out of its input: fine alone, refused by ``vmap``."""

    def __init__(self, dof: int):
        super().__init__()
        self.w = torch.nn.Parameter(torch.ones(2 * dof, dtype=torch.float64))

    def forward(self, q, qd):
        x = torch.cat([q, qd], dim=-1)
        scale = 1.0 if x.abs().max().item() < 1e9 else 0.0
        return scale * (x * x * self.w).sum(-1)


@METHODS.add("toy_unstackable")
class ToyUnstackable(TorchLagrangianMethod):
    """A torch method whose seeds cannot train stacked: the stack's process fails, and each seed runs alone."""

    smoke = {"max_steps": 3, "eval_samples": 64}

    def build_model(self, train):
        return _Unstackable(train.dof)


@METHODS.add("toy_variant", "toy")
class ToyVariant(_Constant):
    """Fits, and derives a variant of its fit: the same constant shifted by 1."""

    def variants(self):
        shifted = ToyConstant()
        shifted.L0, shifted.tau0 = self.L0 + 1.0, self.tau0 + 1.0
        return {"shifted": shifted}
