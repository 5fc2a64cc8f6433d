"""PySR (Cranmer, 2023): symbolic regression by evolution, on a Julia backend.

* **Direct**: ``PySRRegressor`` on ``X = (q, qd)``, ``y = L``.
* **Indirect**: a ``TemplateExpressionSpec`` with one sub-expression
  ``L(q_1..q_n, qd_1..qd_n)``. ``X = (q, qd, qdd, tau)`` and the template's
  ``combine`` computes, with PySR's derivative operator ``D(f, i)`` (the
  derivative of ``f`` in its ``i``-th argument), the squared Euler–Lagrange
  residual of each sample,

      sum_i ( tau_i - [ sum_j d2L/dqd_i dq_j qd_j + d2L/dqd_i dqd_j qdd_j - dL/dq_i ] )^2,

  which the loss ``(pred, target) -> pred`` sums over the data (the target is
  a dummy zero).

PySR downloads a Julia runtime the first time it is imported. Where that
cannot happen (no network to Julia's servers, as on this suite's build
machines) the method is listed as unavailable with the reason, and its runs
are recorded as ``unavailable``. The availability probe imports ``juliacall``
in a separate process with downloads switched off, so it never hangs and never
installs anything.
"""

from __future__ import annotations

import functools
import importlib.util
import math
import os
import subprocess
import sys
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import sympy

from bench.core import symbolic
from bench.core.data import Dataset
from bench.physics.models import ExpressionModel
from methods.base import METHODS, ExpressionMethod
from methods.config import MethodConfig, Range
from methods.progress import Progress

PROBE_TIMEOUT_S = 120


@dataclass(frozen=True)
class PySRConfig(MethodConfig):
    """Attributes: PySR's ``populations``, ``population_size``, ``maxsize``;
    ``fit_samples`` training samples given to it."""

    populations: Annotated[int, Range(1)] = 15
    population_size: Annotated[int, Range(1)] = 33
    maxsize: Annotated[int, Range(1)] = 40
    fit_samples: Annotated[int, Range(1)] = 2048


BINARY = ["+", "-", "*"]
UNARY = ["sin", "cos", "square", "cube", "sqrt_abs(x) = sqrt(abs(x))"]


def lagrangian_template(dof: int) -> dict:
    """Arguments of ``TemplateExpressionSpec`` for the indirect experiment.

    The ``combine`` code is straight-line arithmetic and calls only, so that
    it reads the same in Julia and in Python (the tests execute it in Python
    with a sympy ``D`` to check it against the suite's transform).
    """
    q = [f"q{i}" for i in range(1, dof + 1)]
    qd = [f"qd{i}" for i in range(1, dof + 1)]
    qdd = [f"qdd{i}" for i in range(1, dof + 1)]
    tau = [f"tau{i}" for i in range(1, dof + 1)]
    args = ", ".join(q + qd)
    lines = []
    for i in range(dof):
        vel = dof + i + 1  # argument index of qd_i (1-based, as in Julia)
        parts = [f"D(D(L, {vel}), {j + 1})({args}) * {qd[j]}" for j in range(dof)]
        parts += [f"D(D(L, {vel}), {dof + j + 1})({args}) * {qdd[j]}" for j in range(dof)]
        lines.append(f"r{i + 1} = {tau[i]} - ({' + '.join(parts)} - D(L, {i + 1})({args}))")
    lines.append(" + ".join(f"abs2(r{i + 1})" for i in range(dof)))
    return {"expressions": ["L"], "variable_names": q + qd + qdd + tau, "combine": "\n".join(lines)}


