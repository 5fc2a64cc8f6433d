"""How the residual loop treats each kind of fitted model: one refit strategy per kind.

A fitted model declares its structure (:meth:`bench.physics.models.FittedModel.structure`),
and :func:`strategy_for` picks the strategy registered for it (:data:`STRATEGIES`,
:func:`refits`) once, at the start of the loop.
A strategy owns what differs between kinds of model:

* :meth:`Strategy.start`: what the loop's round 0 does with the fit (a
  parametric model's parameters are polished; a kept fit is cross-fitted);
* :meth:`Strategy.freedom`: the columns of what the model can already
  express, which every term is judged beside, so that one the model
  could express gains nothing;
* :meth:`Strategy.problem`: what tracing and pruning fit (the target and the
  columns always in the fit);
* :meth:`Strategy.refit`: the model's own freedom and the effects fitted
  together, without fitting the method again;
* :meth:`Strategy.check`: a strategy's own reason to undo a round.

=====================  ================================  ==================================================
strategy               models                            refit with effects
=====================  ================================  ==================================================
:class:`Parametric`    a form with nonlinear parameters  nonlinear least squares over the parameters and
                       (SysId on a pendulum)             the effects' coefficients together; its columns
                                                         are its parameters' directions where it stands
:class:`Linear`        linear in its parameters          least squares over its base columns and the
                       (SysId on an arm)                 effects' together
:class:`Feasible`      linear, held physically feasible  the same under each body's pseudo-inertia held
                       (SysId with ``feasible=true``)    positive semidefinite (a semidefinite program)
:class:`Expression`    a sum of at most                  least squares over its terms' and the effects'
                       :data:`MAX_SYMBOLIC_TERMS` terms  columns together (``g`` is linear in ``L``)
                       (sparse regression, GP)
:class:`KeptFit`       anything else (a network,         the effects only, fitted to what the fit
                       SyReNets' full equation)          leaves; cross-fitted (:func:`cross_fit`)
=====================  ================================  ==================================================
"""

from __future__ import annotations

import abc
import math
from typing import ClassVar

import numpy as np
import sympy

from bench.core.data import Dataset, mse
from bench.physics.models import ExpressionModel, FittedModel, ParametricModel
from bench.physics.feasible import feasibility_of, feasible_fit
from bench.physics.regression import Compressed, fit_statistics
from bench.core.symbolic import coordinate_symbols
from bench.physics.terms import Term, TermLibrary
from bench.residual.model import CrossFitted, Fitter, LoopModel, rigid_torque
from bench.residual.basis import orthonormal_basis
from bench.residual.expression_terms import MAX_SYMBOLIC_TERMS, expression_terms
from bench.core.folds import folds
from bench.core.budget import now
from bench.runner.progress import Report

#: random starts of the parametric polish, beside the method's own parameters
POLISH_STARTS = 16
#: training samples each start of the polish is fitted on (the best start is
#: then refined on all of them)
POLISH_SAMPLES = 256


#: the refit strategy of each structure a model declares (:meth:`~bench.physics.models.FittedModel.structure`);
#: a new kind of model declares a structure of its own and registers its strategy with :func:`refits`
STRATEGIES: dict[str, type["Strategy"]] = {}


def refits(structure: str):
    """Register the decorated strategy for the models that declare ``structure``."""

    def register(cls: type["Strategy"]) -> type["Strategy"]:
        if STRATEGIES.get(structure, cls) is not cls:
            raise ValueError(f"the structure {structure!r} already has a refit strategy, {STRATEGIES[structure].__name__}")
        STRATEGIES[structure] = cls
        return cls

    return register


