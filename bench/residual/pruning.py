"""What the loop does to its effects after each joint refit: drop the
redundant ones, refine the shaped ones' nonlinear parameter, replace a law
by the simplest one the data identify, and drop the ones the refit made
impossible. Each works through the model's refit
strategy (:mod:`bench.residual.strategies`)."""

from __future__ import annotations

import math

import numpy as np

from bench.core.data import Dataset
from bench.physics.effects import EFFECTS
from bench.physics.laws import FAMILIES, led_by, one_law_per_family
from bench.physics.regression import Compressed
from bench.physics.terms import Term
from bench.residual.library import admissible, label
from bench.residual.model import LoopModel
from bench.residual.basis import extend_basis, orthonormal_basis
from bench.residual.criteria import MIN_BIC_DROP, ROUNDOFF, bic, joint_weights
from bench.residual.shapes import at_limit, refinable, refined_shape, shape_rss
from bench.residual.strategies import Strategy
from bench.runner.progress import Report


def prune(strategy: Strategy, model: LoopModel, train: Dataset, report: Report) -> tuple[LoopModel, list[str]]:
    """Backward elimination after a joint refit: drop an effect whose removal
    raises the BIC (each joint's rows weighted as the trace weighs them,
    :func:`~bench.residual.criteria.joint_weights`) by less than :data:`MIN_BIC_DROP`
    (it became redundant with the refitted model), then refit; repeat until every effect holds. Each
    pass compresses the linear problem once (:class:`~bench.physics.regression.Compressed`)
    and fits it without each effect from that."""
    removed = []
    while model.effects:
        target, F = strategy.problem(model, train)
        y = target.ravel()
        n, k = len(y), F.shape[1]
        w = joint_weights(y, orthonormal_basis(F), train)  # each joint in its own units, as the trace sees it
        y, F = y * w, F * w[:, None]
        first = k - len(model.effects)  # the effects' columns come last
        # residual sums below round-off are equal: their ratios are floating-point noise
        floor = ROUNDOFF * float(np.mean((train.tau.ravel() * w) ** 2)) * n
        problem = Compressed(F, y)
        rss_all = max(problem.rss(), floor)
        weakest, weakest_gain = None, math.inf
        for i in range(len(model.effects)):
            rss_without = max(problem.rss([c for c in range(k) if c != first + i]), floor)
            gain = bic(rss_without, n, k - 1) - bic(rss_all, n, k)
            if gain < weakest_gain:
                weakest, weakest_gain = i, gain
        if weakest_gain >= MIN_BIC_DROP:
            break
        gone = model.effects[weakest]
        removed.append(label(gone))
        report(f"  dropping {label(gone)}: redundant after the joint refit (BIC gain {weakest_gain:.3g})")
        model = strategy.refit(model, train, model.effects[:weakest] + model.effects[weakest + 1:])
    return model, removed


def _shape_problem(strategy: Strategy, model: LoopModel, train: Dataset, index: int):
    """The linear problem (:meth:`Strategy.problem`) without effect ``index``'s
    column: the others' orthonormal basis, the residual, and the problem's
    rows and columns (the effect's included)."""
    target, F = strategy.problem(model, train)
    y = target.ravel()
    first = F.shape[1] - len(model.effects)  # the effects' columns come last
    others = np.delete(F[:, first:], index, axis=1)
    Q = strategy.freedom_basis(model, train)
    Q = extend_basis(Q, others) if others.shape[1] else Q
    return Q, y - Q @ (Q.T @ y), len(y), F.shape[1]


def refine_shapes(strategy: Strategy, model: LoopModel, train: Dataset, report: Report) -> LoopModel:
    """Each shaped effect's nonlinear parameter (a Stribeck velocity) by a
    bounded scalar search of the residual sum of squares, the linear
    coefficients refitted at each value (variable projection), near where it
    stands (:func:`~bench.residual.shapes.refined_shape`); then a joint refit."""
    for i, term in enumerate(model.effects):
        if not refinable(term):
            continue
        Q, r, _, _ = _shape_problem(strategy, model, train, i)
        v = refined_shape(Q, r, term, train)
        refined = EFFECTS[term.name].term(term.joint, shape=v)
        report(f"  {label(term)}: {EFFECTS[term.name].shaped} refined to {v:.5g}")
        model = strategy.refit(model, train, model.effects[:i] + [refined] + model.effects[i + 1:])
    return model


