"""The residual loop: find what a fitted model lacks, add it, refit, repeat.

Round 0 fits; each later round traces, adds, refits and keeps or undoes:

1. **Fit** (round 0 only). The method is fitted on the training torques (indirect
   experiment) with the system's declared model only. A parametric model's
   parameters (:meth:`~bench.core.models.FittedModel.parametric`) are then
   polished by nonlinear least squares (from the method's parameters and 16
   random starts, each on a subsample, the best then on all the samples), so
   that an optimiser's shortfall is not taken for a physical effect;
   ``mse_before`` is the polished model's, and round 0 records the method's
   own.
2. **Residual.** ``r = tau - g(L_hat) - Phi c`` on the training and test sets.
3. **Trace.** Forward stepwise selection (:mod:`bench.residual.selection`)
   over the candidates of :mod:`bench.residual.candidates`: the named
   effects on every joint, those of the whole system (a payload, a gravity
   tilt) and an open-ended library of terms of ``L`` and ``D``.
   The named effects are tried first at each step. Candidates are judged
   beside the model's own freedom: a symbolic model's terms, or a parametric
   model's parameter directions (its Jacobian), are refitted with them, so a
   candidate the model could already express gains nothing.
4. **Add** the accepted effects: conservative ones to the Lagrangian
   (armature ``+c qd^2/2``, spring ``-c q^2/2``, open-ended ``L`` terms),
   dissipative ones through the Rayleigh function ``D`` (torque ``dD/dqd``:
   viscous friction ``c qd^2/2``, Coulomb and Stribeck friction, drag), an
   offset as a generalized force.
5. **Refit jointly**, without fitting the method again. A parametric model
   (SysId: the system's declared form with unknown physical parameters) is
   refitted with the effects by nonlinear least squares over parameters and
   coefficients together, which keeps the form's constraints (an armature
   cannot hide in a mass); a linear form's base parameters and a symbolic
   model's terms (``g`` is linear in ``L``) are refitted with the effects by
   linear least squares. A neural model, or a symbolic one of more than
   :data:`MAX_SYMBOLIC_TERMS` terms (SyReNets' full equation, which is never
   expanded: :func:`_small` looks at its size first), keeps its fit: only
   the effects are fitted, to what it leaves. Its own terms therefore cannot
   grow to absorb noise in the refit. What such a fit leaves on the samples
   it was fitted on flatters it, so it is also cross-fitted
   (:func:`_cross_fit`: the method fitted on each half of the recordings
   predicts the other half), to check rounds by (step 6). Effects made redundant by the refit
   are dropped again (backward elimination on the BIC).
6. **Keep the round only if it generalises.** The round's model is scored by
   cross-validation over whole recordings (:mod:`bench.residual.validation`:
   leave one recording out, or contiguous blocks where the training data
   name fewer than two); a round that does not lower that held-out error is
   undone and the loop ends, so the final model is never worse than the
   starting one on held-out recordings. For a kept fit (step 5) the
   effects must also lower, on each half, the error of the method fitted on
   the other half. Each round records the figure (``heldout_mse``). A round after which the mass matrix ``d^2 L / dqd^2``
   of the model with its effects is no longer positive definite at the
   training states (:data:`MASS_STATES` of them) is undone too; a fitted
   model whose own mass matrix is not is reported as such.
7. **Repeat** until a round accepts nothing, for at most :data:`MAX_ROUNDS`
   rounds.

``budget_s`` bounds the whole loop (under a work budget, ``steps``, nothing
below depends on time: see :func:`residual_loop`): the method's fit has
:data:`FIT_SHARE` of it, each cross-fit of a kept fit :data:`CROSS_FIT_SHARE`, the polish stops starting new starts at
:data:`POLISH_SHARE`, a round starts only if the time it is expected to
take (the longest round so far) still fits in the budget, and tracing starts
no new step after :data:`TRACE_SHARE` of it.

:func:`residual_loop` runs the loop in this process and returns a
:class:`ResidualResult`; :func:`run_residual` runs a :class:`ResidualJob`
through the runner, in its own process, killed at 1.5 x its budget.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import sympy

from bench.core.budget import Budget
from bench.core.data import Dataset, mse
from bench.core.effects import EFFECTS
from bench.core.errors import UserError
from bench.core.models import ExpressionModel, FittedModel, LinearParametricModel, ParametricModel, mass_and_bias
from bench.core.regression import fit_statistics
from bench.core.terms import Term, TermLibrary, remembered_columns
from bench.residual.candidates import admissible, candidates, describe_all, is_named, label, structural
from bench.residual.report import write_outputs
from bench.residual.result import ResidualResult
from bench.residual.selection import BUDGET_STOP, MIN_BIC_DROP, ROUNDOFF, best_shape, bic, trace
from bench.residual.validation import cv_mse, folds, row_folds
from bench.residual.validation import describe as describe_validation
from bench.runner.execute import given_data
from bench.runner.isolation import Call, CallFailed, run_call
from bench.runner.matrix import KILL_FACTOR
from bench.runner.plugins import import_plugins
from bench.runner.progress import Report, print_now
from bench.runner.provenance import provenance
from methods import METHODS
from systems import SYSTEMS

MAX_ROUNDS = 6
#: seconds for the whole loop where no budget is given
DEFAULT_BUDGET_S = 60.0
#: a symbolic model with more terms than this is refitted like a neural one
#: (a least-squares refit of thousands of terms is neither fast nor meaningful)
MAX_SYMBOLIC_TERMS = 200
#: an expression with more nodes than this is not expanded into terms at all
MAX_SYMBOLIC_NODES = 50 * MAX_SYMBOLIC_TERMS
#: random starts of the parametric polish, beside the method's own parameters
POLISH_STARTS = 16
#: training samples each start of the polish is fitted on (the best start is
#: then refined on all of them)
POLISH_SAMPLES = 256
#: the share of the loop's budget its method's fit has
FIT_SHARE = 0.5
#: the polish starts no new start after this share of the loop's budget
POLISH_SHARE = 0.75
#: tracing starts no new step after this share of the loop's budget (the joint
#: refit, pruning and the held-out check follow)
TRACE_SHARE = 0.85
#: the share of the loop's budget each of the two cross-fits of a kept fit has
#: (see :func:`_cross_fit`)
CROSS_FIT_SHARE = 0.15


#: the last rigid-model torques computed, ``(rigid, data, tau)`` (see :func:`_rigid_torque`)
_TORQUES: list[tuple] = []


def _rigid_torque(rigid: FittedModel, data: Dataset) -> np.ndarray:
    """``rigid.predict_torque(data)`` as float64, remembered for the last few
    ``(rigid, data)`` pairs: the loop asks for a model's torque on the
    training data in every refit and pruning step, and a neural model's costs
    a pass of automatic differentiation. Pairs are matched by identity."""
    for r, d, tau in _TORQUES:
        if r is rigid and d is data:
            return tau
    tau = np.asarray(rigid.predict_torque(data), dtype=np.float64)
    _TORQUES.insert(0, (rigid, data, tau))
    del _TORQUES[4:]
    return tau


class CrossFitted(FittedModel):
    """A kept fit (:func:`_keeps_its_fit`) with the cross-fits' torque on the
    training data (:func:`_cross_fit`): ``torque[halves[k]]`` is predicted by
    the method fitted without ``halves[k]``. It predicts as the fit on all of it."""

    def __init__(self, fit: FittedModel, halves: list[np.ndarray], torque: np.ndarray):
        self.fit, self.halves, self.torque = fit, halves, torque

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        return self.fit.predict_lagrangian(data)

    def predict_torque(self, data: Dataset) -> np.ndarray:
        return self.fit.predict_torque(data)

    def expression(self):
        return self.fit.expression()

    def expression_terms_bound(self) -> int | None:
        return self.fit.expression_terms_bound()

    def readable_expression(self):
        return self.fit.readable_expression()


class LoopModel(FittedModel):
    """``tau_hat = g(L_hat) + Phi c``: a fitted Lagrangian plus accepted effects."""

    def __init__(self, rigid: FittedModel, effects: list[Term], coef, stderr):
        self.rigid, self.effects = rigid, list(effects)
        self.coef, self.stderr = np.asarray(coef, dtype=np.float64), np.asarray(stderr, dtype=np.float64)

    def columns(self, data: Dataset) -> np.ndarray:
        return TermLibrary(self.effects).design(data, "indirect")

    def predict_torque(self, data: Dataset) -> np.ndarray:
        tau = _rigid_torque(self.rigid, data)
        if self.effects:
            tau = tau + (self.columns(data) @ self.coef).reshape(tau.shape)
        return tau

    def predict_lagrangian(self, data: Dataset) -> np.ndarray:
        """The rigid model's ``L`` plus the conservative effects' terms."""
        L = np.asarray(self.rigid.predict_lagrangian(data), dtype=np.float64)
        return L + sum((c * t.value(data) for c, t in zip(self.coef, self.effects)), np.zeros(len(data)))

    def expression(self):
        return self.rigid.expression()


@dataclass(frozen=True)
class _Fitter:
    """How the loop fits its method."""

    method: str
    seed: int
    budget: Budget
    hyperparameters: dict

    def fit(self, train: Dataset) -> FittedModel:
        return METHODS[self.method](**self.hyperparameters).fit(train, "indirect", self.seed, self.budget)


def _nonlinear_fit(rigid: ParametricModel, train: Dataset, effects: list[Term], coef0) -> LoopModel:
    """Parameters and effects' coefficients together, by nonlinear least squares
    (trust-region reflective, analytic effect columns, differenced parameter columns)."""
    from scipy.optimize import least_squares  # 0.7 s to import: only parametric models need it

    Phi = TermLibrary(effects).design(train, "indirect")
    y = train.tau.ravel()
    p = len(rigid.theta)

    def residual(x):
        return rigid.with_parameters(x[:p]).predict_torque(train).ravel() + Phi @ x[p:] - y

    def jac(x):
        return np.hstack([rigid.with_parameters(x[:p]).jacobian(train), Phi])

    x0 = np.concatenate([rigid.theta, np.asarray(coef0, dtype=np.float64)])
    sol = least_squares(residual, x0, jac=jac, method="trf", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    J = sol.jac
    rss = float(sol.fun @ sol.fun)
    cov = np.linalg.pinv(J.T @ J) * (rss / max(len(y) - len(sol.x), 1))
    stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    return LoopModel(rigid.with_parameters(sol.x[:p]), effects, sol.x[p:], stderr[p:])


def _polish(rigid: ParametricModel, train: Dataset, seed: int, deadline: float = math.inf) -> LoopModel:
    """Nonlinear least squares from the method's parameters and from
    :data:`POLISH_STARTS` log-uniform starts in [0.01, 10], each fitted on
    :data:`POLISH_SAMPLES` random training samples; the best of them is then
    refitted on all of ``train``. No start begins after ``deadline``
    (``time.perf_counter()``) but the first; the final refit always runs.

    Screening the starts on a subsample makes each about ``len(train) /
    POLISH_SAMPLES`` times cheaper. Fitted on all the samples, a start from
    an optimiser's poor parameters (negative masses, say) could take the
    whole polish's time on its own and leave the random starts, which find
    the optimum, no time; then the loop took the optimiser's shortfall for
    effects."""
    rng = np.random.default_rng([seed, 0x706F6C])
    starts = [rigid.theta] + [10 ** rng.uniform(-2, 1, len(rigid.theta)) for _ in range(POLISH_STARTS)]
    screen = train
    if len(train) > 2 * POLISH_SAMPLES:
        screen = train.subset(np.sort(rng.choice(len(train), POLISH_SAMPLES, replace=False)))
    best = _best_fit(rigid, starts, screen, deadline)
    if best is None:
        return LoopModel(rigid, [], np.zeros(0), np.zeros(0))
    if screen is train:
        return best
    refined = _best_fit(rigid, [best.rigid.theta], train)
    return best if refined is None else refined


def _best_fit(rigid: ParametricModel, starts: list, data: Dataset, deadline: float = math.inf) -> LoopModel | None:
    """The lowest-RSS nonlinear fit of ``rigid`` on ``data`` from ``starts``
    (``None`` if no start gave a finite one); no start but the first begins after ``deadline``."""
    best, best_rss = None, math.inf
    for i, theta in enumerate(starts):
        if i and time.perf_counter() > deadline:
            break
        try:
            fit = _nonlinear_fit(rigid.with_parameters(theta), data, [], [])
        except (ValueError, np.linalg.LinAlgError):  # a start where the form is not finite
            continue
        r = fit.predict_torque(data) - data.tau
        rss = float(np.sum(r * r))
        if math.isfinite(rss) and rss < best_rss:
            best, best_rss = fit, rss
    return best


def _small(expr: sympy.Expr) -> bool:
    """Whether ``expr`` has at most :data:`MAX_SYMBOLIC_NODES` nodes, found
    without expanding it (counting stops at the limit)."""
    for i, _ in enumerate(sympy.preorder_traversal(expr)):
        if i >= MAX_SYMBOLIC_NODES:
            return False
    return True


@functools.lru_cache(maxsize=16)
def _terms(expr: sympy.Expr) -> tuple[sympy.Expr, ...] | None:
    """The coefficient-free terms of an expanded expression that act on the
    torque; ``None`` for an expression too large to expand (:func:`_small`)
    or with more than :data:`MAX_SYMBOLIC_TERMS` terms."""
    if not _small(expr):
        return None
    out = []
    for term in sympy.Add.make_args(sympy.expand(expr)):
        _, rest = term.as_coeff_Mul()
        if rest.free_symbols and rest not in out:
            out.append(rest)
    return tuple(out) if len(out) <= MAX_SYMBOLIC_TERMS else None


def _lagrangian_columns(rigid: FittedModel, data: Dataset) -> tuple[list[sympy.Expr], np.ndarray] | None:
    """The symbolic model's terms and their torque columns; ``None`` for a
    model without an expression or with more than :data:`MAX_SYMBOLIC_TERMS` terms."""
    if not _expression_small(rigid):
        return None
    expr = rigid.expression()
    basis = None if expr is None else _terms(expr)
    if basis is None:
        return None
    return list(basis), TermLibrary.of_lagrangian(basis).design(data, "indirect")


def _refit(model: LoopModel, train: Dataset, effects: list[Term]) -> LoopModel:
    """The model's own freedom and the effects together (see step 5 of the
    module docstring); the method is not fitted again."""
    y = train.tau.ravel()
    Phi = TermLibrary(effects).design(train, "indirect")
    coef = fit_statistics(Phi, y - np.ravel(_rigid_torque(model.rigid, train)))[0]
    if isinstance(model.rigid, ParametricModel):
        return _nonlinear_fit(model.rigid, train, effects, coef)
    if isinstance(model.rigid, LinearParametricModel):  # its base parameters and the effects, by least squares
        F_L = model.rigid.torque_columns(train)
        coef, stderr, _ = fit_statistics(np.hstack([F_L, Phi]), y)
        k = F_L.shape[1]
        return LoopModel(model.rigid.with_coefficients(coef[:k]), effects, coef[k:], stderr[k:])
    rigid = model.rigid
    lagrangian = _lagrangian_columns(rigid, train)
    if lagrangian is None:
        coef, stderr, _ = fit_statistics(Phi, y - np.ravel(_rigid_torque(rigid, train)))
        return LoopModel(rigid, effects, coef, stderr)
    basis, F_L = lagrangian
    coef, stderr, _ = fit_statistics(np.hstack([F_L, Phi]), y)
    k = len(basis)
    expr = sympy.Add(*[sympy.Float(a) * b for a, b in zip(coef[:k], basis)])
    return LoopModel(ExpressionModel(expr, train.dof), effects, coef[k:], stderr[k:])


def _freedom(model: LoopModel, train: Dataset) -> np.ndarray:
    """Columns for what the model can already express: a parametric model's
    parameter directions, a linear form's base columns, a symbolic model's
    terms, nothing for a neural one."""
    if isinstance(model.rigid, ParametricModel):
        return model.rigid.jacobian(train)
    if isinstance(model.rigid, LinearParametricModel):
        return model.rigid.torque_columns(train)
    lagrangian = _lagrangian_columns(model.rigid, train)
    return np.zeros((train.tau.size, 0)) if lagrangian is None else lagrangian[1]


def _is_symbolic(rigid: FittedModel) -> bool:
    """A model whose columns :func:`_freedom` refits linearly and span its own
    torque: an expression's terms or a linear form's base columns (not a
    nonlinear parametric one)."""
    if isinstance(rigid, LinearParametricModel):
        return True
    if isinstance(rigid, ParametricModel):
        return False
    if not _expression_small(rigid):
        return False
    expr = rigid.expression()
    return expr is not None and _terms(expr) is not None


def _expression_small(rigid: FittedModel) -> bool:
    """Whether the model's expression may be built at all: not where it says
    its terms exceed :data:`MAX_SYMBOLIC_TERMS` (SyReNets' full equation)."""
    bound = rigid.expression_terms_bound()
    return bound is None or bound <= MAX_SYMBOLIC_TERMS


def _fit_problem(model: LoopModel, train: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """What tracing and pruning fit: the target (``(n, dof)``) and the columns
    always in the fit, the model's freedom (:func:`_freedom`) then the accepted
    effects. A symbolic model's terms span its own torque, so the target is the
    torque itself; otherwise it is what the rigid model leaves."""
    target = train.tau if _is_symbolic(model.rigid) else train.tau - _rigid_torque(model.rigid, train)
    return target, np.hstack([_freedom(model, train), model.columns(train)])


def _prune(model: LoopModel, train: Dataset, report: Report) -> tuple[LoopModel, list[str]]:
    """Backward elimination after a joint refit: drop an effect whose removal
    raises the BIC by less than :data:`MIN_BIC_DROP` (it became redundant with
    the refitted model), then refit; repeat until every effect holds."""
    removed = []
    while model.effects:
        target, F = _fit_problem(model, train)
        y = target.ravel()
        n, k = len(y), F.shape[1]
        first = k - len(model.effects)  # the effects' columns come last
        # residual sums below round-off are equal: their ratios are floating-point noise
        floor = ROUNDOFF * float(np.mean(train.tau**2)) * n
        rss_all = max(fit_statistics(F, y)[2], floor)
        weakest, weakest_gain = None, math.inf
        for i in range(len(model.effects)):
            rss_without = max(fit_statistics(np.delete(F, first + i, axis=1), y)[2], floor)
            gain = bic(rss_without, n, k - 1) - bic(rss_all, n, k)
            if gain < weakest_gain:
                weakest, weakest_gain = i, gain
        if weakest_gain >= MIN_BIC_DROP:
            break
        gone = model.effects[weakest]
        removed.append(label(gone))
        report(f"  dropping {label(gone)}: redundant after the joint refit (BIC gain {weakest_gain:.3g})")
        model = _refit(model, train, model.effects[:weakest] + model.effects[weakest + 1:])
    return model, removed


def _shape_rss(model: LoopModel, train: Dataset, index: int):
    """``rss(v)``: the residual sum of squares of the linear problem
    (:func:`_fit_problem`) with effect ``index``'s nonlinear parameter at ``v``."""
    target, F = _fit_problem(model, train)
    y = target.ravel()
    column = F.shape[1] - len(model.effects) + index
    term = model.effects[index]

    def rss(v: float) -> float:
        F[:, column] = EFFECTS[term.name].numeric_torque(train, term.joint, v).ravel()
        return fit_statistics(F, y)[2]

    return rss, len(y), F.shape[1]


def _refine_shapes(model: LoopModel, train: Dataset, report: Report) -> LoopModel:
    """Each shaped effect's nonlinear parameter (a Stribeck velocity) by a
    bounded scalar search of the residual sum of squares, the linear
    coefficients refitted at each value (variable projection), near where it
    stands (:func:`~bench.residual.selection.best_shape`); then a joint refit."""
    for i, term in enumerate(model.effects):
        if term.shape is None:
            continue
        v = best_shape(_shape_rss(model, train, i)[0], term.shape)
        refined = EFFECTS[term.name].term(term.joint, shape=v)
        report(f"  {label(term)}: {EFFECTS[term.name].shaped} refined to {v:.5g}")
        model = _refit(model, train, model.effects[:i] + [refined] + model.effects[i + 1:])
    return model


def _shape_stderr(model: LoopModel, train: Dataset) -> dict[Term, float]:
    """The standard error of each shaped effect's parameter, from the
    curvature of the residual sum of squares: ``sqrt(2 sigma^2 / rss''(v))``."""
    out = {}
    for i, term in enumerate(model.effects):
        if term.shape is None:
            continue
        rss, n, k = _shape_rss(model, train, i)
        v, h = term.shape, 1e-3 * term.shape
        r0 = rss(v)
        curvature = (rss(v + h) - 2 * r0 + rss(v - h)) / h**2
        sigma2 = r0 / max(n - k - 1, 1)
        out[term] = math.sqrt(2 * sigma2 / curvature) if curvature > 0 else float("inf")
    return out


def _drop_inadmissible(model: LoopModel, train: Dataset, report: Report) -> tuple[LoopModel, list[tuple]]:
    """Drop effects whose coefficient the joint refit made impossible (a
    negative friction, say), one at a time, refitting after each; returns
    the model and the dropped ``(term, coefficient, stderr)``."""
    dropped = []
    while True:
        bad = [i for i, (t, c) in enumerate(zip(model.effects, model.coef)) if not admissible(t, c)]
        if not bad:
            return model, dropped
        i = bad[0]
        dropped.append((model.effects[i], float(model.coef[i]), float(model.stderr[i])))
        report(f"  dropping {label(model.effects[i])}: the joint refit gives it an impossible coefficient {model.coef[i]:.4g}")
        model = _refit(model, train, model.effects[:i] + model.effects[i + 1:])


def _heldout(model: LoopModel, train: Dataset) -> float:
    """The model's torque MSE on held-out data: the linear problem that
    tracing and pruning fit (:func:`_fit_problem`), cross-validated over whole
    recordings (:func:`bench.residual.validation.cv_mse`)."""
    target, F = _fit_problem(model, train)
    return cv_mse(F, target.ravel(), row_folds(train))


def _keeps_its_fit(rigid: FittedModel) -> bool:
    """A model the loop does not refit (a neural one, or SyReNets' full
    equation): only the effects are fitted to what it leaves."""
    return not isinstance(rigid, ParametricModel) and not _is_symbolic(rigid)


def _cross_fit(fitter: "_Fitter", fit: FittedModel, train: Dataset, report: Report) -> tuple[CrossFitted, dict]:
    """A kept fit (:func:`_keeps_its_fit`) with cross-fits to check it by.

    The fit saw every training sample, so what it leaves on them is smaller
    than, and unlike, what it leaves on a recording it has not seen: an
    effect can fit that residual, on every recording, and still not help on
    a new one. The validation folds (:func:`bench.residual.validation.folds`:
    the recordings, or contiguous blocks) are dealt alternately into two
    halves; the method is fitted on each half, with :data:`CROSS_FIT_SHARE`
    of the loop's budget, and predicts the other (:func:`_cross_fitted_mse`).

    The effects are still fitted to what the fit on all the training data
    leaves, because that fit is what the loop keeps: on the DFKI recordings,
    an MLP fitted on half of them (two or three recordings) leaves 1.1 to 3.6
    times (median 2.3) the error on the other half that the MLP fitted on
    all of them leaves on the test recordings, and SyReNets up to 88 times,
    so effects fitted to the cross-fits' residual would mend their
    shortfall, not the kept fit's (fitted so, the MLP ended 1.19 times worse
    on the suite's test recordings).
    """
    t0 = time.perf_counter()
    fold_masks = folds(train)
    halves = [np.any(fold_masks[k::2], axis=0) for k in (0, 1)]
    torque = np.empty_like(train.tau)
    for held in halves:
        other = fitter.fit(train.subset(np.flatnonzero(~held)))
        torque[held] = np.asarray(other.predict_torque(train.subset(np.flatnonzero(held))), dtype=np.float64)
    info = {"in_sample_mse": mse(_rigid_torque(fit, train), train.tau), "out_of_fold_mse": mse(torque, train.tau),
            "fit_budget_s": fitter.budget.seconds if fitter.budget.steps is None else None,
            "fit_budget": fitter.budget.to_json(), "seconds": round(time.perf_counter() - t0, 3)}
    report(f"round 0: {fitter.method} cross-fitted on two halves of the training data ({fitter.budget.describe()} each): "
           f"torque MSE {info['out_of_fold_mse']:.4g} on the half it did not see, "
           f"{info['in_sample_mse']:.4g} for the fit on all of it")
    return CrossFitted(fit, halves, torque), info


def _cross_fitted_mse(model: LoopModel, train: Dataset) -> np.ndarray:
    """For each half of a :class:`CrossFitted` model's training data, the
    torque MSE of the method fitted on the other half plus the model's
    effects (their coefficients as fitted)."""
    cross = model.rigid
    tau = cross.torque + (model.columns(train) @ model.coef).reshape(cross.torque.shape) if model.effects else cross.torque
    return np.asarray([mse(tau[held], train.tau[held]) for held in cross.halves])


#: training states the mass matrix is checked at
MASS_STATES = 256


def _smallest_mass_eigenvalue(model: FittedModel, train: Dataset) -> float:
    """The smallest eigenvalue of the model's mass matrix ``d^2 L / dqd^2``
    (with its effects) over up to :data:`MASS_STATES` training states, evenly spread."""
    rows = np.unique(np.linspace(0, len(train) - 1, min(MASS_STATES, len(train))).astype(int))
    states = train.subset(rows)
    M, _ = mass_and_bias(model, states.q, states.qd)
    return float(np.linalg.eigvalsh(0.5 * (M + np.transpose(M, (0, 2, 1))))[:, 0].min())


def residual_loop(method: str, train: Dataset, test: Dataset | None, *, budget_s: float | None = None,
                  steps: int | None = None, seed: int = 0, hyperparameters: dict | None = None, report: Report = print,
                  fitted: FittedModel | None = None, open_ended: bool | None = None) -> ResidualResult:
    """Run the loop in this process; see the module docstring.

    ``budget_s`` bounds the whole loop (its method's fit has
    :data:`FIT_SHARE` of it; default :data:`DEFAULT_BUDGET_S`). With
    ``steps`` the loop is bounded by work instead, and ``budget_s`` is
    only recorded, as the ceiling its caller kills it at: the fit
    and each cross-fit do ``steps`` steps of the method's work, the polish
    all its starts, the trace until nothing is significant, and at most
    :data:`MAX_ROUNDS` rounds run, so that the result does not depend on
    the machine's speed. ``fitted`` is an already fitted instance of
    ``method`` to start from instead of round 0's fit (for instance a model
    fitted before the system changed). Each round records ``seconds``, the
    time since the loop began.
    """
    with remembered_columns(train, test):  # each candidate's and effect's columns once, for every round
        return _residual_loop(method, train, test, budget_s=budget_s, steps=steps, seed=seed,
                              hyperparameters=hyperparameters, report=report, fitted=fitted, open_ended=open_ended)


def _residual_loop(method, train, test, *, budget_s, steps, seed, hyperparameters, report, fitted, open_ended):
    if budget_s is None and steps is None:
        budget_s = DEFAULT_BUDGET_S
    budget = Budget(seconds=budget_s, steps=steps)
    horizon = budget.fit_seconds  # the loop's time (unlimited under a work budget)
    fit_budget = budget.scaled(FIT_SHARE)
    fitter = _Fitter(method, seed, fit_budget, dict(hyperparameters or {}))
    start = time.perf_counter()
    given = fitted is not None  # a given fit was made on other data: what it leaves here is out of sample
    if fitted is None:
        share = "" if steps else f" of the loop's {budget_s:g} s"
        report(f"round 0: fitting {method} on {len(train)} samples with the declared model only "
               f"({fit_budget.describe()}{share})")
        fitted = fitter.fit(train)
    else:
        report(f"round 0: starting from the given {method} fit")

    def scores(m):
        return {"train": mse(m.predict_torque(train), train.tau),
                "test": None if test is None else mse(m.predict_torque(test), test.tau)}

    model = LoopModel(fitted, [], np.zeros(0), np.zeros(0))
    round0 = {"round": 0, "accepted": [], "trace": []}
    parametric = fitted.parametric()
    if isinstance(parametric, LinearParametricModel):  # least squares already reached its optimum
        model = LoopModel(parametric, [], np.zeros(0), np.zeros(0))
    elif parametric is None and not given and _keeps_its_fit(fitted):
        cross, round0["cross_fit"] = _cross_fit(dataclasses.replace(fitter, budget=budget.scaled(CROSS_FIT_SHARE)),
                                                fitted, train, report)
        model = LoopModel(cross, [], np.zeros(0), np.zeros(0))
    elif parametric is not None:
        # polish the parameters, so that an optimiser's shortfall is not taken for an effect
        round0["method_mse"] = scores(model)
        model = _polish(parametric, train, seed, deadline=start + POLISH_SHARE * horizon)
        report(f"round 0: {method}'s parameters polished by nonlinear least squares "
               f"(train MSE {round0['method_mse']['train']:.4g} -> {scores(model)['train']:.4g})")
    first = model
    before = scores(model)
    statistics = 0.0  # seconds in selection, pruning and the held-out and mass-matrix checks

    def timed(fn, *args, **kwargs):
        nonlocal statistics
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            statistics += time.perf_counter() - t0

    heldout = timed(_heldout, model, train)
    mass = timed(_smallest_mass_eigenvalue, model, train)
    mass_before = mass
    if not mass > 0:
        report(f"round 0: {method}'s mass matrix is not positive definite on the training data "
               f"(smallest eigenvalue {mass:.4g}): a finding about the fitted model")
    round0["mse"] = before
    round0["heldout_mse"] = heldout
    round0["seconds"] = round(time.perf_counter() - start, 3)
    rounds = [round0]
    findings: dict[str, dict] = {}  # structural findings, by the term's label
    system = SYSTEMS[train.system]() if train.system in SYSTEMS else None
    pool = candidates(train.dof, coupled=bool(getattr(system, "absolute_angles", False)), system=system)
    if open_ended is False:
        pool = TermLibrary([t for t in pool if is_named(t)])
    split = describe_validation(train)
    report(f"round 0: torque MSE train {before['train']:.4g}, test {_fmt(before['test'])}; "
           f"held out ({split}) {heldout:.4g}")
    longest = 0.0  # the longest round so far
    for k in range(1, MAX_ROUNDS + 1):
        began = time.perf_counter()
        if began - start + longest >= horizon:
            rounds.append({"round": k, "mse": scores(model), "heldout_mse": heldout, "accepted": [], "trace": [],
                           "stop": f"the budget of {budget_s:g} s would be spent before a round ended",
                           "seconds": round(time.perf_counter() - start, 3)})
            report(f"round {k}: not started, the budget of {budget_s:g} s would be spent before it ended")
            break
        target, fixed = _fit_problem(model, train)
        # a nonlinear model's columns are its parameters' directions where it stands: one step a
        # round, then the joint refit moves it, so a large step is not followed by terms that
        # only mend the linearisation
        steps = 1 if isinstance(model.rigid, ParametricModel) else None
        selection = timed(trace, target, train, pool, fixed, exclude=model.effects, max_steps=steps,
                          deadline=start + TRACE_SHARE * horizon)
        findings = {}  # what is left unexplained where the loop ends
        for term, c, se in selection.structural:
            findings[label(term)] = structural(term, c, se)
            report(f"round {k}: structural finding: {findings[label(term)]['finding']}")
        if not selection.accepted:
            rounds.append({"round": k, "mse": scores(model), "heldout_mse": heldout, "accepted": [],
                           "trace": selection.steps, "seconds": round(time.perf_counter() - start, 3)})
            if any(step.get("stop") == BUDGET_STOP for step in selection.steps):
                report(f"round {k}: the loop's budget ran out before the trace found anything significant; "
                       f"a larger budget may find more")
            else:
                report(f"round {k}: nothing significant left")
            break
        effects = model.effects + selection.accepted
        report(f"round {k}: adding {', '.join(label(c) for c in selection.accepted)}; refitting jointly")
        candidate = _refit(model, train, effects)
        candidate, removed = timed(_prune, candidate, train, report)
        candidate = _refine_shapes(candidate, train, report)
        candidate, impossible = _drop_inadmissible(candidate, train, report)
        for term, c, se in impossible:
            findings[label(term)] = structural(term, c, se)
            removed.append(label(term))
        held = timed(_heldout, candidate, train)
        entry = {"round": k, "accepted": [label(c) for c in selection.accepted], "removed": removed,
                 "trace": selection.steps}
        candidate_mass = timed(_smallest_mass_eigenvalue, candidate, train)
        undo = None  # why the round is undone: the JSON's words, then the progress line's
        if mass > 0 and not candidate_mass > 0:
            undo = (f"with these effects the mass matrix is not positive definite on the training data "
                    f"(smallest eigenvalue {candidate_mass:.4g})",
                    f"the mass matrix would not be positive definite (smallest eigenvalue {candidate_mass:.4g})")
        elif not held < heldout:
            undo = ("the refitted model does not lower the held-out error",
                    f"held-out MSE {held:.4g} is not below {heldout:.4g}")
        elif isinstance(model.rigid, CrossFitted):
            # the kept fit saw every training sample; its cross-fits did not see the half they predict
            now, then = timed(_cross_fitted_mse, candidate, train), timed(_cross_fitted_mse, model, train)
            if not np.all(now < then):
                undo = (f"the effects do not lower the error of {method} fitted on one half of the training "
                        f"data on the other half, for each half ({_fmt(now)} against {_fmt(then)})",
                        f"the cross-fitted error ({_fmt(now)}) is not below {_fmt(then)} on each half")
        if undo is not None:
            rounds.append({**entry, "mse": scores(model), "heldout_mse": heldout, "candidate_heldout_mse": held,
                           "stop": f"undone: {undo[0]}", "seconds": round(time.perf_counter() - start, 3)})
            report(f"round {k}: undone, {undo[1]}")
            break
        model, heldout, mass = candidate, held, candidate_mass
        s = scores(model)
        rounds.append({**entry, "mse": s, "heldout_mse": held, "seconds": round(time.perf_counter() - start, 3)})
        longest = max(longest, time.perf_counter() - began)
        if not set(label(c) for c in selection.accepted) - set(removed):
            report(f"round {k}: every effect it added became redundant; stopping")
            break
        report(f"round {k}: torque MSE train {s['train']:.4g}, test {_fmt(s['test'])}, held out {held:.4g}")
    after = scores(model)
    expr = model.expression() if _expression_small(model.rigid) else None
    return ResidualResult(
        system=train.system, method=method, mse_before=before, mse_after=after,
        effects=describe_all(model.effects, model.coef, model.stderr, timed(_shape_stderr, model, train))
        + list(findings.values()),
        rounds=rounds, validation=split,
        mass_matrix={"smallest_eigenvalue_before": mass_before, "smallest_eigenvalue_after": mass,
                     "positive_definite": mass > 0, "states": min(MASS_STATES, len(train))},
        mse_heldout_recordings={"before": rounds[0]["heldout_mse"], "after": heldout} if len(train.recordings()) >= 2 else None,
        lagrangian=None if expr is None else str(expr),
        seconds=round(time.perf_counter() - start, 2), statistics_seconds=round(statistics, 2), budget_s=budget_s,
        fit_budget_s=fit_budget.seconds if steps is None else None, budget=budget.to_json(), seed=seed,
        train_source=train.source, test_source=None if test is None else test.source,
        provenance=provenance(), models=(first, model),
    )


def _fmt(x) -> str:
    if x is None:
        return "—"
    if np.ndim(x):
        return ", ".join(f"{v:.4g}" for v in x)
    return f"{x:.4g}"


# -- through the runner -----------------------------------------------------------------

@dataclass(frozen=True)
class ResidualJob:
    """One run of the loop, as the command line gives it.

    ``train_path`` / ``test_path`` are CSV files in the suite's format; a
    measured system without them uses its own splits. ``json_path`` and
    ``report_path`` are written by the loop's process, atomically.
    """

    system: str
    method: str
    train_path: str | None = None
    test_path: str | None = None
    budget_s: float | None = DEFAULT_BUDGET_S
    steps: int | None = None
    seed: int = 0
    hyperparameters: dict = field(default_factory=dict)
    json_path: str | None = None
    report_path: str | None = None
    plugins: tuple[str, ...] = ()

    def data(self) -> tuple[Dataset, Dataset | None]:
        data = given_data(SYSTEMS[self.system](), self.train_path, self.test_path)
        if data is None:
            raise UserError(f"{self.system} is simulated: give --train (and --test) CSV files, e.g. from python -m bench data")
        return data

    def run(self, report: Report = print_now) -> ResidualResult:
        """The loop in this process, with its outputs written."""
        import_plugins(self.plugins)
        train, test = self.data()
        result = residual_loop(self.method, train, test, budget_s=self.budget_s, steps=self.steps, seed=self.seed,
                               hyperparameters=self.hyperparameters, report=report)
        write_outputs(result, train, test, self.json_path, self.report_path)
        return result


def run_payload(payload: dict, on_phase: Callable[[str], None]) -> dict:
    """The entry point of the loop in its own process: ``payload`` is a
    :class:`ResidualJob` as a dict; returns the result's JSON, or the
    one-line ``user_error`` that bad input gave."""
    job = ResidualJob(**{**payload, "plugins": tuple(payload.get("plugins", ()))})
    on_phase("loop")
    try:
        return job.run(print_now).to_json()
    except UserError as exc:
        return {"user_error": str(exc)}


def run_residual(job: ResidualJob, report: Report = print_now) -> ResidualResult:
    """Run ``job`` in its own process, forked from the runner's fork server,
    showing its progress lines through ``report``; the process is killed at
    1.5 x the job's time budget, or at a work budget's ceiling. Bad input
    raises :class:`UserError` with the loop's one-line message."""
    if job.steps is None:
        limit, what = KILL_FACTOR * job.budget_s, f"{KILL_FACTOR} x its budget of {job.budget_s:g} s"
    else:
        limit, what = (math.inf, "") if job.budget_s is None else (job.budget_s, f"its ceiling of {job.budget_s:g} s")
    with tempfile.TemporaryDirectory(prefix="bench-residual-") as work:
        result_file = Path(work) / "result.json"
        call = Call("bench.residual.loop:run_payload", dataclasses.asdict(job))
        outcome = run_call(call, result_file, work, "residual", {"loop": limit}, echo=report)
    if outcome.killed:
        raise CallFailed(f"the residual loop was still running at {what}; killed")
    if outcome.result is None:
        raise CallFailed(f"the residual loop's process exited with code {outcome.exit_code}: {outcome.log_tail}")
    if "user_error" in outcome.result:
        raise UserError(outcome.result["user_error"])
    return ResidualResult.from_json(outcome.result)
