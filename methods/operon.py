"""Operon (pyoperon): a fast C++ genetic-programming symbolic regressor.

Burlacu, Kronberger & Kommenda (2020), "Operon C++: an efficient genetic
programming framework for symbolic regression". Used through its
scikit-learn interface in the direct experiment: ``L = f(q, qd)``, with
Operon's own nonlinear least-squares tuning of the constants, the operator
set closest to the paper's (+ - x, sin, cos, square, sqrt|x|), population
1000, one thread, and the run's wall-clock budget as Operon's time limit.
Under a work budget its generations are the limit; a time-budgeted run
records the generations it reached (``details.generations``), the work a
replay repeats.

Not applicable to the indirect experiment: Operon fits ``y = f(X)`` to
samples of ``y``, and there are none of ``L`` there; the torque is the
Euler–Lagrange transform of the model, a derivative that Operon cannot put
into its loss.
"""

from __future__ import annotations

import importlib.util
import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import sympy

from bench.core.experiment import DIRECT
from bench.core import symbolic
from bench.core.data import Dataset
from bench.physics.models import ExpressionModel
from methods.base import METHODS, ExpressionMethod
from methods.config import MethodConfig, Range
from methods.progress import Progress

#: Operon's time limit where the fit has none (its generations bound it)
UNLIMITED_S = 10**7
#: Operon's generations where only its time limit bounds it
UNLIMITED_GENERATIONS = 10**6
NOT_APPLICABLE = (
    "Operon fits y = f(X) to samples of y; the indirect experiment has no samples of L, only torques, "
    "which are a derivative (the Euler-Lagrange transform) of the model that Operon cannot put into its loss"
)


@dataclass(frozen=True)
class OperonConfig(MethodConfig):
    """Attributes: Operon's ``population_size``, ``allowed_symbols``,
    ``max_length``; ``fit_samples`` training samples given to it."""

    population_size: Annotated[int, Range(1)] = 1000
    allowed_symbols: str = "add,sub,mul,sin,cos,square,sqrtabs,constant,variable"
    max_length: Annotated[int, Range(1)] = 50
    fit_samples: Annotated[int, Range(1)] = 4096


@METHODS.add("operon", "symbolic", "genetic")
class Operon(ExpressionMethod):
    title = "Operon"
    #: what the method is, for docs/methods_and_systems.md (generated from the registry)
    summary = "Operon's C++ symbolic regression (pyoperon), direct experiment only"
    Config = OperonConfig
    experiments = (DIRECT,)
    not_applicable = NOT_APPLICABLE
    search_space = {"max_length": (25, 50), "population_size": (500, 1000)}
    smoke = {"population_size": 50, "fit_samples": 128, "max_steps": 1, "eval_samples": 128}
    work = 1  # one solve

    @classmethod
    def unavailable_reason(cls):
        if importlib.util.find_spec("pyoperon") is None:
            return "pyoperon is not installed (pip install pyoperon)"
        return None

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        from pyoperon.sklearn import SymbolicRegressor

        cfg = self.config
        rng = np.random.default_rng(self.seed)
        sub = train.subset(np.sort(rng.choice(len(train), min(len(train), cfg.fit_samples), replace=False)))
        X, y = np.concatenate([sub.q, sub.qd], axis=1), sub.L
        self.names = [str(s) for s in sum(symbolic.coordinate_symbols(train.dof), ())]
        self.model = ExpressionModel(sympy.Float(float(np.mean(y))), train.dof)
        self.generations = None
        while progress.step():
            # Operon checks its time limit between generations; leave it a margin. Under a work
            # budget (or a replay) its generations are the limit and time none.
            remaining = progress.remaining()
            seconds = max(1, math.floor(remaining * 0.9)) if math.isfinite(remaining) else UNLIMITED_S
            generations = progress.work_limit or UNLIMITED_GENERATIONS
            reg = SymbolicRegressor(
                allowed_symbols=cfg.allowed_symbols, population_size=cfg.population_size,
                max_length=cfg.max_length, generations=generations, max_time=seconds,
                n_threads=1, random_state=self.seed,
            )
            reg.fit(X, y)
            self.generations = int(reg.stats_["generations"])
            text = reg.get_model_string(reg.model_, 17, self.names)
            self.operon_string = text
            self.model = ExpressionModel(parse_operon(text, self.names), train.dof)
            progress.stop("solved")

    def _work_done(self, progress: Progress) -> int:
        """Operon's generations: its whole search runs inside one step of the loop."""
        return self.generations if self.generations is not None else progress.steps

    def record_details(self):
        return {"generations": self.generations}


def parse_operon(text: str, names: list[str]) -> sympy.Expr:
    """Operon's infix model string as a sympy expression in the suite's symbols."""
    dof = len(names) // 2
    q, qd = symbolic.coordinate_symbols(dof)
    local = {str(s): s for s in list(q) + list(qd)}
    local.update({
        "square": lambda x: x**2,
        "sqrtabs": lambda x: sympy.sqrt(sympy.Abs(x)),
        "sqrt": sympy.sqrt,
        "abs": sympy.Abs,
        "sin": sympy.sin,
        "cos": sympy.cos,
        "exp": sympy.exp,
        "log": sympy.log,
    })
    return sympy.sympify(text.replace("^", "**"), locals=local)