class Strategy(abc.ABC):
    """How the loop refits one kind of model; see the module docstring."""

    #: the strategy's name, as the loop's JSON gives it
    name: ClassVar[str]

    @classmethod
    def of(cls, fitted: FittedModel) -> "Strategy | None":
        """The strategy for ``fitted``, or ``None`` where it cannot take it."""
        return cls()
    #: terms a trace step may accept (``None``: as many as pass)
    trace_steps: ClassVar[int | None] = None
    #: whether the model's own columns span its torque, so that tracing fits the torque itself
    spans_its_torque: ClassVar[bool] = False
    #: whether the model's own columns stay the same through its refits (those of a form linear
    #: in its parameters do; a parametric form's directions move with its parameters)
    fixed_freedom: ClassVar[bool] = True

    def start(self, fitted: FittedModel, train: Dataset, context: "Start") -> tuple[LoopModel, dict]:
        """Round 0: the loop's starting model, and what round 0 records of how it was made
        (``method_model``: the method's own model, where the start changed it)."""
        return LoopModel.bare(self.rigid_of(fitted)), {}

    def rigid_of(self, fitted: FittedModel) -> FittedModel:
        """The model the strategy refits: the parametric form a method gives, or the fit itself."""
        return fitted

    @abc.abstractmethod
    def freedom(self, model: LoopModel, train: Dataset) -> np.ndarray:
        """Columns for what the model can already express, ``(n * dof, k)``."""

    def freedom_basis(self, model: LoopModel, train: Dataset) -> np.ndarray:
        """An orthonormal basis of :meth:`freedom`'s columns; kept per data set
        where the freedom does not move with a refit (:attr:`fixed_freedom`)."""
        if not self.fixed_freedom:
            return orthonormal_basis(self.freedom(model, train))
        kept = getattr(self, "_kept_basis", None)  # (data, basis) of the last data set asked for
        if kept is None or kept[0] is not train:
            kept = self._kept_basis = (train, orthonormal_basis(self.freedom(model, train)))
        return kept[1]

    def problem(self, model: LoopModel, train: Dataset) -> tuple[np.ndarray, np.ndarray]:
        """What tracing and pruning fit: the target (``(n, dof)``) and the columns
        always in the fit, the model's freedom then the accepted effects. Where the
        model's columns span its own torque, the target is the torque itself;
        otherwise it is what the rigid model leaves."""
        target = train.tau if self.spans_its_torque else train.tau - rigid_torque(model.rigid, train)
        return target, np.hstack([self.freedom(model, train), model.columns(train)])

    @abc.abstractmethod
    def refit(self, model: LoopModel, train: Dataset, effects: list[Term]) -> LoopModel:
        """The model's own freedom and ``effects`` fitted together; the method is not fitted again."""

    def check(self, proposed: LoopModel, model: LoopModel, train: Dataset) -> tuple[str, str] | None:
        """A reason of the strategy's own to undo a round (the JSON's words, then the
        progress line's), or ``None``."""
        return None

    def feasibility(self, model: LoopModel, train: Dataset) -> dict | None:
        """Whether the model's inertial parameters are a rigid body's
        (:func:`bench.physics.feasible.feasibility_of`), for a model of rigid bodies; else ``None``."""
        return None

    def holds_out(self) -> str:
        """What the loop's held-out error holds out (the JSON's ``heldout_holds_out``):
        what is refitted without each held-out span or trajectory."""
        return "the model and its effects"

    def _effects_beside(self, model: LoopModel, train: Dataset, effects: list[Term]):
        """The effects' columns and their least-squares coefficients on what the rigid model leaves."""
        Phi = TermLibrary(effects).design(train, "indirect")
        return Phi, fit_statistics(Phi, train.tau.ravel() - np.ravel(rigid_torque(model.rigid, train)))


class Start:
    """What a strategy's round 0 may use: the loop's seed, fitter, budgets and report."""

    def __init__(self, seed: int, fitter: Fitter, cross_fitter: Fitter, given: bool, polish_deadline: float,
                 report: Report):
        self.seed, self.fitter, self.cross_fitter, self.given = seed, fitter, cross_fitter, given
        self.polish_deadline, self.report = polish_deadline, report


