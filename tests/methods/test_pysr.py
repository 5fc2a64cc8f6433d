"""PySR adapter: the indirect template, the availability check, and a real run where Julia exists."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
import sympy

from bench.core import symbolic
from bench.core.data import generate, mse
from bench.physics.dynamics import euler_lagrange
from methods import METHODS
from methods import pysr_adapter
from methods.pysr_adapter import _parse, lagrangian_template
from bench.core.budget import Budget


class _Function:
    """A sympy-backed stand-in for a PySR sub-expression, with PySR's ``D``."""

    def __init__(self, expr, args):
        self.expr, self.args = expr, args

    def __call__(self, *values):
        return sympy.lambdify(self.args, self.expr, "numpy")(*values) + 0 * values[0]


def _run_combine(code: str, L: sympy.Expr, data) -> np.ndarray:
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    env = {"L": _Function(L, [q1, q2, qd1, qd2]), "abs2": np.square,
           "D": lambda f, i: _Function(sympy.diff(f.expr, f.args[i - 1]), f.args)}
    for name, column in zip(lagrangian_template(2)["variable_names"],
                            np.concatenate([data.q, data.qd, data.qdd, data.tau], axis=1).T):
        env[name] = column
    *body, last = code.splitlines()
    exec("\n".join(body), env)  # the combine code is plain arithmetic and calls in both languages
    return eval(last, env)


def test_template_declares_L_over_q_and_qd_and_reads_tau(double_pendulum):
    spec = lagrangian_template(2)
    assert spec["expressions"] == ["L"]
    assert spec["variable_names"] == ["q1", "q2", "qd1", "qd2", "qdd1", "qdd2", "tau1", "tau2"]
    assert "D(D(L, 3), 1)(q1, q2, qd1, qd2) * qd1" in spec["combine"]


def test_template_residual_is_the_euler_lagrange_residual(double_pendulum):
    data = generate(double_pendulum, 300, 2)
    truth = double_pendulum.lagrangian_sympy
    code = lagrangian_template(2)["combine"]
    assert np.abs(_run_combine(code, truth, data)).max() < 1e-18
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    wrong = truth + 0.3 * qd1 * qd2 + sympy.sin(q2)
    t = data.tensors()
    tau = euler_lagrange(symbolic.to_torch(wrong, 2), t["q"], t["qd"], t["qdd"]).numpy()
    expected = ((data.tau - tau) ** 2).sum(axis=1)
    np.testing.assert_allclose(_run_combine(code, wrong, data), expected, rtol=1e-10)


def test_pysr_expressions_are_parsed_into_the_suites_symbols():
    (q1, q2), (qd1, qd2) = symbolic.coordinate_symbols(2)
    assert _parse("square(qd1) * 3.5 + cos(q2)", 2) == 3.5 * qd1**2 + sympy.cos(q2)
    assert _parse("(#3 * #1) - sqrt_abs(#2)", 2) == qd1 * q1 - sympy.sqrt(sympy.Abs(q2))


def test_unavailable_with_a_reason_when_julia_cannot_start(monkeypatch):
    pysr_adapter._probe.cache_clear()
    monkeypatch.setattr(pysr_adapter.importlib.util, "find_spec", lambda name: object())

    def no_julia(*args, **kwargs):
        return subprocess.CompletedProcess(args, 1, "", "Traceback...\nOSError: could not download Julia")

    monkeypatch.setattr(pysr_adapter.subprocess, "run", no_julia)
    reason = METHODS.entry("pysr").unavailable_reason()
    assert "Julia" in reason and "could not download Julia" in reason
    pysr_adapter._probe.cache_clear()


def test_not_installed_is_a_reason_too(monkeypatch):
    pysr_adapter._probe.cache_clear()
    monkeypatch.setattr(pysr_adapter.importlib.util, "find_spec", lambda name: None)
    assert METHODS.entry("pysr").unavailable_reason() == "pysr is not installed (pip install pysr)"
    pysr_adapter._probe.cache_clear()


def test_matrix_records_pysr_as_unavailable_not_failed(tmp_path, monkeypatch):
    from bench.runner import matrix
    from bench.runner.progress import quiet
    from bench.runner.spec import build_specs

    pysr_adapter._probe.cache_clear()
    monkeypatch.setattr(pysr_adapter, "_probe", lambda: "no Julia runtime here")
    specs = build_specs(["double_pendulum"], ["pysr"], ["direct", "indirect"], [0], 5.0, n_train=32, n_test=16)
    records = matrix.run_matrix(specs, tmp_path, workers=1, report=quiet)
    assert [r.status for r in records] == ["unavailable", "unavailable"]
    assert records[0].error == "no Julia runtime here"


@pytest.mark.external
def test_real_pysr_run_finds_a_planted_lagrangian(double_pendulum):
    reason = METHODS.entry("pysr").unavailable_reason()
    if reason:
        pytest.skip(reason)
    train, test = generate(double_pendulum, 1000, 0), generate(double_pendulum, 200, 1)
    for experiment in ("direct", "indirect"):
        m = METHODS["pysr"](populations=8).fit(train, experiment, seed=0, budget=Budget(seconds=300))
        assert mse(m.predict(test), test.target(experiment)) < 1e-3 * np.var(test.target(experiment))
