"""The residual loop: find what a fitted model lacks, add it, refit, repeat.

Round 0 fits; each later round traces, adds, refits and keeps or undoes.
What differs between kinds of fitted model (how round 0 starts, what the
model can already express, how it is refitted with effects, and what else
can undo a round) is the model's refit strategy, chosen once from the model
(:mod:`bench.residual.strategies`); the loop asks the strategy.

1. **Fit** (round 0 only). The method is fitted on the training torques
   (indirect experiment) with the system's declared model only; then its
   strategy starts the loop (:meth:`~bench.residual.strategies.Strategy.start`):
   a parametric model's parameters are polished by nonlinear least squares,
   so that an optimiser's shortfall is not taken for a physical effect
   (``mse_before`` is the polished model's, and round 0 records the
   method's own as ``method_mse``); a kept fit is cross-fitted.
2. **Residual.** ``r = tau - g(L_hat) - Phi c`` on the training and test sets.
3. **Trace.** Forward stepwise selection (:mod:`bench.residual.tracing`)
   over the terms of its library (:mod:`bench.residual.library`): the named
   effects on every joint, those of the whole system (a payload, a gravity
   tilt), the laws of the torque sensor (a gain, a time shift:
   :mod:`bench.residual.sensors`, their columns linearised at the model) and
   an open-ended library of terms of ``L`` and ``D``. The named
   effects are tried first at each step. Terms are judged beside the
   model's own freedom (:meth:`~bench.residual.strategies.Strategy.freedom`),
   so a term the model could already express gains nothing.
4. **Add** the accepted effects: conservative ones to the Lagrangian
   (armature ``+c qd^2/2``, spring ``-c q^2/2``, open-ended ``L`` terms),
   dissipative ones through the Rayleigh function ``D`` (torque ``dD/dqd``:
   viscous friction ``c qd^2/2``, Coulomb and Stribeck friction, drag), an
   offset as a generalized force.
5. **Refit jointly**, without fitting the method again
   (:meth:`~bench.residual.strategies.Strategy.refit`), the sensor's laws
   applied exactly to the training data (:meth:`~bench.residual.choosing.Choosing.choose`); where the
   trace's linearisation may have ranked two terms wrongly, or an
   open-ended term explained the residual far better than the named law it
   accepted, both are refitted and the lower BIC kept. Effects made
   redundant by the refit are dropped again (backward elimination on the
   BIC, :func:`~bench.residual.pruning.prune`), shaped effects' parameters
   refined, each law replaced by the simplest law it contains that the data
   do not tell apart from it, with at most one law of each physical family
   on a joint (:func:`~bench.residual.pruning.simplest_laws`), and effects
   the refit made impossible dropped. Then an effect the data do not
   identify, or one that claims beyond them (an open-ended term, a spring
   whose rest angle the arm never visited) without earning its place on a
   held-out trajectory, is dropped and reported as a finding
   (:mod:`bench.residual.beyond_data`). The JSON reports the effects as laws
   (:mod:`bench.physics.laws`).
6. **Keep the round only if it generalises.** The round's model is scored by
   cross-validation over whole trajectories (:mod:`bench.residual.validation`:
   leave one trajectory out, regions of the states of the one trajectory the
   training data hold, or contiguous blocks of independent samples); a round
   that does not lower that held-out error is undone and the loop ends (on
   trajectories it must lower it by :data:`~bench.residual.criteria.MIN_HELDOUT_GAIN`,
   pooled over the joints or on average with each joint's error in its own
   units, as the trace weighs each joint's rows), so
   the final model is never worse than the starting one on held-out data. A strategy may undo a round too (a
   kept fit's effects must also lower, on each half, the error of the method
   fitted on the other half). Each round records the figure
   (``heldout_mse``). A round after which the mass matrix ``d^2 L / dqd^2``
   of the model with its effects is no longer positive definite at the
   training states (:data:`~bench.residual.checks.MASS_STATES` of them) is
   undone too; a fitted model whose own mass matrix is not is reported as such.
7. **Repeat** until a round accepts nothing, for at most :data:`MAX_ROUNDS`
   rounds. A round whose every law became a finding (step 5) leaves the model
   as it was and is not undone: the findings are not offered again, and the
   next round traces without them.

The budget's seconds bound the whole loop (under a work budget, its steps,
nothing below depends on time: see :func:`residual_loop`), in the shares of
:mod:`bench.residual.limits`: the method's fit has
:data:`FIT_SHARE` of it, each cross-fit of a kept fit :data:`CROSS_FIT_SHARE`,
the polish stops starting new starts at :data:`POLISH_SHARE`, a round starts
only if the time it is expected to take (the longest round so far) still
fits in the budget, and tracing starts no new step after :data:`TRACE_SHARE`
of it.

:func:`residual_loop` runs the loop in this process and returns a
:class:`~bench.residual.result.ResidualResult`; :mod:`bench.residual.job`
runs it through the runner, in its own process.
"""