@refits("parametric")
class Parametric(Strategy):
    """A form with nonlinear parameters (:class:`~bench.physics.models.ParametricModel`)."""

    name = "parametric"
    fixed_freedom = False
    # its columns are its parameters' directions where it stands: one step a round, then the
    # joint refit moves it, so that a large step is not followed by terms that only mend the
    # linearisation
    trace_steps = 1

    def rigid_of(self, fitted):
        return fitted.parametric()

    def start(self, fitted, train, context):
        rigid = self.rigid_of(fitted)
        method = LoopModel.bare(rigid)
        polished = polish(rigid, train, context.seed, deadline=context.polish_deadline)
        before, after = mse(method.predict_torque(train), train.tau), mse(polished.predict_torque(train), train.tau)
        context.report(f"round 0: {context.fitter.method}'s parameters polished by nonlinear least squares "
                       f"(train MSE {before:.4g} -> {after:.4g})")
        return polished, {"method_model": method}

    def freedom(self, model, train):
        return model.rigid.jacobian(train)

    def refit(self, model, train, effects):
        _, (coef, _, _) = self._effects_beside(model, train, effects)
        return nonlinear_fit(model.rigid, train, effects, coef)


@refits("linear")
class Linear(Strategy):
    """A model linear in its parameters (:class:`~bench.physics.linear.LinearParametricModel`):
    least squares has reached its optimum already, so round 0 keeps it."""

    name = "linear"
    spans_its_torque = True

    def rigid_of(self, fitted):
        return fitted.parametric()

    def freedom(self, model, train):
        return model.rigid.torque_columns(train)

    def refit(self, model, train, effects):
        Phi = TermLibrary(effects).design(train, "indirect")
        F_L = model.rigid.torque_columns(train)
        coef, stderr, _ = fit_statistics(np.hstack([F_L, Phi]), train.tau.ravel())
        k = F_L.shape[1]
        return LoopModel(model.rigid.with_coefficients(coef[:k]), effects, coef[k:], stderr[k:])

    def feasibility(self, model, train):
        return feasibility_of(model.rigid, train)


@refits("feasible")
class Feasible(Linear):
    """A model linear in its parameters held physically feasible
    (:class:`~bench.physics.linear.FeasibleSet`): refitted with the effects
    under the same constraints (:func:`bench.physics.feasible.feasible_fit`),
    so that the effects are not judged beside a rigid model no rigid body
    has. Tracing, pruning and the held-out checks judge terms by
    unconstrained least squares, as for :class:`Linear`; the effects'
    standard errors are least squares' too."""

    name = "feasible"

    def refit(self, model, train, effects):
        Phi = TermLibrary(effects).design(train, "indirect")
        F_L = model.rigid.torque_columns(train)
        A, y = np.hstack([F_L, Phi]), train.tau.ravel()
        held = model.rigid.feasible
        problem = Compressed(A, y)
        coef, _ = feasible_fit(problem, held.bodies, np.asarray(held.prior), held.regularisation, held.nonnegative)
        _, stderr, _ = fit_statistics(A, y, problem)
        k = F_L.shape[1]
        return LoopModel(model.rigid.with_coefficients(coef[:k]), effects, coef[k:], stderr[k:])


@refits("expression")
class Expression(Strategy):
    """A symbolic model of at most :data:`MAX_SYMBOLIC_TERMS` terms: its terms'
    coefficients are refitted with the effects (``g`` is linear in ``L``).

    Its freedom holds, beside its own terms, the kinetic term ``qd_j^2`` of
    each coordinate where the expression lacks it: the Lagrangian of every
    mechanical system has one, and a model whose coefficients are free cannot
    tell a rotor inertia (an armature) from its own inertia on that joint. A
    symbolic fit that left ``qd_j^2`` out would otherwise see its own missing
    term as an armature and report it as a physical effect."""

    name = "expression"
    spans_its_torque = True

    def __init__(self, basis: tuple[sympy.Expr, ...]):
        self.basis = TermLibrary.of_lagrangian(basis)

    @classmethod
    def of(cls, fitted: FittedModel) -> "Expression | None":
        """Its terms' strategy, ``None`` where the expression is too large to expand into terms."""
        basis = expression_terms(fitted)
        return None if basis is None else cls(basis)

    def kinetic(self, dof: int) -> None:
        """Add each ``qd_j^2`` the basis lacks (see the class docstring)."""
        _, qd = coordinate_symbols(dof)
        have = self.basis.expressions
        missing = [v**2 for v in qd if v**2 not in have]
        if missing:
            self.basis = TermLibrary.of_lagrangian(tuple(have) + tuple(missing))

    def freedom(self, model, train):
        self.kinetic(train.dof)
        return self.basis.design(train, "indirect")

    def refit(self, model, train, effects):
        Phi = TermLibrary(effects).design(train, "indirect")
        F_L = self.freedom(model, train)
        coef, stderr, _ = fit_statistics(np.hstack([F_L, Phi]), train.tau.ravel())
        k = len(self.basis)
        expr = sympy.Add(*[sympy.Float(a) * b for a, b in zip(coef[:k], self.basis.expressions)])
        return LoopModel(ExpressionModel(expr, train.dof), effects, coef[k:], stderr[k:])