def shape_stderr(strategy: Strategy, model: LoopModel, train: Dataset) -> dict[Term, float]:
    """The standard error of each shaped effect's parameter, from the
    curvature of the residual sum of squares: ``sqrt(2 sigma^2 / rss''(v))``."""
    out = {}
    for i, term in enumerate(model.effects):
        if term.shape is None:
            continue
        if not refinable(term):  # a whole number of periods is not estimated on a continuous scale
            out[term] = 0.0
            continue
        Q, r, n, k = _shape_problem(strategy, model, train, i)
        rss = shape_rss(Q, r, term, train, exact=True)  # a curvature from differences: every row projected
        v, h = term.shape, 1e-3 * term.shape
        r0 = rss(v)
        curvature = (rss(v + h) - 2 * r0 + rss(v - h)) / h**2
        sigma2 = r0 / max(n - k - 1, 1)
        out[term] = math.sqrt(2 * sigma2 / curvature) if curvature > 0 else float("inf")
    return out


def drop_inadmissible(strategy: Strategy, model: LoopModel, train: Dataset, report: Report) -> tuple[LoopModel, list[tuple]]:
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
        model = strategy.refit(model, train, model.effects[:i] + model.effects[i + 1:])


def simplest_laws(strategy: Strategy, model: LoopModel, train: Dataset, report: Report) -> tuple[LoopModel, list[str]]:
    """Each law replaced by the simplest law it contains that the data do not
    tell apart from it, then at most one law of each physical family on a
    joint; refitting after each change. Returns the model and, per change,
    what was replaced by what and why.

    A shaped part (a Stribeck hump, smoothed Coulomb friction) is replaced by
    the parts its law's limits give (:attr:`bench.physics.laws.Law.limits`; the
    limit whose fit has the least BIC) where its shape's or its coefficient's
    standard error is at least its value, where an essential part of its law
    is missing (:attr:`~bench.physics.laws.Law.essential`: a Stribeck law's
    Coulomb level, then ``0 ± 0``), where its shape sits at an end of
    :data:`~bench.residual.shapes.SHAPE_LIMITS`, or where that limit's BIC
    is not above the law's by more than :data:`MIN_BIC_DROP` (the loop's own
    criterion: a shape is a parameter). Then, where a joint's parts make two
    laws of one family (smoothed Coulomb friction beside a Stribeck hump, say),
    the part whose removal raises the BIC least goes, until one law is left.
    """
    changes = []
    while (step := _simpler(strategy, model, train)) is not None:
        effects, text = step
        report(f"  {text}")
        changes.append(text)
        model = strategy.refit(model, train, effects)
    while (step := _one_per_family(strategy, model, train)) is not None:
        effects, text = step
        report(f"  {text}")
        changes.append(text)
        model = strategy.refit(model, train, effects)
    return model, changes


class _Fits:
    """The BIC of the model's linear problem (:meth:`Strategy.problem`) with
    some effects' columns left out or some of ``extra`` added, from one
    compressed problem (:class:`~bench.physics.regression.Compressed`)."""

    def __init__(self, strategy: Strategy, model: LoopModel, train: Dataset, extra: list[Term] = ()):
        target, F = strategy.problem(model, train)
        self.extra = list(dict.fromkeys(extra))
        columns = [F] + [t.column(train, "indirect")[:, None] for t in self.extra]
        y = target.ravel()
        self.k, self.n, self.effects = F.shape[1], len(y), model.effects
        self.problem = Compressed(np.hstack(columns), y)
        self.first = self.k - len(model.effects)  # the effects' columns come last
        self.shapes = sum(_has_shape(t) for t in model.effects)
        self.floor = ROUNDOFF * float(np.mean(train.tau**2)) * self.n
        self.now = self.bic()

    def bic(self, without: tuple[int, ...] = (), added: list[Term] = ()) -> float:
        gone = {self.first + i for i in without}
        columns = [c for c in range(self.k) if c not in gone] + [self.k + self.extra.index(t) for t in added]
        shapes = self.shapes - sum(_has_shape(self.effects[i]) for i in without)
        rss = max(self.problem.rss(columns), self.floor)
        return bic(rss, self.n, len(columns) + shapes)


