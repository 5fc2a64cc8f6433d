"""The README's path for adding a method and a system, end to end.

A toy system and a toy method are registered here, in the test file, exactly
as the README shows; the harness (in worker processes, importing this file
as a plugin) and the table step then cover them like the suite's own.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sympy

# the README's imports
from bench.core import symbolic
from bench.core.data import generate
from bench.physics.dynamics import euler_lagrange
from bench.reporting.tables import write_tables
from bench.runner.matrix import run_matrix
from bench.runner.progress import quiet
from bench.runner.spec import build_specs
from methods import METHODS, Method, MethodConfig
from systems import SYSTEMS, System
from tests.contract import check_method, check_system


# -- a system: one file, one registration line -------------------------------------------

@dataclass(frozen=True)
class MassSpringParams:
    m: float = 2.0
    k: float = 5.0


@SYSTEMS.add("toy_mass_spring", "simulated", "toy")
class MassSpring(System):
    """L = m qd^2 / 2 - k q^2 / 2."""

    coordinates = ("x",)
    Params = MassSpringParams
    sysid_unknowns = ("m", "k")

    def lagrangian_expr(self, q, qd, p):
        return p.m * qd[0] ** 2 / 2 - p.k * q[0] ** 2 / 2


# -- a method: one file, one registration line ----------------------------------------------

@dataclass(frozen=True)
class QuadraticConfig(MethodConfig):
    ridge: float = 0.0


@METHODS.add("toy_quadratic", "symbolic", "toy")
class QuadraticLagrangian(Method):
    """L = sum_i a_i qd_i^2 + b_i q_i^2 + c, fitted by least squares.

    Indirectly, g is linear in L, so the torques of the basis functions are
    regressed on tau.
    """

    Config = QuadraticConfig
    smoke = {"max_steps": 1}

    def _basis(self, dof):
        q, qd = symbolic.coordinate_symbols(dof)
        return [s**2 for s in qd] + [s**2 for s in q] + [sympy.Integer(1)]

    def _fit(self, train, experiment, progress):
        basis = self._basis(train.dof)
        t = train.tensors()
        if experiment == "direct":
            X = np.stack([symbolic.to_numpy(b, train.dof)(train.q, train.qd) for b in basis], axis=1)
            y = train.L
        else:
            cols = [euler_lagrange(symbolic.to_torch(b, train.dof), t["q"], t["qd"], t["qdd"]).numpy().ravel() for b in basis]
            X, y = np.stack(cols, axis=1), train.tau.ravel()
        self.coef = np.zeros(len(basis))
        while progress.step():
            A = X.T @ X + self.config.ridge * np.eye(X.shape[1])
            self.coef = np.linalg.lstsq(A, X.T @ y, rcond=None)[0]
            progress.stop("solved")

    def _get_state(self):
        return self.coef.copy()

    def _set_state(self, state):
        self.coef = state

    def expression(self):
        return sum(sympy.Float(c) * b for c, b in zip(self.coef, self._basis(self.dof)))

    def predict_lagrangian(self, data):
        return symbolic.to_numpy(self.expression(), data.dof)(data.q, data.qd)

    def predict_torque(self, data):
        t = data.tensors()
        return euler_lagrange(symbolic.to_torch(self.expression(), data.dof), t["q"], t["qd"], t["qdd"]).numpy()


# -- the tests ----------------------------------------------------------------------------------

def test_toy_system_and_method_pass_the_contracts():
    system = SYSTEMS["toy_mass_spring"]()
    check_system(system)
    train, test = generate(system, 128, 0), generate(system, 64, 1000)
    for experiment in ("direct", "indirect"):
        check_method(METHODS["toy_quadratic"], train, test, experiment)


def test_toy_runs_through_the_harness_and_the_tables(tmp_path):
    specs = build_specs(
        ["toy_mass_spring", "double_pendulum"], ["toy_quadratic", "sysid"], ["direct", "indirect"], [0, 1], 2.0,
        profile="smoke", n_train=128, n_test=64, plugins=(str(Path(__file__).resolve()),),
    )
    records = run_matrix(specs, tmp_path, workers=2, report=quiet)
    assert all(r.status == "ok" for r in records), [r.error for r in records if r.status != "ok"]
    exact = [r for r in records if r.system == "toy_mass_spring" and r.method == "toy_quadratic"]
    assert len(exact) == 4 and all(r.test_mse < 1e-20 for r in exact)
    # the toy cannot express the double pendulum
    assert all(r.test_mse > 1e-3 for r in records if r.system == "double_pendulum" and r.method == "toy_quadratic")
    text = write_tables(tmp_path)
    assert "## toy_mass_spring, direct experiment" in text and "## toy_mass_spring, indirect experiment" in text
    assert "| Group | Split | sysid | toy_quadratic |" in text
    assert "| Runs | | 2/2 ok | 2/2 ok |" in text
