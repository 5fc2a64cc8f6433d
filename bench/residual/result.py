"""The residual loop's typed result (:func:`bench.residual.loop.residual_loop`) and the record of each of its rounds."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from bench.physics.models import FittedModel
from bench.runner.provenance import Provenanced
from bench.runner.records import Record, residual_fields, residual_record


@dataclass(frozen=True)
class ResidualResult(Provenanced):
    """What the loop found. On disk it is a :class:`~bench.runner.records.Record`
    of kind ``residual`` (:meth:`to_json`, :func:`~bench.runner.records.residual_record`):
    the record's own fields where it has them (the Lagrangian is its
    ``expression``, ``seconds`` its ``fit_seconds``), the rest in its
    ``details``; that is the JSON of ``python -m bench residual --json``.
    :meth:`from_json` reads it, and the loop's JSON as it was written before
    (every field at the top). ``spec`` is the run's
    :class:`~bench.runner.spec.RunSpec` as JSON (``None`` for a loop run
    outside a job: the record makes one from the system, method, seed and
    budget), ``code`` the hash of the code that ran it
    (:func:`bench.runner.sources.code_hash`).

    ``validation`` says how held-out data were formed (:mod:`bench.residual.validation`);
    ``mse_heldout_trajectories`` is the cross-validated torque MSE before and
    after the loop, over held-out trajectories (or spans of one), where the
    training data name two or more recordings (files published before the
    key was named for trajectories call it ``mse_heldout_recordings``, and
    :meth:`from_json` reads either). ``sensor_laws_offered`` names the laws
    of the sensor and the drive the loop looked for on the training data (a
    time shift needs time stamps).
    ``mass_matrix`` gives the smallest eigenvalue of ``d^2 L / dqd^2`` over
    the training states checked, before and after, and whether the final
    model's is positive definite there. ``statistics_seconds`` is the part of
    ``seconds`` spent in the loop's statistics: the trace, pruning (with its
    refits), and the held-out, mass-matrix and standard-error checks.
    ``budget`` is the loop's budget, seconds or steps of work
    (:meth:`bench.core.budget.Budget.to_json`); under a work budget
    ``budget_s`` is its ceiling (``None``: none) and ``fit_budget_s`` is ``None``.
    ``feasibility`` says, for a model of rigid bodies (SysId on an arm),
    whether its inertial parameters are a rigid body's before and after the
    loop (:func:`bench.physics.feasible.feasibility_of`): the masses and each
    body's smallest pseudo-inertia eigenvalue; ``None`` for other models.
    ``rollout`` gives, where the test data name their recordings' times
    (measured data), the driven rollouts of the test recordings before and
    after the loop (:func:`bench.evaluation.driven.driven_entry`).
    ``stopped`` says where the time budget ended the loop before it ended by
    itself (a round not started, a round undone when the budget ran out in
    it, or the process killed), else ``None``. ``loop_seconds`` is the time of
    the fit and the rounds, the part the budget bounds; ``rollout_seconds``
    that of the driven rollouts after them.
    ``per_joint`` gives the test error per joint and per test trajectory
    before and after the loop (:func:`bench.evaluation.per_joint.per_joint`:
    MSE and nMSE, against the logged torque too for a measured system's own
    data); ``None`` without test data or models.
    ``models`` holds the fitted models before and after the loop, for the
    report's residual plots; it is not part of the JSON.
    """

    system: str | None
    method: str
    mse_before: dict
    mse_after: dict
    effects: list[dict]
    rounds: list[dict]
    lagrangian: str | None
    seconds: float
    budget_s: float | None
    fit_budget_s: float | None
    seed: int
    train_source: str
    test_source: str | None
    validation: str = ""
    mse_heldout_trajectories: dict | None = None
    mass_matrix: dict | None = None
    statistics_seconds: float | None = None
    budget: dict | None = None
    provenance: dict = field(default_factory=dict)
    feasibility: dict | None = None
    rollout: dict | None = None
    #: where the method's fits trained (:func:`bench.core.devices.describe`)
    device: dict | None = None
    #: what the result was made from (:meth:`bench.residual.job.ResidualJob.inputs`): the command
    #: line, the ``--set`` values, the configuration and every hyperparameter of the method, and
    #: each data file's sha256 with the settings ``convert`` made it with
    inputs: dict | None = None
    stopped: str | None = None
    #: what the held-out errors hold out (:meth:`bench.residual.strategies.Strategy.holds_out`)
    heldout_holds_out: str | None = None
    loop_seconds: float | None = None
    rollout_seconds: float | None = None
    sensor_laws_offered: list[str] | None = None
    #: the loop worked on every ``thinned``-th sample of each training recording (:data:`bench.residual.loop.MAX_SAMPLES`)
    thinned: int = 1
    per_joint: dict | None = None
    #: why the rounds ended (:meth:`bench.residual.loop._Loop.rounds`): ``reason`` (``nothing_significant``,
    #: ``budget``, ``undone``, ``redundant``, ``failed`` or ``max_rounds``), the ``round`` and a ``detail``;
    #: where the last round was undone or stopped, the laws it had ``found`` (each with its trace's held-out
    #: gain), its ``heldout_mse`` where it got that far, and under a time budget ``budget_needed_s``
    ending: dict | None = None
    #: the kept rounds' laws that the data could not tell from others: per round, the law ``kept``, the
    #: ``equivalent`` ones, each one's held-out error with the kept one's standard error, and the rule that chose
    equivalent_laws: list | None = None
    #: what the final model leaves of the training torques: ``train``, its residual's sum of squares over the
    #: torques' about each joint's mean, pooled over the joints, and ``per_joint``, each joint's
    #: (:meth:`bench.residual.loop._Loop.unexplained`)
    unexplained: dict | None = None
    spec: dict | None = None
    code: dict | None = None
    models: tuple[FittedModel, FittedModel] | None = field(default=None, repr=False, compare=False)

    def to_record(self) -> Record:
        return residual_record({f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "models"})

    def to_json(self) -> dict:
        return self.to_record().to_json()

    @classmethod
    def from_json(cls, obj: dict, source: str = "the residual loop's result") -> "ResidualResult":
        """The result in a record's JSON (or in the loop's JSON as it was written before it was a record);
        :class:`~bench.runner.records.RecordError` naming ``source`` otherwise."""
        fields = residual_fields(Record.from_json(obj, source), source)
        if isinstance(fields.get("rounds"), list):
            fields["rounds"] = [renamed(r) for r in fields["rounds"]]
        return cls(**fields)


def renamed(round_):
    """A round of the JSON with the keys the loop wrote before a term of its library was called a term
    (``candidate_heldout_mse``; a trace step's ``candidate``) under today's names."""
    if not isinstance(round_, dict):
        return round_
    out = {("undone_heldout_mse" if k == "candidate_heldout_mse" else k): v for k, v in round_.items()}
    if isinstance(out.get("trace"), list):
        out["trace"] = [{("term" if k == "candidate" else k): v for k, v in step.items()}
                        if isinstance(step, dict) else step for step in out["trace"]]
    return out


@dataclass
class Round:
    """One round of the loop, as its JSON gives it (fields that are ``None`` are left out).

    ``accepted`` names the effects the trace added, ``removed`` those the
    refit made redundant or impossible, ``simplified`` each law replaced by a
    simpler one it contains, and why, ``trace`` the statistics of each step;
    ``stop`` says why the loop ended here (undone, not started, the budget);
    ``undone_heldout_mse`` is an undone round's held-out error; round 0 has
    ``method_mse`` (the method's own model, before its strategy's start) and
    ``cross_fit`` (a kept fit's cross-fits) where those apply.
    """

    round: int
    mse: dict
    heldout_mse: float
    accepted: list[str] = field(default_factory=list)
    trace: list[dict] = field(default_factory=list)
    removed: list[str] | None = None
    stop: str | None = None
    undone_heldout_mse: float | None = None
    method_mse: dict | None = None
    cross_fit: dict | None = None
    simplified: list[str] | None = None
    seconds: float = 0.0
    #: laws of this round that the held-out error could not tell apart (:attr:`~bench.residual.tracing.Trace.equivalents`)
    equivalent: list[dict] | None = None

    def to_json(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}