@refits("opaque")
class KeptFit(Strategy):
    """A model the loop does not refit (a network, or SyReNets' full equation):
    only the effects are fitted to what it leaves. Its own terms therefore
    cannot grow to absorb noise in the refit. What it leaves on the samples it
    was fitted on flatters it, so, unless it was fitted on other data (a
    given fit), it is cross-fitted (:func:`cross_fit`) and a round must also
    lower the error of each cross-fit on the half it did not see."""

    name = "kept fit"

    def __init__(self):
        self.cross_fitted = False

    def start(self, fitted, train, context):
        if context.given:  # fitted on other data: what it leaves here is out of sample already
            return LoopModel.bare(fitted), {}
        cross, info = cross_fit(context.cross_fitter, fitted, train, context.report)
        self.cross_fitted = True
        return LoopModel.bare(cross), {"cross_fit": info}

    def freedom(self, model, train):
        return np.zeros((train.tau.size, 0))

    def refit(self, model, train, effects):
        _, (coef, stderr, _) = self._effects_beside(model, train, effects)
        return LoopModel(model.rigid, effects, coef, stderr)

    def holds_out(self):
        if not self.cross_fitted:  # a given fit was made on other data
            return "the model and its effects (the fit was made on other data)"
        return "the effects only: the fit saw every training row"

    def check(self, proposed, model, train):
        if not self.cross_fitted:  # a given fit has no cross-fits
            return None
        # the kept fit saw every training sample; its cross-fits did not see the half they predict
        now, then = cross_fitted_mse(proposed, train), cross_fitted_mse(model, train)
        if np.all(now < then):
            return None
        return (f"the effects do not lower the error of the method fitted on one half of the training "
                f"data on the other half, for each half ({_fmt(now)} against {_fmt(then)})",
                f"the cross-fitted error ({_fmt(now)}) is not below {_fmt(then)} on each half")


def strategy_for(fitted: FittedModel) -> Strategy:
    """The strategy for ``fitted``, chosen once from its declared structure
    (:meth:`~bench.physics.models.FittedModel.structure`) in :data:`STRATEGIES`;
    a model the strategy cannot take (an expression too large to expand into
    terms) is kept like a network."""
    return STRATEGIES.get(fitted.structure(), KeptFit).of(fitted) or KeptFit()


# -- the parametric strategy's fits ------------------------------------------------------

def nonlinear_fit(rigid: ParametricModel, train: Dataset, effects: list[Term], coef0) -> LoopModel:
    """Parameters and effects' coefficients together, by nonlinear least squares
    (trust-region reflective, analytic effect columns, the form's parameter
    Jacobian, :meth:`~bench.physics.models.ParametricModel.jacobian`)."""
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


