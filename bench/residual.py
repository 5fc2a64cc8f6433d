"""The residual loop: find what a fitted model lacks, add it, refit, repeat.

Each round:

1. **Fit.** The method is fitted on the training torques (indirect
   experiment) with the system's declared model only. A parametric model's
   parameters are then polished by nonlinear least squares (from the
   method's parameters and 16 random starts), so that an
   optimiser's shortfall is not taken for a physical effect; ``mse_before``
   is the polished model's, and round 0 records the method's own.
2. **Residual.** ``r = tau - g(L_hat) - Phi c`` on the training and test sets.
3. **Trace.** Forward stepwise selection over candidate torque columns
   ``Phi``: per joint, the effects of :mod:`bench.effects` (viscous and
   Coulomb friction, armature, spring, offset) and an open-ended library
   generated from ``q, qd, qdd, sign qd, |qd|`` and trigonometric functions
   of the joint's and its neighbours' angles: every product of two of them
   (quadratic drag ``qd |qd|``, a velocity-dependent coupling
   ``qd_1 cos(q_1 - q_2)``, ...) and ``q^3``, ``qd^3``
   (:func:`_symbolic_terms`), reported as ``symbolic`` with their expression.
   The named effects are tried first at each step. Candidates are
   judged beside the model's own freedom: a symbolic model's terms, or a
   parametric model's parameter directions (its Jacobian), are refitted with
   them, so a candidate the model could already express gains nothing.
4. **Add** the accepted effects: conservative ones to the Lagrangian
   (armature ``+c qd^2/2``, spring ``-c q^2/2``), dissipative ones as
   generalized forces (viscous friction from the Rayleigh function
   ``c qd^2/2``, Coulomb friction, offsets, symbolic terms).
5. **Refit jointly.** A parametric model (SysId: the system's declared form
   with unknown physical parameters) is refitted with the effects by
   nonlinear least squares over parameters and coefficients together, which
   keeps the form's constraints (an armature cannot hide in a mass). Other
   methods are refitted on the targets with the effects' torques taken off;
   then a symbolic model's terms and the effects' coefficients are refitted
   together by linear least squares (``g`` is linear in ``L``), and a neural
   model's effects on what it leaves (backfitting). A symbolic model of more
   than :data:`MAX_SYMBOLIC_TERMS` terms (SyReNets' full equation) is treated
   like a neural one.
6. **Repeat** until a round accepts nothing.

Statistics
----------
A candidate is accepted only if all hold:

* the Bayesian information criterion of the residual fit, over all training
  rows, falls by more than :data:`MIN_BIC_DROP` (strong evidence on Kass &
  Raftery's scale);
* its coefficient is at least :data:`MIN_T` standard errors from zero;
* it lowers the mean squared residual on held-out rows (every fourth of
  :data:`HELDOUT_BLOCKS` contiguous blocks of training samples, not used to
  fit it: on measured trajectories neighbouring samples are near copies, so
  interleaved rows would not test generalisation) by at least
  :data:`MIN_HELDOUT_GAIN` of that residual;
* the residual is above the floor of numerical round-off
  (:data:`ROUNDOFF` of the torque's mean square), so a model that already
  fits exactly is left alone.

Noise alone fails the first two tests: with Gaussian residuals, a useless
column lowers ``n log RSS`` by a chi-squared(1) amount, and ``log n`` plus the
drop of 10 asks for a chi-squared value above 20 (p < 1e-5 per candidate).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
import sympy

from bench import symbolic
from bench.data import Dataset, mse
from bench.effects import EFFECTS

MIN_BIC_DROP = 10.0
MIN_T = 5.0
MIN_HELDOUT_GAIN = 0.01
ROUNDOFF = 1e-20
MAX_ROUNDS = 6
#: the held-out rows are every fourth of this many contiguous blocks of the training data
HELDOUT_BLOCKS = 16
#: a symbolic model with more terms than this is refitted like a neural one
#: (a least-squares refit of thousands of terms is neither fast nor meaningful)
MAX_SYMBOLIC_TERMS = 200


@dataclass(frozen=True)
class Candidate:
    """One torque column: an effect (or a symbolic term) on one joint (0-based)."""

    name: str
    joint: int
    expression: str | None = None

    def key(self) -> tuple:
        return (self.name, self.joint, self.expression)

    def label(self) -> str:
        what = self.expression if self.expression else self.name
        return f"{what} on joint {self.joint + 1}"


def _primitives(dof: int, j: int) -> list[tuple[str, object]]:
    """The building blocks of the open-ended terms of joint ``j``: its own
    ``q, qd, qdd, sign qd, |qd|, sin q, cos q`` and, per other joint ``k``,
    ``q_k, qd_k, qdd_k, sin(q_j - q_k), cos(q_j - q_k)``."""
    n = j + 1
    out = [
        (f"q_{n}", lambda d: d.q[:, j]),
        (f"qd_{n}", lambda d: d.qd[:, j]),
        (f"qdd_{n}", lambda d: d.qdd[:, j]),
        (f"sign(qd_{n})", lambda d: np.sign(d.qd[:, j])),
        (f"Abs(qd_{n})", lambda d: np.abs(d.qd[:, j])),
        (f"sin(q_{n})", lambda d: np.sin(d.q[:, j])),
        (f"cos(q_{n})", lambda d: np.cos(d.q[:, j])),
    ]
    for k in range(dof):
        if k != j:
            m = k + 1
            out += [
                (f"q_{m}", lambda d, k=k: d.q[:, k]),
                (f"qd_{m}", lambda d, k=k: d.qd[:, k]),
                (f"qdd_{m}", lambda d, k=k: d.qdd[:, k]),
                (f"sin(q_{n} - q_{m})", lambda d, k=k: np.sin(d.q[:, j] - d.q[:, k])),
                (f"cos(q_{n} - q_{m})", lambda d, k=k: np.cos(d.q[:, j] - d.q[:, k])),
            ]
    return out


#: products of the joint's own sign(qd) and |qd| are not new terms: sign^2 = 1,
#: sign(x) |x| = x, |x|^2 = x^2 (a square of a cosine, 1 - sin^2, and
#: qd sign(qd) = |qd| are skipped too)
_DEGENERATE = {("sign", "sign"), ("sign", "Abs"), ("Abs", "sign"), ("Abs", "Abs")}


@functools.lru_cache(maxsize=None)
def _symbolic_terms(dof: int, j: int) -> tuple[tuple[str, object], ...]:
    """Open-ended terms for joint ``j``: ``(expression text, feature(data) -> (n,))``.

    Every primitive (:func:`_primitives`) that is not a named effect's own
    column, every product of two primitives (with repetition, less the
    degenerate ones), and ``q^3``, ``qd^3`` and ``sign(qd) |q|`` of the joint:
    a polynomial-trigonometric library of degree two in the states, searched
    by the same stepwise selection as the named effects.
    """
    n = j + 1
    prims = _primitives(dof, j)
    named = {f"q_{n}", f"qd_{n}", f"qdd_{n}", f"sign(qd_{n})"}  # spring, viscous, armature, Coulomb
    terms = [(text, f) for text, f in prims if text not in named]
    for a in range(len(prims)):
        for b in range(a, len(prims)):
            (ta, fa), (tb, fb) = prims[a], prims[b]
            heads = (ta.split("(")[0], tb.split("(")[0])
            if heads in _DEGENERATE or (ta == tb and heads[0] == "cos") or {ta, tb} == {f"qd_{n}", f"sign(qd_{n})"}:
                continue
            text = f"{ta}**2" if ta == tb else f"{ta}*{tb}"
            terms.append((text, lambda d, fa=fa, fb=fb: fa(d) * fb(d)))
    terms += [
        (f"q_{n}**3", lambda d: d.q[:, j] ** 3),
        (f"qd_{n}**3", lambda d: d.qd[:, j] ** 3),
        (f"sign(qd_{n})*Abs(q_{n})", lambda d: np.sign(d.qd[:, j]) * np.abs(d.q[:, j])),
    ]
    return tuple(terms)


def candidates(dof: int) -> list[Candidate]:
    out = [Candidate(name, j) for name in EFFECTS for j in range(dof)]
    out += [Candidate("symbolic", j, expr) for j in range(dof) for expr, _ in _symbolic_terms(dof, j)]
    return out


def column(c: Candidate, data: Dataset) -> np.ndarray:
    """The candidate's torque per unit coefficient, flattened sample-major ``(n * dof,)``."""
    if c.name != "symbolic":
        return EFFECTS[c.name].torque(data, c.joint).ravel()
    feature = dict(_symbolic_terms(data.dof, c.joint))[c.expression]
    out = np.zeros_like(data.tau)
    out[:, c.joint] = feature(data)
    return out.ravel()