def _has_shape(term: Term) -> bool:
    """Whether ``term`` carries its law's shape as a parameter of its own: a shaped
    part that leads its law (a periodic torque's cosine part shares its sine's ``N``)."""
    return term.shape is not None and led_by(term.name) is not None


def _simpler(strategy: Strategy, model: LoopModel, train: Dataset) -> tuple[list[Term], str] | None:
    """The first shaped part to replace by a limit of its law, as the new
    effects and the words for it; ``None`` where every one holds."""
    shaped = [i for i, t in enumerate(model.effects)
              if t.shape is not None and led_by(t.name) is not None and t.name in led_by(t.name).limits]
    if not shaped:
        return None
    on_joint = {i: {t.name for t in model.effects if t.joint == model.effects[i].joint and len(t.joints) == 1}
                for i in shaped}
    options = {}  # per shaped part: each limit's parts and the effects it would add
    for i in shaped:
        term = model.effects[i]
        options[i] = [(parts, [EFFECTS[p].term(term.joint) for p in parts if p not in on_joint[i]])
                      for parts in led_by(term.name).limits[term.name]]
    fits = _Fits(strategy, model, train, [t for limits in options.values() for _, added in limits for t in added])
    errors = shape_stderr(strategy, model, train)
    for i in shaped:
        term, effect, law = model.effects[i], EFFECTS[model.effects[i].name], led_by(model.effects[i].name)
        limits = [(fits.bic((i,), added), parts, added) for parts, added in options[i]]
        best, parts, added = min(limits, key=lambda limit: limit[0])
        why = [f"{law.name}'s {part} is not on joint {term.joint + 1}: its parameter is 0 ± 0, not identified"
               for part in law.essential if part not in on_joint[i]]
        if errors.get(term, 0.0) >= term.shape:
            why.append(f"{effect.shaped}'s standard error {errors[term]:.2g} is at least its value")
        if abs(model.coef[i]) <= model.stderr[i]:
            why.append(f"{effect.parameter}'s standard error {model.stderr[i]:.2g} is at least its value "
                       f"{model.coef[i]:.3g}")
        if at_limit(term.shape):
            why.append(f"{effect.shaped} = {term.shape:.4g} is at an end of its range")
        if best - fits.now <= MIN_BIC_DROP:
            why.append(f"the simpler law is no worse by BIC ({best - fits.now:+.3g})")
        if why:
            into = " + ".join(f"{p} on joint {term.joint + 1}" for p in parts) or "nothing"
            text = f"{label(term)} replaced by {into}, the law's limit: {'; '.join(why)}"
            return model.effects[:i] + model.effects[i + 1:] + added, text
    return None


def _one_per_family(strategy: Strategy, model: LoopModel, train: Dataset) -> tuple[list[Term], str] | None:
    """The part to drop where a joint's parts make two laws of one family, as
    the new effects and the words for it; ``None`` where no joint does."""
    for joint in sorted({t.joint for t in model.effects if t.joint is not None and len(t.joints) == 1}):
        mine = [i for i, t in enumerate(model.effects) if t.joint == joint and len(t.joints) == 1 and t.name in FAMILIES]
        if one_law_per_family({model.effects[i].name for i in mine}):
            continue
        fits = _Fits(strategy, model, train)
        i = min(mine, key=lambda i: fits.bic((i,)))
        text = (f"{label(model.effects[i])} dropped: joint {joint + 1} would carry two laws of one family, and "
                f"without it the BIC rises least ({fits.bic((i,)) - fits.now:+.3g})")
        return model.effects[:i] + model.effects[i + 1:], text
    return None