def polish(rigid: ParametricModel, train: Dataset, seed: int, deadline: float = math.inf) -> LoopModel:
    """Nonlinear least squares from the method's parameters and from
    :data:`POLISH_STARTS` log-uniform starts in [0.01, 10], each fitted on
    :data:`POLISH_SAMPLES` random training samples; the best of them is then
    refitted on all of ``train``. No start begins after ``deadline``
    (:func:`bench.core.budget.now`) but the first; the final refit always runs.

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
        return LoopModel.bare(rigid)
    if screen is train:
        return best
    refined = _best_fit(rigid, [best.rigid.theta], train)
    return best if refined is None else refined


def _best_fit(rigid: ParametricModel, starts: list, data: Dataset, deadline: float = math.inf) -> LoopModel | None:
    """The lowest-RSS nonlinear fit of ``rigid`` on ``data`` from ``starts``
    (``None`` if no start gave a finite one); no start but the first begins after ``deadline``."""
    best, best_rss = None, math.inf
    for i, theta in enumerate(starts):
        if i and now() > deadline:
            break
        try:
            fit = nonlinear_fit(rigid.with_parameters(theta), data, [], [])
        except (ValueError, np.linalg.LinAlgError):  # a start where the form is not finite
            continue
        r = fit.predict_torque(data) - data.tau
        rss = float(np.sum(r * r))
        if math.isfinite(rss) and rss < best_rss:
            best, best_rss = fit, rss
    return best


# -- the kept fit's cross-fits -------------------------------------------------------------

def cross_fit(fitter: Fitter, fit: FittedModel, train: Dataset, report: Report) -> tuple[CrossFitted, dict]:
    """A kept fit with cross-fits to check it by.

    The fit saw every training sample, so what it leaves on them is smaller
    than, and unlike, what it leaves on a recording it has not seen: an
    effect can fit that residual, on every recording, and still not help on
    a new one. The validation folds (:func:`bench.core.folds.folds`:
    the trajectories, or spans in time) are dealt alternately into two
    halves; the method is fitted on each half, with ``fitter``'s budget, and
    predicts the other (:func:`cross_fitted_mse`).

    The effects are still fitted to what the fit on all the training data
    leaves, because that fit is what the loop keeps: on the DFKI recordings,
    an MLP fitted on half of them (two or three recordings) leaves 1.1 to 3.6
    times (median 2.3) the error on the other half that the MLP fitted on
    all of them leaves on the test recordings, and SyReNets up to 88 times,
    so effects fitted to the cross-fits' residual would mend their
    shortfall, not the kept fit's (fitted so, the MLP ended 1.19 times worse
    on the suite's test recordings).
    """
    t0 = now()
    fold_masks = folds(train).held
    halves = [np.any(fold_masks[k::2], axis=0) for k in (0, 1)]
    torque = np.empty_like(train.tau)
    for held in halves:
        other = fitter.fit(train.subset(np.flatnonzero(~held)))
        torque[held] = np.asarray(other.predict_torque(train.subset(np.flatnonzero(held))), dtype=np.float64)
    info = {"in_sample_mse": mse(rigid_torque(fit, train), train.tau), "out_of_fold_mse": mse(torque, train.tau),
            "fit_budget_s": fitter.budget.seconds if fitter.budget.steps is None else None,
            "fit_budget": fitter.budget.to_json(), "seconds": round(now() - t0, 3)}
    report(f"round 0: {fitter.method} cross-fitted on two halves of the training data ({fitter.budget.describe()} each): "
           f"torque MSE {info['out_of_fold_mse']:.4g} on the half it did not see, "
           f"{info['in_sample_mse']:.4g} for the fit on all of it")
    return CrossFitted(fit, halves, torque), info


def cross_fitted_mse(model: LoopModel, train: Dataset) -> np.ndarray:
    """For each half of a :class:`CrossFitted` model's training data, the
    torque MSE of the method fitted on the other half plus the model's
    effects (their coefficients as fitted)."""
    cross = model.rigid
    tau = cross.torque + (model.columns(train) @ model.coef).reshape(cross.torque.shape) if model.effects else cross.torque
    return np.asarray([mse(tau[held], train.tau[held]) for held in cross.halves])


def _fmt(x) -> str:
    return ", ".join(f"{v:.4g}" for v in np.atleast_1d(x))