from __future__ import annotations

import contextlib
import dataclasses
import traceback
from typing import Callable

import numpy as np

from bench.core.budget import DEFAULT_BUDGET_S, Budget, now
from bench.core.data import Dataset, mse
from bench.core.errors import first_line
from bench.physics.models import FittedModel
from bench.physics.terms import TermLibrary, remembered_columns, share_columns
from bench.residual.library import describe_all, is_named, loop_library, label, resolved_periods, structural
from bench.residual.choosing import Choosing
from bench.residual.checks import MASS_STATES, heldout, heldout_by_joint, smallest_mass_eigenvalue
from bench.residual.model import Fitter, LoopModel
from bench.residual.pruning import shape_stderr
from bench.residual.result import ResidualResult, Round
from bench.residual.rollouts import driven_rollouts, test_mse
from bench.residual.criteria import MIN_HELDOUT_GAIN
from bench.residual.limits import CROSS_FIT_SHARE, FIT_SHARE, MAX_ROUNDS, POLISH_SHARE, TRACE_SHARE
from bench.residual.tracing import BUDGET_STOP, Trace, trace
from bench.residual.sensors import Sensed, Sensor, column as sensor_column
from bench.residual.strategies import MAX_SYMBOLIC_TERMS, Start, strategy_for
from bench.residual.tidying import Tidying
from bench.residual.validation import describe as describe_validation
from bench.runner.progress import Report
from bench.runner.provenance import device_entry, provenance
from systems import SYSTEMS


#: the training samples the loop works on at most: a longer log is thinned to every k-th sample of each
#: recording (:meth:`bench.core.data.Dataset.thinned`), so that a round's statistics, which grow with the
#: rows, stay bounded. Chosen on training data alone: on the long log the loop ends with the same laws from
#: at most 4,096, 8,192 and 16,384 samples (results/residual/loop_speed.md, ``python -m bench study
#: loop-speed``), and the shipped arms' logs (the KUKA's 4,926 training samples, the DFKI pendulum's 3,800)
#: and the geared arm's (4,000) are not thinned
MAX_SAMPLES = 8192


def not_started(budget_s: float) -> str:
    """The ``stop`` of a round the loop did not start because the time budget ``budget_s`` would end first."""
    return f"the budget of {budget_s:g} s would be spent before a round ended"


