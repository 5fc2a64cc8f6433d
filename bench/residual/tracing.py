"""Which terms explain a residual: forward stepwise selection judged by
information, significance and held-out error.

A term is accepted only if it passes the tests of :mod:`bench.residual.criteria`:
the information it adds, its significance, its held-out gain and its physical sense.

Where other terms that pass every test explain the same part of the
residual as the one chosen (as much of it, and nothing significant beside it)
and give the same held-out error, within the standard error of the difference (paired over the
scored samples, counted as the independent samples they hold; or both at
round-off), the data cannot tell them apart (a law of the whole system, a
payload or a tilt, whose torque is a sum of terms, is also compared with the
best pair of other terms): the step records them as
*equivalent on these data* (:attr:`Trace.equivalents`), and the one kept
is chosen by :data:`EQUIVALENCE_RULE`: the fewest parameters, then the law
declared first (:func:`declared`), not by a difference in fit the data do not
support.

A term is fitted beside the columns already in the design by projecting
it off them (Frisch–Waugh–Lovell: the same coefficients, errors and residual
as refitting the whole design, at a fraction of the cost when the design has
a linear form's dozens of base columns).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bench.core.data import Dataset
from bench.physics.effects import EFFECTS
from bench.physics.laws import led_by
from bench.physics.terms import Term, TermLibrary
from bench.core.budget import now
from bench.residual.basis import extend_basis, orthonormal_basis, project_off
from bench.residual.criteria import (AS_WELL, MIN_BIC_DROP, MIN_HELDOUT_CHI2, MIN_HELDOUT_GAIN, MIN_T, ROUNDOFF, bic,
                                     joint_weights, passes, slot)
from bench.residual.library import admissible, is_named, label
from bench.residual.shapes import SHAPE_LIMITS, at_limit, refinable, refined_shape
from bench.residual.validation import FoldFits, paired_difference, row_folds

#: a term column whose part off the design is below this share of its norm is one the design spans
SPANNED = 1e-9
#: terms tried a step, best first, past ones that fail on significance or held-out error
MAX_TRIES = 8

#: a trace's last step where the loop's time ran out before it ended
BUDGET_STOP = "the loop's budget: no further step started"
#: two held-out errors this close, relatively, are the same fit to round-off (two columns the same beside the design)
SAME = 1e-6
#: a law of the whole system is compared with pairs of the best term and one of this many next best
PAIRED = 20
#: how the trace chooses among terms equivalent on the data (see the module docstring)
EQUIVALENCE_RULE = ("the fewest parameters, then the law declared first (the arm's laws in the order "
                    "bench/physics/effects.py declares them, each from joint 1 on, then the whole system's, the laws "
                    "of the sensor and the drive, and the open-ended terms last)")


@dataclass
class Trace:
    accepted: list[Term]
    steps: list[dict] = field(default_factory=list)
    #: ``(term, coefficient, stderr)`` of a residual only an inadmissible coefficient explains
    structural: list[tuple[Term, float, float]] = field(default_factory=list)
    #: ``(named group, open-ended term, BIC margin, its torque's RMS, the residual's RMS)`` where an
    #: open-ended term explained the residual far better than the named law accepted for it
    mismatched: list[tuple] = field(default_factory=list)
    #: ``(accepted group, runner-up group)``: the next best named term that passed every test
    runners_up: list[tuple] = field(default_factory=list)
    #: ``(kept group, [equivalent groups], entry)``: terms of one step that the held-out error cannot
    #: tell apart, the one kept by :data:`EQUIVALENCE_RULE`; ``entry`` is what the loop's JSON gives of them
    equivalents: list[tuple] = field(default_factory=list)
    #: each joint's weight in the trace's fits (:func:`~bench.residual.criteria.joint_weights`)
    weights: np.ndarray | None = None


def trace(target: np.ndarray, data: Dataset, pool: TermLibrary, fixed: np.ndarray | None = None,
          exclude: list[Term] = (), max_steps: int | None = None, deadline: float = math.inf,
          given: dict[Term, np.ndarray] | None = None, runner_up: bool = False) -> Trace:
    """Forward stepwise selection of terms explaining ``target`` (``(n, dof)``).

    Each step tries the named effects first and the open-ended (symbolic)
    terms only when no named effect passes: a physical effect is preferred
    where both explain the residual (a spring ``c q`` beside a model whose
    gravity absorbs ``sin q`` leaves ``c (q - sin q)``, which ``q^3`` also fits).
    Where an open-ended term explains it better than the best named law by
    more than :data:`MIN_BIC_DROP`, that law may be only the nearest one the
    vocabulary has: the step is recorded in :attr:`Trace.mismatched`, and
    the loop settles it by refitting both (:meth:`bench.residual.loop._Loop.compare`;
    a parametric model's linearisation can favour either).
    ``fixed`` columns (the model's own terms and effects already accepted)
    stay in every fit, so a term that only repeats them gains nothing.
    At most ``max_steps`` terms (or laws) are accepted, where given, and
    no step starts after ``deadline`` (:func:`bench.core.budget.now`).
    ``given`` adds terms whose columns depend on more than the data (a
    sensor's laws, linearised at the model: :mod:`bench.residual.sensors`),
    with those columns; they are named terms like the effects.
    With ``runner_up``, each step also records the next best named term
    of another slot that passes every test (:attr:`Trace.runners_up`),
    for a model whose linearisation may rank the two wrongly (a parametric
    form: :meth:`bench.residual.loop._Loop.compare` refits both).
    Returns the newly accepted terms, per step the statistics of the
    best term, accepted or not, and any structural finding.
    """
    return Tracer(target, data, pool, fixed, exclude, max_steps, deadline, given, runner_up).run()


class Tracer:
    """One trace (:func:`trace`): its data, the terms' columns, what the steps have accepted so far, the
    design's basis and residual, and each step's held-out fits. :meth:`run` takes the steps and returns the
    :class:`Trace`; the other methods are what a step asks of a term (its statistics beside the design,
    its group and refined shape, its physical sense, its equivalents and rivals)."""

    def __init__(self, target: np.ndarray, data: Dataset, pool: TermLibrary, fixed: np.ndarray | None = None,
                 exclude: list[Term] = (), max_steps: int | None = None, deadline: float = math.inf,
                 given: dict[Term, np.ndarray] | None = None, runner_up: bool = False):
        self.data, self.pool, self.fixed, self.exclude = data, pool, fixed, exclude
        self.max_steps, self.deadline, self.given, self.runner_up = max_steps, deadline, given, runner_up
        #: the step's residual off the design, its sum of squares, and its held-out fits and error
        self.r, self.rss_now, self.held_fits, self.before = None, None, None, None
        y = target.ravel()
        self.n_rows = len(y)
        self.held = row_folds(self.data)
        self.min_gain = MIN_HELDOUT_GAIN if self.data.trajectories() else \
            min(MIN_HELDOUT_GAIN, MIN_HELDOUT_CHI2 / self.n_rows)
        fixed = np.zeros((self.n_rows, 0)) if self.fixed is None else self.fixed
        # every row in its joint's units (joint_weights): the target, the design and each term's column
        self.w = joint_weights(y, orthonormal_basis(fixed), data)
        self.y, self.fixed = y * self.w, fixed * self.w[:, None]
        self.floor = ROUNDOFF * float(np.mean((self.data.tau.ravel() * self.w) ** 2))
        self.F_all = {c: self.column(c) for c in self.pool if c not in self.exclude}
        self.F_all.update({c: np.asarray(f, dtype=np.float64) * self.w for c, f in (self.given or {}).items()})
        # a term not finite on the data is left out
        self.F_all = {c: f for c, f in self.F_all.items() if np.isfinite(f).all()}
        self.accepted, self.steps, self.structural = [], [], []
        self.taken = {slot(t) for t in self.exclude}
        self.steps_taken: list[dict] = []
        self.nuisance: list[Term] = []  # what structural findings explain: in every later fit, in no model
        # named laws an open-ended term explained far better: (group, term, margin, size, rms)
        self.mismatched: list[tuple] = []
        self.runners_up: list[tuple] = []  # (accepted group, the next best group that passed every test)
        self.off: dict[Term, np.ndarray] = {}  # term columns projected off the design, as it stands (project)
        self.blocks: list[tuple] = []  # the projected columns' blocks: (terms, columns, their norms before)
        self.memo: dict[tuple, dict] = {}  # this step's statistics of each term's group (stats)
        self.spanned: set[Term] = set()  # terms the design already expresses (the model's own friction columns)
        self.Q, self.in_basis = orthonormal_basis(self.fixed), set()
        self.named = list(self.given or ()) + [c for c in self.pool if is_named(c)]
        self.tiers = [[c for c in self.named if c in self.F_all],
                      [c for c in self.pool if not is_named(c) and c in self.F_all]]
        self.declared_order: dict = {}
        for c in ([c for c in self.pool if is_named(c)] + list(self.given or ())
                  + [c for c in self.pool if not is_named(c)]):
            self.declared_order.setdefault(slot(c), (len(self.declared_order),))
        self.equivalents: list[tuple] = []

    def column(self, term: Term) -> np.ndarray:
        """``term``'s column on the data, each row weighted as the trace weighs it (:attr:`w`)."""
        return term.column(self.data, "indirect") * self.w

    def _rival(self, chosen: dict) -> dict | None:
        """The open-ended term that explains the residual better than the named law
        ``chosen`` by more than :data:`MIN_BIC_DROP` and passes every test, or ``None``:
        then the named law would be the nearest one the vocabulary has, not the right one."""
        others = [c for c in self.tiers[1] if slot(c) not in self.taken]
        if not others:
            return None
        self.project(others)
        k_now = self.fixed.shape[1] + len(self.nuisance) + len(self.accepted)
        best = max((self.stats(c, k_now, self.rss_now) for c in others), key=lambda b: b["bic_drop"])
        if not best["bic_drop"] > chosen["bic_drop"] + MIN_BIC_DROP or self.physical(best) is not None:
            return None
        ok, info = passes(best, self.held_gain, self.min_gain)
        if not ok:
            return None
        self.steps.append({**info, "rival_of": " + ".join(label(t) for t in chosen["group"])})
        return best

    def _size(self, best: dict) -> float:
        """The root mean square of the torque ``best``'s term fits, over its joints' rows."""
        column = best["coefs"][-1] * self.F_all[best["term"]]
        rows = np.zeros(self.data.dof, dtype=bool)
        rows[list(best["term"].joints)] = True
        mine = column.reshape(-1, self.data.dof)[:, rows]
        return float(np.sqrt(np.mean(mine**2)))

    def held_residuals(self, group: list[Term]) -> np.ndarray:
        """The held-out residual on each scored row with ``group``'s columns beside this step's design."""
        return self.held_fits.residuals(np.column_stack([self.F_all[t] for t in group]))

    def params(self, best: dict) -> int:
        """A term's parameters: its group's coefficients, and its shape."""
        return len(best["group"]) + (best["term"].shape is not None)

    def redundant(self, chosen: dict, other: dict, k_now: int) -> bool:
        """Whether each of the two terms adds nothing significant beside the other (a BIC
        drop of at most :data:`MIN_BIC_DROP`, residuals floored at round-off): they explain the
        same part of the residual, rather than two parts that a later step would take both of."""
        both = chosen["group"] + [t for t in other["group"] if t not in chosen["group"]]
        rss_both = max(self.beside(both, k_now)[2], self.floor * self.n_rows)
        k_both = k_now + self.params(chosen) + self.params(other)
        return all(bic(max(one["rss"], self.floor * self.n_rows), self.n_rows, k_now + self.params(one))
                   - bic(rss_both, self.n_rows, k_both)
                   <= MIN_BIC_DROP for one in (chosen, other))

    def _equivalents(self, chosen: dict, info: dict, k_now: int, rss_now: float):
        """The terms (of either tier) that pass every test, are physical, explain the same part
        of the residual as ``chosen`` (as much of it, and nothing beside it: :func:`redundant`) and
        whose held-out error differs from ``chosen``'s by no more than the standard error of the difference
        (:func:`~bench.residual.validation.paired_difference`), or both at round-off; the kept
        one by :data:`EQUIVALENCE_RULE`, its step's statistics, the others, and the JSON's entry
        (``None`` where there is none)."""
        mine = {slot(t) for t in chosen["group"]}
        others = [c for tier in self.tiers for c in tier if slot(c) not in self.taken and slot(c) not in mine]
        if not others:
            return chosen, info, [], None
        r_c = self.held_residuals(chosen["group"])
        cv_c = float(np.nanmean(r_c**2))

        def rival(best: dict):
            """``(best, its step's statistics, held-out error, standard error of the difference)``
            where ``best`` is ``chosen``'s equal on these data, else ``None``."""
            if {slot(t) for t in best["group"]} & mine or self.physical(best) is not None:
                return None
            if rss_now - best["rss"] < AS_WELL * (rss_now - chosen["rss"]):  # it explains less of the residual
                return None
            if not self.redundant(chosen, best, k_now):  # it explains something else too: another cause, not a rival
                return None
            ok, other_info = passes(best, self.held_gain, self.min_gain)
            if not ok:
                return None
            r_b = self.held_residuals(best["group"])
            cv_b = float(np.nanmean(r_b**2))
            difference, stderr = paired_difference(self.data, r_c, r_b)
            if abs(difference) <= max(stderr, SAME * max(cv_b, cv_c)) or max(cv_b, cv_c) <= self.floor:
                return best, other_info, cv_b, stderr
            return None

        self.project(t for c in others for t in self.group(c))
        singles, seen = [], set()
        for best in sorted((self.stats(c, k_now, rss_now) for c in others), key=lambda b: -b["bic_drop"]):
            if slot(best["term"]) in seen or not best["bic_drop"] > MIN_BIC_DROP:
                continue
            seen.add(slot(best["term"]))
            if not {slot(t) for t in best["group"]} & mine and self.physical(best) is None:
                singles.append(best)
        found = [x for x in map(rival, singles) if x is not None]
        if not found and self.whole(chosen["term"]) and len(singles) >= 2:
            # a law of the whole system is a sum of terms each of which others may give: the best pair stands too
            first = singles[0]
            pairs = [self.stats(b["term"], k_now, rss_now, first["group"] + b["group"])
                     for b in singles[1:PAIRED + 1]
                     if not {slot(t) for t in b["group"]} & {slot(t) for t in first["group"]}]
            pairs = [p for p in pairs if len(p["group"]) == len(first["group"]) + 1 and p["bic_drop"] > MIN_BIC_DROP]
            if pairs:
                found = [x for x in [rival(min(pairs, key=lambda p: p["rss"]))] if x is not None]
        if not found:
            return chosen, info, [], None
        return self._kept_of_equals((chosen, info, cv_c, None), found)

    def _kept_of_equals(self, chosen: tuple, found: list[tuple]):
        """Of ``chosen`` and the ``found`` terms the held-out error cannot tell from it (each ``(statistics,
        step's statistics, held-out error, standard error of the difference)``), the one kept by
        :data:`EQUIVALENCE_RULE`: it, its step's statistics, the others, and the JSON's entry."""
        every = sorted([chosen] + found, key=lambda e: (self.params(e[0]), self.declared(e[0]["term"])))
        kept = every[0][0]
        name = {id(b): " + ".join(label(t) for t in b["group"]) for b, *_ in every}
        entry = {"kept": name[id(kept)], "equivalent": [name[id(b)] for b, *_ in every if b is not kept],
                 "heldout_mse": {name[id(b)]: cv for b, _, cv, _ in every},
                 "difference_stderr": {name[id(b)]: se for b, _, _, se in found},
                 "parameters": {name[id(b)]: self.params(b) for b, *_ in every}, "rule": EQUIVALENCE_RULE}
        return kept, every[0][1], [b for b, *_ in every if b is not kept], entry

    def whole(self, term: Term) -> bool:
        """Whether ``term`` is a law of the whole system (a payload, a gravity tilt), not of one joint or pair."""
        return is_named(term) and term.place != "sensor" and EFFECTS[term.name].arity == 0

    def declared(self, term: Term) -> tuple:
        """Where ``term`` stands in the order the terms are declared in (see :data:`EQUIVALENCE_RULE`)."""
        return self.declared_order.get(slot(term), (len(self.declared_order),))

    def design(self, cands):
        cands = self.nuisance + list(cands)
        return np.column_stack([self.fixed] + [self.F_all[c][:, None] for c in cands]) if cands else self.fixed

    def held_gain(self, group: list[Term]) -> float:
        """The share of this step's held-out error (``held_fits``) that ``group``'s columns save beside the design."""
        after = self.held_fits.cv(np.column_stack([self.F_all[t] for t in group]))
        return (self.before - after) / self.before if self.before > 0 else 0.0

    def group(self, c: Term) -> list[Term]:
        """A shaped term with the other parts of the law it leads
        (:func:`bench.physics.laws.led_by`; a Stribeck hump comes with Coulomb
        and viscous friction on its joint), where those are not in the model yet."""
        law = led_by(c.name) if c.shape is not None else None
        if law is None or not law.optional:
            return [c]
        mates = [EFFECTS[n].term(c.joint, shape=c.shape if EFFECTS[n].shaped else None) for n in law.optional]
        mates = [t for t in mates if slot(t) not in self.taken]
        for t in mates:
            if t not in self.F_all:
                self.F_all[t] = self.column(t)
        return mates + [c]

    def refine(self, c: Term) -> Term:
        """``c`` with its shape at the least residual beside the accepted columns and its companions."""
        effect = EFFECTS[c.name]
        mates = self.group(c)[:-1]
        Qm = self.Q if not mates else np.hstack(
            [self.Q, orthonormal_basis(project_off(self.Q, np.column_stack([self.F_all[t] for t in mates])))])
        refined = effect.term(c.joint, shape=refined_shape(Qm, self.y - Qm @ (Qm.T @ self.y), c, self.data))
        column = self.column(refined)
        if not np.isfinite(column).all():
            return c
        self.F_all[refined] = column
        return refined

    def project(self, terms) -> None:
        """Project the columns of ``terms`` not yet projected, in one product; a column the design already
        spans (its part off it at round-off) is noted in ``spanned``. The projected columns are kept, as
        blocks, and follow the design as it grows (:meth:`extend`)."""
        new = [t for t in dict.fromkeys(terms) if t not in self.off]
        if new:
            F = np.column_stack([self.F_all[t] for t in new])
            P = np.asfortranarray(project_off(self.Q, F))  # each term's column contiguous: the fits read it whole
            self.off.update({t: P[:, i] for i, t in enumerate(new)})
            self.blocks.append((new, P, np.linalg.norm(F, axis=0)))
            self.note_spanned(new, P, self.blocks[-1][2])

    def note_spanned(self, terms: list[Term], P: np.ndarray, norms: np.ndarray) -> None:
        left = np.linalg.norm(P, axis=0) <= SPANNED * norms
        self.spanned.update(t for t, inside in zip(terms, left) if inside)

    def extend(self, G: np.ndarray) -> None:
        """The design's basis with what the columns ``G`` add (:func:`~bench.residual.basis.extend_basis`),
        and every kept projected column taken off the new basis vectors too (twice, as
        :func:`~bench.residual.basis.project_off` does), in place: a projection on the few columns a step
        adds, rather than on the whole design, and the same columns to round-off."""
        before = self.Q.shape[1]
        self.Q = extend_basis(self.Q, G)
        E = self.Q[:, before:]
        if not E.shape[1]:
            return
        for terms, P, norms in self.blocks:
            P -= E @ (E.T @ P)
            P -= E @ (E.T @ P)
            self.note_spanned(terms, P, norms)

    def beside(self, terms: list[Term], k: int):
        self.project(terms)
        return _fit_beside(self.r, np.column_stack([self.off[t] for t in terms]), k)

    def stats(self, c: Term, k_now: int, rss_now: float, g: list[Term] | None = None) -> dict:
        """The statistics of ``c``'s group (or of ``g``) beside this step's design; a term's own group's
        once a step, however many of the step's choices ask for them (they depend on the design alone)."""
        if g is None:
            key = (c, k_now, rss_now)
            if key not in self.memo:
                self.memo[key] = self._stats(c, k_now, rss_now, self.group(c))
            return self.memo[key]
        return self._stats(c, k_now, rss_now, g)

    def _stats(self, c: Term, k_now: int, rss_now: float, g: list[Term]) -> dict:
        # Frisch-Waugh-Lovell: the group's coefficients, errors and residual are those of its
        # columns' part orthogonal to the design, fitted to the design's residual
        coef, stderr, rss = self.beside(g, k_now)
        if self.spanned & set(g):  # nothing the model could already express is tried, nor a finding
            return {"term": c, "group": g, "bic_drop": -math.inf, "coef": 0.0, "stderr": math.inf,
                    "coefs": [0.0] * len(g), "stderrs": [math.inf] * len(g), "rss": rss_now}
        if len(g) > 1:  # companions the data do not support leave the law (a Stribeck law without viscous friction)
            weak = [t for t, a, e in zip(g[:-1], coef, stderr) if not abs(a) >= MIN_T * e]
            if weak:
                g = [t for t in g if t not in weak]
                coef, stderr, rss = self.beside(g, k_now)
        k_new = k_now + len(g) + (c.shape is not None)  # a shape is a parameter too
        drop = bic(rss_now, self.n_rows, k_now) - bic(rss, self.n_rows, k_new)
        if len(g) > 1:
            # a law is judged by what it adds to its companions: they compete on their own as well
            rss_mates = self.beside(g[:-1], k_now)[2]
            extra = bic(rss_mates, self.n_rows, k_new - 2) - bic(rss, self.n_rows, k_new)
            drop = drop if extra > MIN_BIC_DROP else -math.inf
        return {"term": c, "group": g, "bic_drop": drop, "coef": float(coef[-1]), "stderr": float(stderr[-1]),
                "coefs": [float(v) for v in coef[-len(g):]], "stderrs": [float(v) for v in stderr[-len(g):]], "rss": rss}

    def limit(self, c: Term, k_now: int, rss_now: float) -> dict | None:
        """The statistics of the limit law a shaped term at an end of its
        range stands for (:attr:`bench.physics.laws.Law.limits`: the first at the
        low end, the second at the high end) with the companions of the law it
        leads; ``None`` where that limit adds nothing new."""
        law = led_by(c.name)
        parts = law.limits[c.name][0 if c.shape < math.sqrt(SHAPE_LIMITS[0] * SHAPE_LIMITS[1]) else 1]
        new = [t for t in (EFFECTS[p].term(c.joint) for p in parts) if slot(t) not in self.taken and t in self.F_all]
        if not new:
            return None
        mates = [t for t in self.group(c)[:-1] if t not in new]
        return self.stats(new[-1], k_now, rss_now, mates + new)

    def physical(self, best: dict) -> tuple[Term, float, float] | None:
        """The first member of the term's group with an impossible coefficient, or ``None``."""
        for t, a, e in zip(best["group"], best["coefs"], best["stderrs"]):
            if not admissible(t, a):
                return t, a, e
        return None

    def run(self) -> Trace:
        """The steps, until one accepts nothing (or ``max_steps`` were taken, or the deadline passed)."""
        while self.max_steps is None or len(self.steps_taken) < self.max_steps:
            k_now = self.fixed.shape[1] + len(self.nuisance) + len(self.accepted)
            if self._stops_before_step():
                break
            chosen, chosen_info, inadmissible = self._step(k_now)
            if chosen is not None and now() <= self.deadline:
                chosen = self._equivalent_kept(chosen, chosen_info, k_now)
            if chosen is not None and is_named(chosen["term"]):
                self._note_rival(chosen)
            if chosen is None:
                if inadmissible is None:
                    break
                self._set_aside(inadmissible)
                continue
            self.accepted.extend(chosen["group"])
            self.steps_taken.append(chosen)
            self.taken.update(slot(t) for t in chosen["group"])
            self.rss_now = chosen["rss"]
        return Trace(self.accepted, self.steps, self.structural, self.mismatched, self.runners_up, self.equivalents,
                     self.w[:self.data.dof])

    def _stops_before_step(self) -> bool:
        """Bring the basis up to the terms taken so far and the residual up to it; whether the trace stops
        here, with its step saying why: the residual at round-off level, or the deadline passed."""
        new = [t for t in self.nuisance + self.accepted if t not in self.in_basis]
        if new:
            self.extend(np.column_stack([self.F_all[t] for t in new]))
        self.in_basis.update(new)
        self.r = self.y - self.Q @ (self.Q.T @ self.y)
        self.rss_now = float(self.r @ self.r)
        self.memo = {}
        if self.rss_now / self.n_rows <= self.floor:
            self.steps.append({"stop": "the residual is at round-off level", "residual_mse": self.rss_now / self.n_rows})
            return True
        if now() > self.deadline:
            self.steps.append({"stop": BUDGET_STOP})
            return True
        return False

    def _step(self, k_now: int):
        """One step over the tiers, the named terms first: the term it accepts and its step's entry, or the
        best term whose coefficient is impossible (a structural finding), each ``None`` where there is none.
        An impossible coefficient is not handed to a later tier's open-ended terms to mimic."""
        self.before = None
        for tier in self.tiers:
            chosen, chosen_info, inadmissible = self._pick(self._ranked(tier, k_now))
            if chosen is not None or inadmissible is not None:
                return chosen, chosen_info, inadmissible
        return None, None, None

    def _ranked(self, tier, k_now: int) -> list[dict]:
        """The statistics of the terms of ``tier`` whose slot is free, the best first, one a slot: a shaped
        term (a Stribeck velocity from a grid) stands for its best shape, the best of its slot (a physical
        one first) refined and the others of that slot dropped, all projected at once (one matrix product)."""
        self.project(t for c in tier if slot(c) not in self.taken for t in self.group(c))
        ranked = sorted((self.stats(c, k_now, self.rss_now) for c in tier if slot(c) not in self.taken),
                        key=lambda b: (self.physical(b) is not None, -b["bic_drop"]))
        seen, unique = set(), []
        for best in ranked:
            if slot(best["term"]) in seen:
                continue
            seen.add(slot(best["term"]))
            if refinable(best["term"]) and best["bic_drop"] > MIN_BIC_DROP:
                refined = self.refine(best["term"])
                if at_limit(refined.shape):  # there it is the simpler law it contains: that law stands instead
                    best = self.limit(refined, k_now, self.rss_now)
                    if best is None:
                        continue
                else:
                    best = self.stats(refined, k_now, self.rss_now)
            unique.append(best)
        return sorted(unique, key=lambda b: -b["bic_drop"])

    def _pick(self, ranked: list[dict]):
        """The step's choice among ``ranked``: the best that passes every test with a possible coefficient (and,
        where it is named and runners-up are asked for, the next that does, as its runner-up), past an
        impossible coefficient only a term that fits as well; returns the chosen term, its step's entry and
        the first term whose coefficient is impossible, each ``None`` where there is none."""
        chosen = chosen_info = inadmissible = None
        tried = 0
        for best in ranked:
            if inadmissible is not None and self.rss_now - best["rss"] < AS_WELL * (self.rss_now - inadmissible["rss"]):
                break
            if self.before is None:
                self.held_fits = FoldFits(self.design(self.accepted), self.y, self.held)
                self.before = self.held_fits.cv()
            ok, info = passes(best, self.held_gain, self.min_gain)
            impossible = self.physical(best)
            if ok and impossible is None:
                if chosen is not None:  # the runner-up: the step's choice is made
                    self.runners_up.append((chosen["group"], best["group"]))
                    self.steps.append({**info, "runner_up_of": " + ".join(label(t) for t in chosen["group"])})
                    break
                chosen, chosen_info = best, {**info, "accepted": True}
                self.steps.append(chosen_info)
                if not self.runner_up or not is_named(best["term"]):
                    break
                continue
            if ok and chosen is None:
                if inadmissible is None:
                    self.steps.append({**info, "accepted": False, "inadmissible": label(impossible[0])})
                    inadmissible = {**best, "impossible": impossible}
                continue
            if chosen is None and inadmissible is None and not tried:
                self.steps.append(info)  # the best term, rejected
            tried += 1
            if not best["bic_drop"] > MIN_BIC_DROP or tried >= MAX_TRIES:
                break  # weaker terms explain less still
        return chosen, chosen_info, inadmissible

    def _equivalent_kept(self, chosen: dict, chosen_info: dict, k_now: int) -> dict:
        """The term the step keeps where held-out data cannot tell the chosen one from others
        (:meth:`_equivalents`, by :data:`EQUIVALENCE_RULE`): the step's choice and its runner-up follow it."""
        kept, kept_info, others, entry = self._equivalents(chosen, chosen_info, k_now, self.rss_now)
        if entry is None:
            return chosen
        if kept is not chosen:
            chosen_info.update(accepted=False, equivalent_of=entry["kept"])
            self.steps.append({**kept_info, "accepted": True, "chosen_by": EQUIVALENCE_RULE})
            if self.runners_up and self.runners_up[-1][0] is chosen["group"]:
                runner = self.runners_up[-1][1]
                self.runners_up[-1] = (kept["group"], chosen["group"] if runner == kept["group"] else runner)
            chosen = kept
        self.equivalents.append((kept["group"], [b["group"] for b in others], entry))
        return chosen

    def _note_rival(self, chosen: dict) -> None:
        """Note where an open-ended term explains the residual far better than the named law ``chosen``."""
        rival = self._rival(chosen)
        if rival is not None:
            self.mismatched.append((chosen["group"], rival["term"], rival["bic_drop"] - chosen["bic_drop"],
                                    self._size(rival), math.sqrt(self.rss_now / self.n_rows)))

    def _set_aside(self, inadmissible: dict) -> None:
        """A structural finding: the term with an impossible coefficient explains its share of the residual,
        so that no admissible term mimics it, and the selection goes on for what else is there (its
        companions, a law's Coulomb part say, stay in the library)."""
        self.structural.append(inadmissible["impossible"])
        wrong = inadmissible["impossible"][0]
        self.nuisance.append(wrong)
        self.taken.add(slot(wrong))

def _fit_beside(r: np.ndarray, G: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Coefficients, standard errors and residual sum of squares of columns
    added to a design with residual ``r`` and ``k`` columns, given their part
    ``G`` orthogonal to the design (:func:`project_off`): the fit of ``r`` on ``G``."""
    if G.shape[1] == 1:  # one column: the fit in closed form
        g = G[:, 0]
        gg = float(g @ g)
        c = float(g @ r) / gg if gg > 0 else 0.0
        res = r - c * g
        rss = float(res @ res)
        se = math.sqrt(rss / max(len(r) - k - 1, 1) / gg) if gg > 0 else math.inf
        return np.array([c]), np.array([se]), rss
    coef, *_ = np.linalg.lstsq(G, r, rcond=None)
    res = r - G @ coef
    rss = float(res @ res)
    cov = np.linalg.pinv(G.T @ G) * (rss / max(len(r) - k - G.shape[1], 1))
    return coef, np.sqrt(np.clip(np.diag(cov), 0, None)), rss
