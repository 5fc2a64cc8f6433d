"""Exact recovery of a Lagrangian, up to its gauge.

A Lagrangian is determined by the dynamics only up to an additive constant, a
total time derivative ``dF(q)/dt`` and a global scale. In the indirect
experiment the scale is fixed by the torques; in the direct experiment the
values of ``L`` fix everything but the constant. Hence:

* **indirect**: ``L_hat`` is exact when ``g(L_hat) - g(L) = 0``, judged
  symbolically on the Euler–Lagrange images;
* **direct**: ``L_hat`` is exact when ``L_hat - L`` is a constant.

The symbolic judgement expands the difference (trigonometric functions of
sums are expanded too), drops every term whose coefficient is below
``tolerance`` times the largest coefficient of the truth, and asks sympy
whether what remains simplifies to zero (or, direct, to a constant).
Numerical agreement on fresh samples is checked as well, and both verdicts are
returned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import sympy
import torch

from bench.core.experiment import Experiment
from bench.core import symbolic
from bench.physics.dynamics import euler_lagrange
from bench.core.timeouts import call_with_timeout

#: relative size below which a coefficient of the difference counts as zero
TOLERANCE = 1e-6


@dataclass(frozen=True)
class Verdict:
    exact: bool
    symbolic: bool
    numeric: bool
    residual: str  # what was left of the difference after rounding, as text

    def as_dict(self) -> dict:
        return {"exact": self.exact, "symbolic": self.symbolic, "numeric": self.numeric, "residual": self.residual}


def euler_lagrange_symbolic(L: sympy.Expr, dof: int) -> list[sympy.Expr]:
    """``tau_i = d/dt dL/dqd_i - dL/dq_i`` in q, qd, qdd symbols."""
    q, qd = symbolic.coordinate_symbols(dof)
    qdd = symbolic.acceleration_symbols(dof)
    out = []
    for i in range(dof):
        p = sympy.diff(L, qd[i])
        dt = sum(sympy.diff(p, q[j]) * qd[j] + sympy.diff(p, qd[j]) * qdd[j] for j in range(dof))
        out.append(dt - sympy.diff(L, q[i]))
    return out


def _even_functions(expr: sympy.Expr) -> sympy.Expr:
    """cos is even: ``cos(|u|) = cos(u)`` for real u, which sympy leaves alone."""
    return expr.replace(
        lambda e: isinstance(e, sympy.cos) and isinstance(e.args[0], sympy.Abs), lambda e: sympy.cos(e.args[0].args[0])
    )


def _canonical(expr: sympy.Expr) -> sympy.Expr:
    return sympy.expand(sympy.expand_trig(sympy.expand(_even_functions(expr))))


def _coefficients(expr: sympy.Expr) -> list[float]:
    out = []
    for term in sympy.Add.make_args(expr):
        c, _ = term.as_coeff_Mul()
        if c.is_number:
            out.append(abs(float(c)))
    return out


def _rounded(expr: sympy.Expr, cutoff: float) -> sympy.Expr:
    """Drop the terms of an expanded expression whose coefficient is below ``cutoff``."""
    kept = []
    for term in sympy.Add.make_args(expr):
        c, rest = term.as_coeff_Mul()
        if abs(float(c)) >= cutoff:
            kept.append(term)
    return sympy.Add(*kept)


def _vanishes(diff: sympy.Expr, scale: float, tolerance: float, allow_constant: bool) -> tuple[bool, sympy.Expr]:
    remainder = _rounded(_canonical(diff), tolerance * scale)
    if allow_constant:
        remainder = sympy.Add(*[t for t in sympy.Add.make_args(remainder) if t.free_symbols])
    if remainder == 0:
        return True, remainder
    simplified = sympy.simplify(sympy.trigsimp(remainder))
    simplified = _rounded(_canonical(simplified), tolerance * scale)
    if allow_constant:
        simplified = sympy.Add(*[t for t in sympy.Add.make_args(simplified) if t.free_symbols])
    return simplified == 0, simplified


def judge(L_hat: sympy.Expr, L_true: sympy.Expr, dof: int, experiment: str, *,
          tolerance: float = TOLERANCE, up_to_scale: bool = False,
          domain=None, seed: int = 12345, symbolic_limit_s: float = math.inf) -> Verdict:
    """Is ``L_hat`` the true Lagrangian ``L_true`` up to the gauge of ``experiment``?

    ``up_to_scale=True`` also allows a global factor (for dynamics without
    torques, where nothing fixes the scale): ``L_hat`` is first rescaled by the
    least-squares factor of its torques onto the true ones. The numerical
    check runs first; the symbolic one only when it passes, so that a clear
    miss costs no algebra. With a finite ``symbolic_limit_s`` the symbolic
    check (pure sympy, which cannot be asked to stop) runs in a child
    process, and :class:`~bench.core.timeouts.Timeout` is raised when it has
    not ended in that time.
    """
    experiment = Experiment.of(experiment)
    L_hat = _even_functions(symbolic.numeric_subexpressions_to_floats(sympy.sympify(L_hat)))
    if up_to_scale:
        L_hat = _best_scale(L_hat, L_true, dof, domain, seed) * L_hat
    if not _numerically_equal(L_hat, L_true, dof, experiment, tolerance, domain, seed):
        return Verdict(exact=False, symbolic=False, numeric=False, residual="differs numerically on fresh samples")

    def symbolic_check() -> tuple[bool, str]:
        if not experiment.learns_torque:
            scale = max(_coefficients(_canonical(L_true)), default=1.0)
            ok, residual = _vanishes(L_hat - L_true, scale, tolerance, allow_constant=True)
            return bool(ok), str(residual)
        tau_hat, tau_true = euler_lagrange_symbolic(L_hat, dof), euler_lagrange_symbolic(L_true, dof)
        scale = max((c for t in tau_true for c in _coefficients(_canonical(t))), default=1.0)
        checks = [_vanishes(a - b, scale, tolerance, allow_constant=False) for a, b in zip(tau_hat, tau_true)]
        return bool(all(ok for ok, _ in checks)), str(sympy.Tuple(*[r for _, r in checks]))

    sym_ok, residual = symbolic_check() if math.isinf(symbolic_limit_s) else call_with_timeout(symbolic_check, symbolic_limit_s)
    return Verdict(exact=sym_ok, symbolic=sym_ok, numeric=True, residual=residual)


def _samples(dof, domain, seed):
    """Fresh states from ``domain`` (a :class:`~bench.physics.system.Domain`, or None for U(-pi/2, pi/2))."""
    g = np.random.default_rng(seed)
    if domain is None:
        return [torch.from_numpy(g.uniform(-np.pi / 2, np.pi / 2, size=(2000, dof))) for _ in range(3)]
    return [torch.from_numpy(g.uniform(*domain.bounds(k, dof), size=(2000, dof))) for k in ("q", "qd", "qdd")]


def _best_scale(L_hat, L_true, dof, domain, seed) -> sympy.Float:
    q, qd, qdd = _samples(dof, domain, seed)
    a = euler_lagrange(symbolic.to_torch(L_hat, dof), q, qd, qdd).numpy().ravel()
    b = euler_lagrange(symbolic.to_torch(L_true, dof), q, qd, qdd).numpy().ravel()
    denom = float(a @ a)
    return sympy.Float(float(a @ b) / denom if denom > 0 else 1.0)


def _numerically_equal(L_hat, L_true, dof, experiment, tolerance, domain, seed) -> bool:
    q, qd, qdd = _samples(dof, domain, seed)
    f_hat, f_true = symbolic.to_torch(L_hat, dof), symbolic.to_torch(L_true, dof)
    if not experiment.learns_torque:
        d = (f_hat(q, qd) - f_true(q, qd)).numpy()
        d = d - d.mean()
        ref = f_true(q, qd).numpy()
    else:
        d = (euler_lagrange(f_hat, q, qd, qdd) - euler_lagrange(f_true, q, qd, qdd)).numpy()
        ref = euler_lagrange(f_true, q, qd, qdd).numpy()
    scale = float(np.sqrt(np.mean(ref * ref))) or 1.0
    return bool(np.sqrt(np.mean(d * d)) <= 10 * tolerance * scale)