def residual_loop(method: str, train: Dataset, test: Dataset | None, *, budget: Budget | None = None, seed: int = 0,
                  hyperparameters: dict | None = None, report: Report = print,
                  fitted: FittedModel | None = None, open_ended: bool | None = None,
                  device: str = "cpu", checkpoint: Callable[[ResidualResult], None] | None = None,
                  on_phase: Callable[[str], None] | None = None, max_rounds: int = MAX_ROUNDS) -> ResidualResult:
    """Run the loop in this process; see the module docstring.

    ``budget``'s seconds bound the whole loop (its method's fit has
    :data:`FIT_SHARE` of them; default :data:`DEFAULT_BUDGET_S`). With
    steps the loop is bounded by work instead, and the seconds are
    only recorded, as the ceiling its caller kills it at: the fit
    and each cross-fit do that many steps of the method's work, the polish
    all its starts, the trace until nothing is significant, and at most
    ``max_rounds`` (default :data:`MAX_ROUNDS`) rounds run, so that the result
    does not depend on the machine's speed. ``fitted`` is an already fitted instance of
    ``method`` to start from instead of round 0's fit (for instance a model
    fitted before the system changed). Each round records ``seconds``, the
    time since the loop began. ``device`` is where a torch method's fits
    train (:mod:`bench.core.devices`); the loop's own work is on the CPU.

    A round still running when the time budget ends is undone, and the loop
    ends with the rounds that finished (:attr:`ResidualResult.stopped` says
    where). ``checkpoint``, where given, receives the result as it stands
    (without driven rollouts) after round 0, after every later round and
    once the rounds end, so that a caller that must kill the loop still has
    the rounds that finished. ``on_phase`` is told ``"evaluate"`` when the
    rounds end and the work after them (the driven rollouts of the test
    recordings) begins: that work is not charged to the budget.
    """
    budget = budget or Budget(seconds=DEFAULT_BUDGET_S)
    train, thinned = train.thinned(MAX_SAMPLES)
    if thinned > 1:
        report(f"the loop works on one sample in {thinned} of each training recording, {len(train)} samples: "
               f"neighbouring samples are near copies, and its statistics grow with the rows (at most {MAX_SAMPLES})")
    with remembered_columns(train, test):  # each term's and effect's columns once, for every round
        loop = _Loop(method, train, test, budget, seed, dict(hyperparameters or {}),
                     report, open_ended, device)
        loop.thinned, loop.max_rounds = thinned, min(int(max_rounds), MAX_ROUNDS)
        loop.checkpoint, loop.on_phase = checkpoint or (lambda result: None), on_phase or (lambda phase: None)
        return loop.run(fitted)


class _BudgetSpent(Exception):
    """The loop's time budget ended during a round (the message says in which of its stages)."""