@functools.lru_cache(maxsize=1)
def _probe() -> str | None:
    if importlib.util.find_spec("pysr") is None:
        return "pysr is not installed (pip install pysr)"
    env = dict(os.environ, PYTHON_JULIAPKG_OFFLINE="yes")
    try:
        done = subprocess.run([sys.executable, "-c", "import juliacall"], env=env, capture_output=True,
                              text=True, timeout=PROBE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return f"PySR's Julia runtime did not start within {PROBE_TIMEOUT_S} s"
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        return f"PySR needs a Julia runtime, which it downloads at first import, and none is available here ({last[:200]})"
    return None


@METHODS.add("pysr", "symbolic", "genetic", "needs-julia")
class PySR(ExpressionMethod):
    title = "PySR"
    #: what the method is, for docs/methods_and_systems.md (generated from the registry)
    summary = ("PySR, directly and, indirectly, through a template whose loss is the Euler–Lagrange residual; "
               "needs a Julia runtime")
    Config = PySRConfig
    search_space = {"maxsize": (20, 40)}
    smoke = {"populations": 2, "population_size": 20, "fit_samples": 128, "max_steps": 1, "eval_samples": 128}
    work = 1  # one solve

    @classmethod
    def unavailable_reason(cls):
        return _probe()

    @classmethod
    def replay_unavailable_reason(cls):
        return ("PySR's search ends at its time limit and does not report the iterations it reached; "
                "run it with a work budget (--steps, its iterations) to repeat a run")

    def _fit(self, train: Dataset, experiment: str, progress: Progress) -> None:
        from pysr import PySRRegressor, TemplateExpressionSpec

        cfg = self.config
        rng = np.random.default_rng(self.seed)
        sub = train.subset(np.sort(rng.choice(len(train), min(len(train), cfg.fit_samples), replace=False)))
        self.model = ExpressionModel(sympy.Integer(0), train.dof)
        common = dict(
            binary_operators=BINARY, unary_operators=UNARY,
            extra_sympy_mappings={"sqrt_abs": lambda x: sympy.sqrt(sympy.Abs(x))},
            populations=cfg.populations, population_size=cfg.population_size, maxsize=cfg.maxsize,
            niterations=progress.work_limit or 10**6, precision=64,
            random_state=self.seed, deterministic=True, parallelism="serial", progress=False, verbosity=0,
        )
        while progress.step():
            remaining = progress.remaining()  # under a work budget its iterations bound it, and time does not
            seconds = max(1.0, remaining * 0.9) if math.isfinite(remaining) else None
            if not experiment.learns_torque:
                reg = PySRRegressor(timeout_in_seconds=seconds, **common)
                reg.fit(np.concatenate([sub.q, sub.qd], axis=1), sub.L,
                        variable_names=[f"q{i}" for i in range(1, train.dof + 1)] + [f"qd{i}" for i in range(1, train.dof + 1)])
                text = str(reg.sympy())
            else:
                spec = TemplateExpressionSpec(**lagrangian_template(train.dof))
                reg = PySRRegressor(timeout_in_seconds=seconds, expression_spec=spec,
                                    elementwise_loss="(pred, target) -> pred", **common)
                X = np.concatenate([sub.q, sub.qd, sub.qdd, sub.tau], axis=1)
                reg.fit(X, np.zeros(len(sub)))
                best = reg.get_best()
                text = str(best["julia_expression"].trees.L)
            self.pysr_text = text
            self.model = ExpressionModel(_parse(text, train.dof), train.dof)
            progress.stop("solved")



def _parse(text: str, dof: int) -> sympy.Expr:
    """A PySR expression (variables ``q1``, ``qd1`` or ``#1``..) in the suite's symbols."""
    q, qd = symbolic.coordinate_symbols(dof)
    local = {f"q{i + 1}": q[i] for i in range(dof)} | {f"qd{i + 1}": qd[i] for i in range(dof)}
    for k, s in reversed(list(enumerate(list(q) + list(qd)))):  # "#12" before "#1"
        text = text.replace(f"#{k + 1}", f"__x{k + 1}")
        local[f"__x{k + 1}"] = s
    local |= {"square": lambda x: x**2, "cube": lambda x: x**3, "sqrt_abs": lambda x: sympy.sqrt(sympy.Abs(x))}
    return sympy.sympify(text.replace("^", "**"), locals=local)