def columns(cands: list[Candidate], data: Dataset) -> np.ndarray:
    if not cands:
        return np.zeros((data.tau.size, 0))
    return np.stack([column(c, data) for c in cands], axis=1)


def _lstsq(F: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Coefficients, their standard errors, and the residual sum of squares."""
    coef, *_ = np.linalg.lstsq(F, y, rcond=None)
    resid = y - F @ coef
    rss = float(resid @ resid)
    dof = max(len(y) - F.shape[1], 1)
    try:
        cov = np.linalg.pinv(F.T @ F) * (rss / dof)
        stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        stderr = np.full(F.shape[1], np.inf)
    return coef, stderr, rss


def _bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


@dataclass
class Selection:
    accepted: list[Candidate]
    steps: list[dict] = field(default_factory=list)


def trace(target: np.ndarray, data: Dataset, pool: list[Candidate], fixed: np.ndarray | None = None,
          exclude: list[Candidate] = ()) -> Selection:
    """Forward stepwise selection of candidates explaining ``target`` (``(n, dof)``).

    Each step tries the named effects first and the open-ended (symbolic)
    terms only when no named effect passes: a physical effect is preferred
    where both explain the residual (a spring ``c q`` beside a model whose
    gravity absorbs ``sin q`` leaves ``c (q - sin q)``, which ``q^3`` also fits).
    ``fixed`` columns (the model's own terms and effects already accepted)
    stay in every fit, so a candidate that only repeats them gains nothing.
    Returns the newly accepted candidates and, per step, the statistics of
    the best candidate, accepted or not.
    """
    y = target.ravel()
    n_rows = len(y)
    # every fourth of 16 contiguous blocks: on trajectories, interleaved samples
    # are near copies of their neighbours and would not test generalisation
    held = np.repeat((np.arange(len(data)) * HELDOUT_BLOCKS // len(data)) % 4 == 3, data.dof)
    fit = ~held
    floor = ROUNDOFF * float(np.mean(data.tau**2))
    fixed = np.zeros((n_rows, 0)) if fixed is None else fixed
    F_all = {c.key(): column(c, data) for c in pool if c not in exclude}
    accepted, steps = [], []

    def design(cands):
        return np.column_stack([fixed] + [F_all[c.key()][:, None] for c in cands]) if cands else fixed

    rss_now = _lstsq(fixed, y)[2] if fixed.shape[1] else float(y @ y)
    # the named effects first; the open-ended terms only where no named effect passes
    tiers = [[c for c in pool if c.name != "symbolic"], [c for c in pool if c.name == "symbolic"]]
    while True:
        if rss_now / n_rows <= floor:
            steps.append({"stop": "the residual is at round-off level", "residual_mse": rss_now / n_rows})
            break
        k_now = fixed.shape[1] + len(accepted)
        chosen = None
        for tier in tiers:
            best = None
            for c in tier:
                if c in exclude or c in accepted:
                    continue
                coef, stderr, rss = _lstsq(design(accepted + [c]), y)
                drop = _bic(rss_now, n_rows, k_now) - _bic(rss, n_rows, k_now + 1)
                if best is None or drop > best["bic_drop"]:
                    best = {"candidate": c, "bic_drop": drop, "coef": float(coef[-1]), "stderr": float(stderr[-1]), "rss": rss}
            if best is None:
                continue
            c = best["candidate"]
            before = _heldout_mse(design(accepted), y, fit, held)
            after = _heldout_mse(design(accepted + [c]), y, fit, held)
            gain = (before - after) / before if before > 0 else 0.0
            t = abs(best["coef"]) / best["stderr"] if best["stderr"] > 0 else math.inf
            ok = best["bic_drop"] > MIN_BIC_DROP and t >= MIN_T and gain >= MIN_HELDOUT_GAIN
            steps.append({"candidate": c.label(), "bic_drop": best["bic_drop"], "t": t if math.isfinite(t) else None,
                          "heldout_gain": gain, "accepted": ok})
            if ok:
                chosen = best
                break
        if chosen is None:
            break
        accepted.append(chosen["candidate"])
        rss_now = chosen["rss"]
    return Selection(accepted, steps)


def _heldout_mse(F: np.ndarray, y: np.ndarray, fit: np.ndarray, held: np.ndarray) -> float:
    if F.shape[1] == 0:
        return float(np.mean(y[held] ** 2))
    coef, *_ = np.linalg.lstsq(F[fit], y[fit], rcond=None)
    r = y[held] - F[held] @ coef
    return float(np.mean(r**2))


# -- the loop ------------------------------------------------------------------------

class LoopModel:
    """``tau_hat = g(L_hat) + Phi c``: a fitted Lagrangian plus accepted effects."""

    def __init__(self, rigid, effects: list[Candidate], coef: np.ndarray, stderr: np.ndarray):
        self.rigid, self.effects = rigid, list(effects)
        self.coef, self.stderr = np.asarray(coef, dtype=np.float64), np.asarray(stderr, dtype=np.float64)

    def predict_torque(self, data: Dataset) -> np.ndarray:
        tau = np.asarray(self.rigid.predict_torque(data), dtype=np.float64)
        if self.effects:
            tau = tau + (columns(self.effects, data) @ self.coef).reshape(tau.shape)
        return tau

    def expression(self):
        expression = getattr(self.rigid, "expression", None)
        return expression() if expression else None


class ParametricModel:
    """``g(L(q, qd; theta))`` for a system's parametric form (:class:`systems.base.ParametricForm`)."""

    def __init__(self, form, theta):
        self.form, self.theta = form, np.asarray(theta, dtype=np.float64)

    def predict_torque(self, data: Dataset, theta=None) -> np.ndarray:
        import torch

        from bench.dynamics import euler_lagrange_chunked

        th = torch.tensor(self.theta if theta is None else theta, dtype=torch.float64)
        t = data.tensors()
        return euler_lagrange_chunked(lambda q, qd: self.form.torch_fn(q, qd, th), t["q"], t["qd"], t["qdd"])[0].numpy()

    def jacobian(self, data: Dataset) -> np.ndarray:
        """``d tau / d theta``, flattened sample-major, by central differences."""
        cols = []
        for i, value in enumerate(self.theta):
            h = 1e-6 * max(1.0, abs(value))
            up, down = self.theta.copy(), self.theta.copy()
            up[i] += h
            down[i] -= h
            cols.append((self.predict_torque(data, up) - self.predict_torque(data, down)).ravel() / (2 * h))
        return np.stack(cols, axis=1)

    def expression(self) -> sympy.Expr:
        return sympy.expand(self.form.substitute(self.theta.tolist()))


def _nonlinear_fit(rigid: ParametricModel, train: Dataset, effects: list[Candidate], coef0) -> "LoopModel":
    """Parameters and effects' coefficients together, by nonlinear least squares
    (trust-region reflective, analytic effect columns, differenced parameter columns)."""
    from scipy.optimize import least_squares

    Phi = columns(effects, train)
    y = train.tau.ravel()
    p = len(rigid.theta)

    def residual(x):
        return ParametricModel(rigid.form, x[:p]).predict_torque(train).ravel() + Phi @ x[p:] - y

    def jac(x):
        return np.hstack([ParametricModel(rigid.form, x[:p]).jacobian(train), Phi])

    x0 = np.concatenate([rigid.theta, np.asarray(coef0, dtype=np.float64)])
    sol = least_squares(residual, x0, jac=jac, method="trf", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    J = sol.jac
    rss = float(sol.fun @ sol.fun)
    cov = np.linalg.pinv(J.T @ J) * (rss / max(len(y) - len(sol.x), 1))
    stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    return LoopModel(ParametricModel(rigid.form, sol.x[:p]), effects, sol.x[p:], stderr[p:])


#: random starts of the parametric polish, beside the method's own parameters
POLISH_STARTS = 16


def _polish(rigid: ParametricModel, train: Dataset, seed: int) -> "LoopModel":
    """Nonlinear least squares from the method's parameters and from
    :data:`POLISH_STARTS` log-uniform starts in [0.01, 10]; the best fit is kept."""
    rng = np.random.default_rng([seed, 0x706F6C])
    starts = [rigid.theta] + [10 ** rng.uniform(-2, 1, len(rigid.theta)) for _ in range(POLISH_STARTS)]
    best, best_rss = None, math.inf
    for theta in starts:
        try:
            fit = _nonlinear_fit(ParametricModel(rigid.form, theta), train, [], [])
        except (ValueError, np.linalg.LinAlgError):  # a start where the form is not finite
            continue
        r = fit.predict_torque(train) - train.tau
        rss = float(np.sum(r * r))
        if math.isfinite(rss) and rss < best_rss:
            best, best_rss = fit, rss
    return best if best is not None else LoopModel(rigid, [], np.zeros(0), np.zeros(0))


def _as_parametric(fitted):
    """A :class:`ParametricModel` for a method that identifies a parametric form, else ``None``."""
    if hasattr(fitted, "identified_parameters") and hasattr(fitted, "form"):
        return ParametricModel(fitted.form, list(fitted.identified_parameters().values()))
    return fitted if isinstance(fitted, ParametricModel) else None


def _with_tau(data: Dataset, tau: np.ndarray) -> Dataset:
    return Dataset(data.q, data.qd, data.qdd, tau, None, data.system, data.source, dict(data.meta))


def _fit_method(method: str, train: Dataset, seed: int, budget_s: float, hyperparameters: dict):
    from methods import METHODS

    return METHODS[method](**hyperparameters).fit(train, "indirect", seed, budget_s)


def _terms(expr: sympy.Expr) -> list[sympy.Expr]:
    """The coefficient-free terms of an expanded expression that act on the torque."""
    out = []
    for term in sympy.Add.make_args(sympy.expand(expr)):
        _, rest = term.as_coeff_Mul()
        if rest.free_symbols and rest not in out:
            out.append(rest)
    return out


def _lagrangian_columns(rigid, data: Dataset) -> tuple[list[sympy.Expr], np.ndarray] | None:
    """The symbolic model's terms and their torque columns; ``None`` for a neural model."""
    from bench import regression

    expression = getattr(rigid, "expression", None)
    expr = expression() if expression else None
    if expr is None:
        return None
    basis = _terms(expr)
    if len(basis) > MAX_SYMBOLIC_TERMS:
        return None
    return basis, regression.design_matrix(basis, data, "indirect")


def _refit(model: LoopModel, train: Dataset, effects: list[Candidate], spec: dict) -> LoopModel:
    """Refit the method with the effects' torques off the targets, then the
    Lagrangian's terms (symbolic models) and the effects together."""
    from methods.base import ExpressionModel

    y = train.tau.ravel()
    Phi = columns(effects, train)
    coef = _lstsq(Phi, y - np.ravel(model.rigid.predict_torque(train)))[0]
    if isinstance(model.rigid, ParametricModel):
        return _nonlinear_fit(model.rigid, train, effects, coef)
    rigid = _fit_method(spec["method"], _with_tau(train, train.tau - (Phi @ coef).reshape(train.tau.shape)),
                        spec["seed"], spec["budget_s"], spec["hyperparameters"])
    lagrangian = _lagrangian_columns(rigid, train)
    if lagrangian is None:
        coef, stderr, _ = _lstsq(Phi, y - np.ravel(rigid.predict_torque(train)))
        return LoopModel(rigid, effects, coef, stderr)
    basis, F_L = lagrangian
    coef, stderr, _ = _lstsq(np.hstack([F_L, Phi]), y)
    k = len(basis)
    expr = sympy.Add(*[sympy.Float(a) * b for a, b in zip(coef[:k], basis)])
    return LoopModel(ExpressionModel(expr, train.dof), effects, coef[k:], stderr[k:])


def _freedom(model: LoopModel, train: Dataset) -> np.ndarray:
    """Columns for what the model can already express: a parametric model's
    parameter directions, a symbolic model's terms, nothing for a neural one."""
    if isinstance(model.rigid, ParametricModel):
        return model.rigid.jacobian(train)
    lagrangian = _lagrangian_columns(model.rigid, train)
    return np.zeros((train.tau.size, 0)) if lagrangian is None else lagrangian[1]


def _fit_problem(model: LoopModel, train: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """What tracing and pruning fit: the target (``(n, dof)``) and the columns
    always in the fit, the model's freedom (:func:`_freedom`) then the accepted
    effects. A symbolic model's terms span its own torque, so the target is the
    torque itself; otherwise it is what the rigid model leaves."""
    target = train.tau if _is_symbolic(model.rigid) else train.tau - np.asarray(model.rigid.predict_torque(train))
    return target, np.hstack([_freedom(model, train), columns(model.effects, train)])


def _prune(model: LoopModel, train: Dataset, spec: dict, report) -> tuple[LoopModel, list[str]]:
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
        rss_all = max(_lstsq(F, y)[2], floor)
        weakest, weakest_gain = None, math.inf
        for i in range(len(model.effects)):
            rss_without = max(_lstsq(np.delete(F, first + i, axis=1), y)[2], floor)
            gain = _bic(rss_without, n, k - 1) - _bic(rss_all, n, k)
            if gain < weakest_gain:
                weakest, weakest_gain = i, gain
        if weakest_gain >= MIN_BIC_DROP:
            break
        gone = model.effects[weakest]
        removed.append(gone.label())
        report(f"  dropping {gone.label()}: redundant after the joint refit (BIC gain {weakest_gain:.3g})")
        model = _refit(model, train, model.effects[:weakest] + model.effects[weakest + 1:], spec)
    return model, removed


def _is_symbolic(rigid) -> bool:
    """A model given by an expression whose terms :func:`_freedom` refits (not a parametric one)."""
    if isinstance(rigid, ParametricModel):
        return False
    expression = getattr(rigid, "expression", None)
    expr = expression() if expression is not None else None
    return expr is not None and len(_terms(expr)) <= MAX_SYMBOLIC_TERMS


def residual_loop(method: str, train: Dataset, test: Dataset | None, *, budget_s: float = 60.0, seed: int = 0,
                  hyperparameters: dict | None = None, report=print, fitted=None) -> dict:
    """Run the loop; returns the JSON contract (see ``python -m bench residual``).

    ``fitted`` is an already fitted instance of ``method`` to start from
    instead of round 0's fit (for instance a model fitted before the system
    changed). Each round records ``seconds``, the time since the loop began.
    """
    spec = {"method": method, "seed": seed, "budget_s": budget_s, "hyperparameters": hyperparameters or {}}
    start = time.perf_counter()
    if fitted is None:
        report(f"round 0: fitting {method} on {len(train)} samples with the declared model only ({budget_s:g} s)")
        fitted = _fit_method(method, train, seed, budget_s, spec["hyperparameters"])
    else:
        report(f"round 0: starting from the given {method} fit")

    def scores(m):
        return {"train": mse(m.predict_torque(train), train.tau),
                "test": None if test is None else mse(m.predict_torque(test), test.tau)}

    model = LoopModel(fitted, [], np.zeros(0), np.zeros(0))
    round0 = {"round": 0, "accepted": [], "trace": []}
    parametric = _as_parametric(fitted)
    if parametric is not None:
        # polish the parameters, so that an optimiser's shortfall is not taken for an effect
        round0["method_mse"] = scores(model)
        model = _polish(parametric, train, seed)
        report(f"round 0: {method}'s parameters polished by nonlinear least squares "
               f"(train MSE {round0['method_mse']['train']:.4g} -> {scores(model)['train']:.4g})")
    first = model
    before = scores(model)
    round0["mse"] = before
    round0["seconds"] = round(time.perf_counter() - start, 3)
    rounds = [round0]
    pool = candidates(train.dof)
    report(f"round 0: torque MSE train {before['train']:.4g}, test {_fmt(before['test'])}")
    for k in range(1, MAX_ROUNDS + 1):
        target, fixed = _fit_problem(model, train)
        selection = trace(target, train, pool, fixed, exclude=model.effects)
        if not selection.accepted:
            rounds.append({"round": k, "mse": scores(model), "accepted": [], "trace": selection.steps,
                           "seconds": round(time.perf_counter() - start, 3)})
            report(f"round {k}: nothing significant left")
            break
        effects = model.effects + selection.accepted
        report(f"round {k}: adding {', '.join(c.label() for c in selection.accepted)}; refitting jointly")
        model = _refit(model, train, effects, spec)
        model, removed = _prune(model, train, spec, report)
        s = scores(model)
        rounds.append({"round": k, "mse": s, "accepted": [c.label() for c in selection.accepted], "removed": removed,
                       "trace": selection.steps, "seconds": round(time.perf_counter() - start, 3)})
        if not set(c.label() for c in selection.accepted) - set(removed):
            report(f"round {k}: every effect it added became redundant; stopping")
            break
        report(f"round {k}: torque MSE train {s['train']:.4g}, test {_fmt(s['test'])}")
    after = scores(model)
    expr = model.expression()
    return {
        "system": train.system,
        "method": method,
        "mse_before": before,
        "mse_after": after,
        "effects": [_effect_entry(c, a, s) for c, a, s in zip(model.effects, model.coef, model.stderr)],
        "rounds": rounds,
        "lagrangian": None if expr is None else str(expr),
        "seconds": round(time.perf_counter() - start, 2),
        "budget_s": budget_s,
        "seed": seed,
        "train_source": train.source,
        "test_source": None if test is None else test.source,
        "_models": (first, model),
    }


def _effect_entry(c: Candidate, coef: float, stderr: float) -> dict:
    entry = {"name": c.name, "joint": c.joint + 1, "coefficient": float(coef), "stderr": float(stderr)}
    if c.expression:
        entry["expression"] = c.expression
    return entry


def _fmt(x) -> str:
    return "—" if x is None else f"{x:.4g}"


# -- output ---------------------------------------------------------------------------

def write_outputs(result: dict, train: Dataset, test: Dataset | None, json_path=None, report_path=None) -> None:
    """The JSON contract and the markdown report with residual-versus-state plots.
    Each file is written atomically; the plot and the report's text are made
    before the JSON and the report are written."""
    from pathlib import Path

    from bench.fileio import atomic_write, write_json
    from bench.records import provenance

    public = {k: v for k, v in result.items() if not k.startswith("_")}
    public["provenance"] = provenance()
    if report_path is not None:
        report_path = Path(report_path)
        first, final = result["_models"]
        data = test if test is not None else train
        split = "test" if test is not None else "train"
        stem = report_path.with_suffix("")
        from bench.plots import residual_plot

        plot = residual_plot(data, data.tau - first.predict_torque(data), Path(f"{stem}_residuals.png"),
                             title=f"{result['system']}, {result['method']}: torque residual on the {split} set, "
                                   "before and after the loop",
                             after=data.tau - final.predict_torque(data))
        text = report(public, plot.name)
    if json_path is not None:
        write_json(json_path, public)
    if report_path is not None:
        atomic_write(report_path, lambda f: f.write(text))


def report(result: dict, plot_name: str | None = None) -> str:
    b, a = result["mse_before"], result["mse_after"]

    def cell(x):
        return "—" if x is None else f"{x:.4g}"

    def ratio(x, y):
        return "—" if x is None or y is None or y == 0 else f"{x / y:.3g}"

    lines = [
        f"# Residual loop: {result['system']}, {result['method']}",
        "",
        f"Training data: `{result['train_source']}`; test data: `{result['test_source']}`. "
        f"{result['budget_s']:g} s per fit of the method, seed {result['seed']}; {result['seconds']:g} s in all.",
        "",
        "| torque MSE | train | test |",
        "|---|---:|---:|",
        f"| before (declared model only) | {cell(b['train'])} | {cell(b['test'])} |",
        f"| after (with the effects below) | {cell(a['train'])} | {cell(a['test'])} |",
        f"| after ÷ before | {ratio(a['train'], b['train'])} | {ratio(a['test'], b['test'])} |",
        "",
    ]
    if result["effects"]:
        lines += ["| effect | joint | coefficient | std. error |", "|---|---:|---:|---:|"]
        for e in result["effects"]:
            name = f"symbolic: `{e['expression']}`" if e.get("expression") else e["name"]
            lines.append(f"| {name} | {e['joint']} | {e['coefficient']:.6g} | {e['stderr']:.2g} |")
    else:
        lines.append("No effect added: nothing significant in the residual.")
    lines += ["", "Rounds:", ""]
    for r in result["rounds"]:
        added = ", ".join(r["accepted"]) or "nothing"
        removed = f"; dropped as redundant: {', '.join(r['removed'])}" if r.get("removed") else ""
        last = next((t for t in reversed(r["trace"]) if "candidate" in t and not t["accepted"]), None)
        why = (f" (best rejected: {last['candidate']}, BIC drop {last['bic_drop']:.3g}, |t| {'∞' if last['t'] is None else format(last['t'], '.3g')}, "
               f"held-out gain {last['heldout_gain']:.2%})") if last else ""
        lines.append(f"- round {r['round']}: test MSE {cell(r['mse']['test'])}; added {added}{removed}{why}")
    if plot_name:
        lines += ["", f"![residuals before and after]({plot_name})"]
    if result.get("lagrangian"):
        lines += ["", "Final Lagrangian:", "", f"    {result['lagrangian']}"]
    return "\n".join(lines) + "\n"
