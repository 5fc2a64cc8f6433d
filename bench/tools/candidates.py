"""The candidates of ``bench select`` (:mod:`bench.tools.select`): each one's method, configuration and work.

Its own module, which imports no method, so that the command line names them in ``bench select --help``
and checks ``--candidates`` before the methods are imported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import methods
from bench.core.errors import UserError


@dataclass(frozen=True)
class Candidate:
    """A candidate: its name on the page, the method, its configuration and the hyperparameters it fixes.
    :attr:`work` is the steps its final fit does where ``--steps`` is not given (its fold fits do the same,
    :mod:`bench.evaluation.tuning`); select's seconds are then only a ceiling, past which it is killed.
    ``start`` is when its run starts among the others, the lowest first (:func:`bench.tools.select.run`): the longest runs first
    (the loop's rounds on every fold; then the searches of the learned residuals; the records of
    results/measured/select_default say how long each took), so that two workers end close together. ``loop+gp``
    starts after them: its prior is the loop's model on each fold, which the ``loop`` candidate's fits share
    through the runs' folder (:func:`methods.hybrid.share_priors`), so that it does not run the rounds again."""

    name: str
    method: str
    profile: str = "default"
    fixed: tuple[tuple[str, object], ...] = ()
    start: int = 0
    #: passes over the training samples its fits make at least (0: its ``work`` alone), in the batches of the
    #: learned residual ``learner`` (a method's name: its default ``batch_size`` samples a step)
    epochs: float = 0.0
    learner: str | None = None

    @property
    def work(self) -> int:
        """The work its method declares (:attr:`methods.base.Method.work`)."""
        return methods.METHODS[self.method].work

    def steps(self, samples: int | None) -> int:
        """The steps of its fits on ``samples`` training samples: ``work``, or more where ``epochs`` passes over
        them in the learner's batches take more (an iterative fit's work grows with the data)."""
        if not self.epochs or not samples:
            return self.work
        batch = methods.METHODS[self.learner].Config().batch_size
        return max(self.work, math.ceil(self.epochs * samples / batch))


#: the passes over the training samples the GP's steps make of the KUKA's 4,926 (in its batches of 512),
#: rounded down: on a longer log its fits make as many passes, and so more steps. The networks keep their
#: steps: as many passes (5,019 steps on 64,240 samples) put the MLP's and DeLaN's searches past select's
#: ceiling on the long-log study's log with one core busy beside them (bench select at bf81cac)
GP_EPOCHS = 3.0

#: the candidates, in the page's order; the closed-form fits (SysId, sparse regression) are one step
CANDIDATES = (
    Candidate("standard", "sysid", "standard", start=9),
    Candidate("feasible", "sysid", "feasible", start=8),
    Candidate("standard+gp", "standard+gp", start=5, epochs=GP_EPOCHS, learner="gp"),
    Candidate("feasible+gp", "feasible+gp", start=4, epochs=GP_EPOCHS, learner="gp"),
    Candidate("standard+mlp", "standard+mlp", start=2),
    Candidate("feasible+delan", "feasible+delan", start=3),
    Candidate("feasible+sparse_torque", "feasible+sparse_torque", start=7),
    Candidate("loop", "loop", start=0),
    Candidate("loop_feasible", "loop", "feasible", start=1),
    Candidate("loop+gp", "loop+gp", start=6, epochs=GP_EPOCHS, learner="gp"),
)


WORDS = {1: "one", 2: "two"}


def named_candidates(names: list[str], at_least: int = 1) -> tuple[str, ...]:
    """``names`` in :data:`CANDIDATES`' order, each once (``--candidates``); a :class:`UserError` in one line
    where one is not a candidate or fewer than ``at_least`` are named."""
    known = [c.name for c in CANDIDATES]
    unknown = [n for n in names if n not in known]
    if unknown or len(set(names)) < at_least:
        said = "unknown candidate(s) " + ", ".join(unknown) if unknown else f"{WORDS[at_least]} at least"
        raise UserError(f"--candidates: {said}; select's are {', '.join(known)}")
    return tuple(n for n in known if n in names)