class _Loop(Tidying, Choosing):
    """One run of the loop: its data, budget, strategy and running figures; the choice of a round's model is
    :class:`~bench.residual.choosing.Choosing`'s, what follows its joint refit
    :class:`~bench.residual.tidying.Tidying`'s."""

    def __init__(self, method: str, train: Dataset, test: Dataset | None, budget: Budget, seed: int,
                 hyperparameters: dict, report: Report, open_ended: bool | None, device: str = "cpu"):
        self.method, self.train, self.test, self.budget, self.seed = method, train, test, budget, seed
        # the measured training data; ``train`` is what the sensor's laws found so far make of them
        self.measured, self.sensor = train, Sensor.exact(train)
        self.stack = contextlib.ExitStack()  # the corrected training data's remembered columns
        self.report, self.open_ended = report, open_ended
        self.horizon = budget.fit_seconds  # the loop's time (unlimited under a work budget)
        self.checkpoint, self.on_phase = (lambda result: None), (lambda phase: None)
        self.stopped: str | None = None  # where the budget ended the loop early
        self.ending: dict = {}  # why the rounds ended (ResidualResult.ending)
        self.pending: dict = {}  # what the running round has found so far: its laws, then its held-out error
        self.round_began = 0.0  # when the running round began (bench.core.budget.now)
        self.equivalent: list[dict] = []  # the kept rounds' laws that the data could not tell from others
        self.fit_seconds, self.fit_scales = 0.0, False  # the method's fit, and whether a longer budget lengthens it
        self.fitter = Fitter(method, seed, budget.scaled(FIT_SHARE), hyperparameters, device)
        self.start = now()
        self.beyond: dict[str, tuple] = {}  # effects dropped for claiming beyond the data: label -> (term, entry)
        self.unnamed: dict[str, dict] = {}  # open-ended terms taken where a named law was only the nearest: label -> entry
        self.thinned = 1  # the loop works on one training sample in this many (residual_loop)
        self.max_rounds = MAX_ROUNDS  # the most rounds it runs (residual_loop)
        self.statistics = 0.0  # seconds in the trace, pruning and the held-out and mass-matrix checks
        # the share of the held-out error a round must save: on trajectories, whose held-out spans are not
        # independent of the rest, what each round must (a smaller gain is a fit to the one motion)
        self.round_gain = MIN_HELDOUT_GAIN if train.trajectories() else 0.0

    def timed(self, fn, *args, **kwargs):
        t0 = now()
        try:
            return fn(*args, **kwargs)
        finally:
            self.statistics += now() - t0

    def scores(self, model: FittedModel) -> dict:
        """Torque MSEs in the measured torque's units: the model read through the sensor."""
        model = Sensed(model, self.sensor)
        return {"train": mse(model.predict_torque(self.measured), self.measured.tau),
                "test": None if self.test is None else test_mse(model, self.test)}

    def unexplained(self, model: FittedModel) -> dict:
        """The share of the measured training torques' variance that ``model``, read through the sensor, leaves:
        pooled over the joints (``train``) and each joint's (``per_joint``)."""
        tau = self.measured.tau
        left = np.sum((Sensed(model, self.sensor).predict_torque(self.measured) - tau) ** 2, axis=0)
        total = np.maximum(np.sum((tau - tau.mean(axis=0)) ** 2, axis=0), 1e-300)
        return {"train": float(left.sum() / total.sum()), "per_joint": [float(x) for x in left / total]}

    def heldout(self, model: LoopModel, train: Dataset | None = None, sensor: Sensor | None = None) -> float:
        """:func:`~bench.residual.checks.heldout` in the measured torque's units."""
        sensor = self.sensor if sensor is None else sensor
        train = self.train if train is None else train
        return heldout(self.strategy, model, train, sensor.factor(train))

    def heldout_by_joint(self, model: LoopModel, train: Dataset | None = None, sensor: Sensor | None = None) -> np.ndarray:
        """:func:`~bench.residual.checks.heldout_by_joint` in the measured torque's units, as :meth:`heldout`."""
        sensor = self.sensor if sensor is None else sensor
        train = self.train if train is None else train
        return heldout_by_joint(self.strategy, model, train, sensor.factor(train))

    def pays_in_joint_units(self, model: LoopModel, proposed: LoopModel, proposed_held: float, held: float,
                            before_round: tuple) -> bool:
        """Whether a round whose held-out error falls by less than ``round_gain`` pooled still pays: it falls
        pooled, and by ``round_gain`` with each joint's held-out error in its own units (over its error
        before the round, as the trace weighs each joint: :func:`~bench.residual.criteria.joint_weights`),
        averaged over the joints. On a geared arm a wrist's rotor inertia is half of the wrist's error
        and a fraction of a percent of the pooled one."""
        if not self.round_gain or not proposed_held < held:
            return False
        before, after = self.heldout_by_joint(model, *before_round), self.heldout_by_joint(proposed)
        kept = before > 0
        return bool(kept.any()) and float(np.mean(after[kept] / before[kept])) < 1 - self.round_gain

    def use(self, train: Dataset, sensor: Sensor) -> None:
        """Fit from now on to ``train``, the measured data as ``sensor`` corrects them;
        their columns are remembered (shared with the measured data's where the states are theirs)."""
        if train is not self.train:
            if not share_columns(train, self.measured):
                self.stack.enter_context(remembered_columns(train))
        self.train, self.sensor = train, sensor

    def elapsed(self) -> float:
        return round(now() - self.start, 3)

    def in_budget(self, stage: str) -> None:
        """Raise :class:`_BudgetSpent` where the loop's time budget has ended
        (never under a work budget), naming ``stage``, the part of the round
        that was running."""
        if now() - self.start > self.horizon:
            raise _BudgetSpent(stage)

    def run(self, fitted: FittedModel | None) -> ResidualResult:
        with self.stack:
            return self._run(fitted)

    def _run(self, fitted: FittedModel | None) -> ResidualResult:
        train, report, budget = self.train, self.report, self.budget
        given = fitted is not None  # a given fit was made on other data: what it leaves here is out of sample
        if fitted is None:
            share = "" if budget.kind == "steps" else f" of the loop's {budget.seconds:g} s"
            report(f"round 0: fitting {self.method} on {len(train)} samples with the declared model only "
                   f"({self.fitter.budget.describe()}{share})")
            fitted = self.fitter.fit(train)
            info = getattr(fitted, "fit_info", {}) or {}
            self.fit_seconds = float(info.get("fit_seconds") or 0.0)
            self.fit_scales = budget.kind == "seconds" and info.get("stop_reason") == "budget"
        else:
            report(f"round 0: starting from the given {self.method} fit")
        strategy = self.strategy = strategy_for(fitted)
        self.trained_on = fitted.trained_on() if hasattr(fitted, "trained_on") else "cpu"
        context = Start(self.seed, self.fitter, dataclasses.replace(self.fitter, budget=budget.scaled(CROSS_FIT_SHARE)),
                        given, self.start + POLISH_SHARE * self.horizon, report)
        model, started = strategy.start(fitted, train, context)
        first, before = model, self.scores(model)
        held = self.timed(self.heldout, model)
        mass = mass_before = self.timed(smallest_mass_eigenvalue, model, train)
        if not mass > 0:
            report(f"round 0: {self.method}'s mass matrix is not positive definite on the training data "
                   f"(smallest eigenvalue {mass:.4g}): a finding about the fitted model")
        rounds = [Round(0, before, held, method_mse=None if "method_model" not in started
                        else self.scores(started["method_model"]), cross_fit=started.get("cross_fit"),
                        seconds=self.elapsed())]
        split = describe_validation(train)
        # the progress lines give the figures the loop chooses by; the test MSE of each round is the report's,
        # once the loop has ended
        report(f"round 0: torque MSE train {before['train']:.4g}; "
               f"held out ({split}; it holds out {strategy.holds_out()}) {held:.4g}")
        self.first, self.before, self.mass_before = first, before, mass_before
        self.feasible_before = strategy.feasibility(model, train)
        self.save(model, held, mass, rounds, {})
        model, held, mass, findings = self.rounds(model, held, mass, rounds)
        loop_seconds = self.elapsed()
        self.on_phase("evaluate")
        result = dataclasses.replace(self.result(model, held, mass, rounds, findings), loop_seconds=loop_seconds)
        self.checkpoint(result)
        if self.test is not None and self.test.time is not None and self.test.recording is not None:
            result = driven_rollouts(result, first, model, self.sensor, self.test, report)
        return dataclasses.replace(result, seconds=round(now() - self.start, 2), models=(first, Sensed(model, self.sensor)))

    def result(self, model: LoopModel, held: float, mass: float, rounds: list[Round], findings: dict) -> ResidualResult:
        """The result as it stands with ``model`` as the loop's model (no driven rollouts)."""
        train, budget, strategy = self.train, self.budget, self.strategy
        bound = model.rigid.expression_terms_bound()  # SyReNets' full equation is never built
        expr = model.expression() if bound is None or bound <= MAX_SYMBOLIC_TERMS else None
        feasible_after = strategy.feasibility(model, train)
        return ResidualResult(
            system=train.system, method=self.method, mse_before=self.before, mse_after=self.scores(model),
            effects=describe_all(model.effects, model.coef, model.stderr, self.timed(shape_stderr, strategy, model, train))
            + self.sensor.entries(train.dof) + list(findings.values()) + list(self.unnamed.values())
            + [entry for _, entry in self.beyond.values()],
            rounds=[r.to_json() for r in rounds], validation=describe_validation(train), thinned=self.thinned,
            mass_matrix={"smallest_eigenvalue_before": self.mass_before, "smallest_eigenvalue_after": mass,
                         "positive_definite": mass > 0, "states": min(MASS_STATES, len(train))},
            mse_heldout_trajectories={"before": rounds[0].heldout_mse, "after": held} if len(train.recordings()) >= 2 else None,
            lagrangian=None if expr is None else str(expr),
            seconds=round(now() - self.start, 2), statistics_seconds=round(self.statistics, 2),
            budget_s=budget.seconds, fit_budget_s=self.fitter.budget.seconds if budget.kind == "seconds" else None,
            device=device_entry(self.trained_on),
            budget=budget.to_json(), seed=self.seed, train_source=train.source,
            test_source=None if self.test is None else self.test.source, provenance=provenance(),
            feasibility=None if self.feasible_before is None else {"before": self.feasible_before, "after": feasible_after},
            stopped=self.stopped, heldout_holds_out=strategy.holds_out(), ending=self.ending or None,
            equivalent_laws=self.equivalent or None, unexplained=self.unexplained(model),
            sensor_laws_offered=list(dict.fromkeys(t.name for t in Sensor.exact(self.measured).terms(self.measured))),
        )

    def save(self, model: LoopModel, held: float, mass: float, rounds: list[Round], findings: dict) -> None:
        """Hand the result as it stands to the checkpoint (see :func:`residual_loop`)."""
        self.checkpoint(self.result(model, held, mass, rounds, findings))

    def library(self) -> TermLibrary:
        """The terms this loop tries (:func:`~bench.residual.library.loop_library`), less periodic parts whose
        period the data do not resolve and, where they are off, the open-ended terms."""
        train = self.train
        system = SYSTEMS[train.system]() if train.system in SYSTEMS else None
        pool = [t for t in loop_library(train.dof, coupled=bool(getattr(system, "absolute_angles", False)), system=system)
                if resolved_periods(t, train)]
        return TermLibrary([t for t in pool if is_named(t) or self.open_ended is not False])

    def rounds(self, model: LoopModel, held: float, mass: float, rounds: list[Round]):
        """Rounds 1 to :attr:`max_rounds`; returns the final model, its held-out
        error and mass-matrix eigenvalue, and the structural findings."""
        report = self.report
        pool, findings, longest = self.library(), {}, 0.0
        for k in range(1, self.max_rounds + 1):
            began = now()
            if began - self.start + longest >= self.horizon:
                rounds.append(Round(k, self.scores(model), held, stop=not_started(self.budget.seconds),
                                    seconds=self.elapsed()))
                self.stopped = (f"round {k} not started: the budget of {self.budget.seconds:g} s would be spent "
                                f"before it ended")
                report(f"round {k}: not started, the budget of {self.budget.seconds:g} s would be spent before it ended")
                self.ending = {"reason": "budget", "round": k, "detail": self.stopped, "found": [],
                               "budget_needed_s": {"at_least": round(began - self.start + longest, 1),
                                                   "estimate": "the time spent so far and the longest round's"}}
                break
            before_round = (self.train, self.sensor, dict(self.beyond), dict(self.unnamed))
            self.pending, self.round_began = {}, began
            try:
                model, held, mass, findings, done = self.round(k, model, held, mass, pool, rounds)
            except Exception as exc:  # the budget ran out, or the round failed: the rounds before it stand
                self.use(*before_round[:2])
                self.beyond, self.unnamed = before_round[2], before_round[3]
                if isinstance(exc, _BudgetSpent):
                    why = f"the budget of {self.budget.describe()} ran out in round {k}, while {exc}"
                    self.ending = {"reason": "budget", "round": k, "detail": why, **self.pending,
                                   "budget_needed_s": self.needed(began)}
                else:
                    traceback.print_exc()  # to the loop's log
                    why = f"round {k} failed ({type(exc).__name__}: {first_line(exc)})"
                    self.ending = {"reason": "failed", "round": k, "detail": why, **self.pending}
                self.stopped = f"{why}: the round is undone, and the rounds before it are kept"
                rounds.append(Round(k, self.scores(model), held, stop=f"stopped: {self.stopped}", seconds=self.elapsed()))
                report(f"round {k}: stopped, {self.stopped}")
                done = True
            longest = max(longest, now() - began)
            if done:
                break
            self.save(model, held, mass, rounds, findings)
        else:
            self.ending = {"reason": "max_rounds", "detail": f"the loop ran its {self.max_rounds} rounds"}
        return model, held, mass, findings

    def needed(self, began: float) -> dict:
        """A lower bound on the time budget that would have let the round that began at
        ``began`` finish: the loop had run this long when the budget ended inside it, and
        where the method's fit stopped on its share of the budget, a larger budget
        lengthens the fit too (:data:`FIT_SHARE`)."""
        spent, so_far = now() - self.start, now() - began
        bound = max(spent, (spent - self.fit_seconds) / (1 - FIT_SHARE)) if self.fit_scales else spent
        return {"more_than": round(bound, 1), "round_seconds_so_far": round(so_far, 1),
                "estimate": f"a lower bound: the round had run {so_far:.1f} s and not finished"
                            + (f", and the method's fit takes {FIT_SHARE:.0%} of any time budget" if self.fit_scales else "")}

    def round(self, k: int, model: LoopModel, held: float, mass: float, pool: TermLibrary, rounds: list[Round]):
        """Round ``k`` from ``model``; appends its :class:`Round` to ``rounds`` and
        returns the loop's model, its held-out error and smallest mass-matrix
        eigenvalue, the structural findings, and whether the loop ends here
        (nothing found, the round undone, or nothing it added kept). Raises
        :class:`_BudgetSpent` where the time budget ends before the round does."""
        traced, laws, findings = self.traced(k, model, pool)
        if not traced.accepted:
            rounds.append(Round(k, self.scores(model), held, trace=traced.steps, seconds=self.elapsed()))
            self.nothing_found(k, model, traced)
            return model, held, mass, findings, True
        self.pending = {"found": [{"law": step["term"], **{key: step.get(key) for key in
                                                               ("coefficient", "bic_drop", "heldout_gain")}}
                                  for step in traced.steps if step.get("accepted")],
                        "equivalent": [entry for _, _, entry in traced.equivalents]}
        self.in_budget("tracing")
        accepted = [label(c) for c in traced.accepted]
        self.report(f"round {k}: adding {', '.join(accepted)}; refitting jointly")
        before_round, refused_before = (self.train, self.sensor), set(self.beyond)
        proposed = self.choose(model, traced, laws, k)
        self.in_budget("refitting jointly")
        proposed, removed, simplified = self.tidy(proposed, findings)
        made = _Proposal(k, traced, accepted, removed, simplified, before_round)
        ends = self.unchanged(made, refused_before)
        if ends is not None:  # nothing of the round is left to score: the model is the one before it
            self.use(*before_round)
            rounds.append(made.round(self.scores(model), held, self.elapsed()))
            return model, held, mass, findings, ends
        proposed_held, proposed_mass, undo = self.judged(model, proposed, held, mass, before_round)
        if undo is not None:
            self.use(*before_round)
            rounds.append(made.round(self.scores(model), held, self.elapsed(), f"undone: {undo[0]}", proposed_held))
            self.report(f"round {k}: undone, {undo[1]}")
            self.ending = {"reason": "undone", "round": k, "detail": f"round {k} was undone: {undo[0]}", **self.pending}
            return model, held, mass, findings, True
        return (proposed, proposed_held, proposed_mass, findings,
                self.kept(made, self.scores(proposed), proposed_held, rounds))

    def traced(self, k: int, model: LoopModel, pool: TermLibrary):
        """Round ``k``'s trace of what ``model`` leaves (:func:`~bench.residual.tracing.trace`), the sensor's
        laws offered beside the library's terms; returns the trace, those laws' columns and the structural
        findings it made."""
        strategy, train, sensor = self.strategy, self.train, self.sensor
        target, fixed = strategy.problem(model, train)
        excluded = model.effects + [term for term, _ in self.beyond.values()]
        laws = {t: sensor_column(t, model, train, sensor) for t in sensor.terms(train) if t not in excluded}
        traced = self.timed(trace, target, train, pool, fixed, exclude=excluded, max_steps=strategy.trace_steps,
                            deadline=self.start + TRACE_SHARE * self.horizon, given=laws,
                            runner_up=not strategy.fixed_freedom)
        findings = {}  # what is left unexplained where the loop ends
        for term, c, se in traced.structural:
            findings[label(term)] = structural(term, c, se)
            self.report(f"round {k}: structural finding: {findings[label(term)]['finding']}")
        return traced, laws, findings

    def nothing_found(self, k: int, model: LoopModel, traced: Trace) -> None:
        """The loop's ending where round ``k``'s trace accepted nothing: its budget ran out in the trace, or no
        law passed every test, said with the share of the torques' variance the model leaves."""
        if any(step.get("stop") == BUDGET_STOP for step in traced.steps):
            self.stopped = (f"the budget of {self.budget.describe()} ran out in round {k}'s trace before it found "
                            f"anything significant (no step of it starts after {TRACE_SHARE:.0%} of the budget); "
                            f"a larger budget may find more")
            self.report(f"round {k}: the loop's budget ran out before the trace found anything significant; "
                        f"a larger budget may find more")
            self.ending = {"reason": "budget", "round": k, "detail": self.stopped, "found": [],
                           "budget_needed_s": self.needed(self.round_began)}
            return
        left = self.unexplained(model)
        self.report(f"round {k}: nothing significant left: no law passes every test, and the model leaves "
                    f"{left['train']:.0%} of the training torques' variance")
        self.ending = {"reason": "nothing_significant", "round": k,
                       "detail": f"round {k}'s trace found no term that passes every test"}

    def unchanged(self, made: "_Proposal", refused_before: set) -> bool | None:
        """Whether the loop ends (``True``) or goes on (``False``) where the joint refit left nothing of the
        round to score: every law it found became a finding, which the trace does not offer again (the next
        round traces without them), or the refit dropped every law it found and simplified nothing; ``None``
        where something is left."""
        k, accepted, removed = made.k, made.accepted, made.removed
        refused = set(accepted) & (self.beyond.keys() - refused_before)
        if refused and not set(accepted) - set(removed):
            self.report(f"round {k}: every law it found is a finding, not offered again; the next round traces "
                        f"without them")
            return False
        if set(removed) == set(accepted) and not made.simplified:
            self.report(f"round {k}: every effect it added became redundant in the joint refit; stopping")
            self.ending = {"reason": "redundant", "round": k,
                           "detail": f"every effect round {k} added became redundant in the joint refit", **self.pending}
            return True
        return None

    def judged(self, model: LoopModel, proposed: LoopModel, held: float, mass: float, before_round: tuple):
        """The refitted model ``proposed`` scored on held-out data and its mass matrix, and why the round is
        undone (the JSON's words, then the progress line's), or ``None``: a mass matrix no longer positive
        definite, a held-out error that does not fall by :attr:`round_gain` (pooled, or in each joint's own
        units: :meth:`pays_in_joint_units`), or the strategy's own check."""
        train = self.train
        proposed_held = self.timed(self.heldout, proposed)
        self.pending["heldout_mse"] = {"before": held, "with_them": proposed_held}
        proposed_mass = self.timed(smallest_mass_eigenvalue, proposed, train)
        self.in_budget("scoring the refitted model on held-out data")
        if mass > 0 and not proposed_mass > 0:
            undo = (f"with these effects the mass matrix is not positive definite on the training data "
                    f"(smallest eigenvalue {proposed_mass:.4g})",
                    f"the mass matrix would not be positive definite (smallest eigenvalue {proposed_mass:.4g})")
        elif not proposed_held < (1 - self.round_gain) * held and not self.timed(
                self.pays_in_joint_units, model, proposed, proposed_held, held, before_round):
            undo = ("the refitted model does not lower the held-out error"
                    + (f" by {self.round_gain:.0%}, as each round must on trajectories" if self.round_gain else ""),
                    f"held-out MSE {proposed_held:.4g} is not below {(1 - self.round_gain) * held:.4g}")
        else:
            undo = self.timed(self.strategy.check, proposed, model, train)
        return proposed_held, proposed_mass, undo

    def kept(self, made: "_Proposal", s: dict, proposed_held: float, rounds: list[Round]) -> bool:
        """Keep the round's model (its training and test MSEs ``s``, its held-out error ``proposed_held``):
        append its :class:`Round` and its equivalent laws; whether the loop ends here, every effect it added
        having become redundant."""
        k = made.k
        rounds.append(made.round(s, proposed_held, self.elapsed()))
        for entry in made.equivalent or ():
            self.equivalent.append({"round": k, **entry})
            self.report(f"round {k}: equivalent on these data: {' ≡ '.join([entry['kept'], *entry['equivalent']])}; "
                        f"kept {entry['kept']} by {entry.get('chosen_by', entry['rule'])}")
        if not set(made.accepted) - set(made.removed):
            self.report(f"round {k}: every effect it added became redundant; stopping")
            self.ending = {"reason": "redundant", "round": k,
                           "detail": f"every effect round {k} added became redundant in the joint refit"}
            return True
        self.report(f"round {k}: torque MSE train {s['train']:.4g}, held out {proposed_held:.4g}")
        return False


@dataclasses.dataclass(frozen=True)
class _Proposal:
    """Round ``k``'s laws as its trace found them (``accepted``) and its joint refit left them (``removed``,
    ``simplified``), with the training data and sensor before it (``before_round``)."""

    k: int
    traced: Trace
    accepted: list
    removed: list
    simplified: list
    before_round: tuple

    @property
    def equivalent(self) -> list | None:
        return [entry for _, _, entry in self.traced.equivalents] or None

    def round(self, s: dict, held: float, seconds: float, stop: str | None = None,
              undone_heldout: float | None = None) -> Round:
        """The :class:`Round` of this proposal, its MSEs ``s`` and held-out error ``held``."""
        return Round(self.k, s, held, self.accepted, self.traced.steps, self.removed, stop, undone_heldout,
                     simplified=self.simplified or None, seconds=seconds, equivalent=self.equivalent)
