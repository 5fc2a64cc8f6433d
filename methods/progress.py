"""A fit's progress: its deadline or step limit, the steps it counts, the
scheduled evaluations of its training error, the best state seen, and the
clock it reads, recorded so that a time-budgeted fit can be replayed.

:class:`Progress` is what a method's loop talks to (see :mod:`methods.base`).
"""

from __future__ import annotations

import math
from typing import Any, Callable

from bench.core.budget import Schedule
from bench.core.budget import now as _now


class Progress:
    """Deadline, step counting, scheduled evaluation and best-state tracking.

    The training MSE is evaluated at wall-clock times spaced so that
    evaluation takes at most ``overhead`` of the run (at least
    ``1/overhead`` times its own cost apart) and roughly geometrically
    (at least 10 % of the elapsed time apart), which gives an even curve on
    log-time axes. The state with the lowest evaluated MSE is kept.

    With a step limit the schedule counts steps instead: every step up to
    the tenth, then at least 10 % of the steps done apart, and the last
    step. Which states are compared then does not depend on the machine's
    speed or load, so a step-limited run is a pure function of its seed
    (unless the budget ends it first).

    **Replay.** Everything a method decides from the clock goes through
    this object: whether to stop (:meth:`step`), when to evaluate, and how
    much of the budget is spent (:meth:`fraction`). Under a time budget the
    fraction is read from the wall clock only at the scheduled evaluations,
    and between them it advances by the last pace per step (its
    ``clock`` anchors); :meth:`schedule` returns the steps done, the
    evaluations' steps and those anchors. Given that
    :class:`~bench.core.budget.Schedule`, a fit with the same seed repeats
    the same steps, evaluations and fractions without reading the clock,
    and so ends with the same state: ``python -m bench rerun``.

    Parameters
    ----------
    budget_s
        Wall-clock budget, counted from construction (``math.inf`` under a
        work budget).
    evaluate
        Returns the current training MSE (on the evaluation subset).
    snapshot
        Returns a copy of the current state, to be restored later.
    max_steps
        Optional step limit: the method's own ``max_steps`` or a work
        budget, whichever is smaller. The fraction of the budget spent is
        then the fraction of these steps done.
    schedule
        A time-budgeted fit's :class:`~bench.core.budget.Schedule` to
        replay: it stops after the schedule's steps and evaluates where it
        says.
    tolerance
        Stop once the best MSE falls to or below this value.
    """

    def __init__(
        self,
        budget_s: float,
        evaluate: Callable[[], float],
        snapshot: Callable[[], Any],
        *,
        max_steps: int | None = None,
        schedule: Schedule | None = None,
        tolerance: float = 0.0,
        overhead: float = 0.1,
    ):
        self.start = _now()
        self.deadline = self.start + float(budget_s)
        self._evaluate = evaluate
        self._snapshot = snapshot
        self.max_steps = max_steps  # the horizon of fraction()
        #: the most steps the loop may take: ``max_steps`` or a replay's steps
        self.work_limit = min((n for n in (max_steps, schedule and schedule.steps) if n is not None), default=None)
        self.tolerance = tolerance
        self.overhead = overhead
        self.steps = 0
        self._calls = 0
        self.best_mse = math.inf
        self.best_state: Any = None
        self.best_step = -1
        self.curve: list[tuple[float, float]] = []
        self.measured: list[float] = []  # every evaluated training MSE, in order
        self.scheduled: list[int] = []  # the steps of the scheduled evaluations (from step())
        self.eval_seconds = 0.0
        self._last_eval_cost = 0.0
        self._next_eval = self.start
        self._next_eval_step = 0
        self._evaluated_at = -1
        self._last_call = None
        self._step_time = 0.0
        self.stop_reason: str | None = None
        self._replayed = None if schedule is None else set(schedule.evaluations)
        # (step, fraction, fraction per step): read from the clock live, or replayed
        self._wall_clock = max_steps is None and schedule is None
        # the first anchor stands for the time before the first call of step()
        self.clock: list[tuple[int, float, float]] = [(-1, 0.0, 0.0)]
        if schedule is not None and schedule.clock is not None and max_steps is None:
            self.clock = [tuple(a) for a in schedule.clock]
        self._anchor = 0

    @property
    def evaluations(self) -> int:
        return len(self.measured)

    def elapsed(self) -> float:
        return _now() - self.start

    def remaining(self) -> float:
        return self.deadline - _now()

    def overrun(self) -> bool:
        """Whether the deadline has passed (never under a work budget): for a
        method whose step is long, to ask inside the step and abandon it. The
        state is then the last finished step's, and :attr:`steps` counts the
        finished steps only, so that a replay of those steps ends in the same
        state."""
        if _now() > self.deadline:
            self.stop("budget")
            return True
        return False

    def evaluate_now(self) -> float:
        value = self.measure()
        if not math.isfinite(value):
            self.stop_reason = "non-finite training loss"
        return value

    def measure(self) -> float:
        """The current state's training MSE, as one of the scheduled
        evaluations (a new lowest value keeps the state), but a non-finite
        value does not stop the loop: for a method that compares several
        states and drops the ones that failed."""
        t0 = _now()
        value = float(self._evaluate())
        cost = _now() - t0
        self._last_eval_cost = cost
        self.eval_seconds += cost
        self.measured.append(value)
        self._evaluated_at = self.steps
        if math.isfinite(value) and value < self.best_mse:
            self.best_mse = value
            self.best_state = self._snapshot()
            self.best_step = self.steps
        if math.isfinite(self.best_mse):
            self.curve.append((_now() - self.start, self.best_mse))
        now = _now()
        gap = max(cost / self.overhead, 0.1 * (now - self.start), 1e-3)
        self._next_eval = now + gap
        self._next_eval_step = self.steps + max(1, math.ceil(0.1 * self.steps))
        return value

    def _due(self, now: float) -> bool:
        if self._calls == 1:
            return True
        if self._replayed is not None:
            return self.steps in self._replayed
        return self.steps >= self._next_eval_step if self.max_steps is not None else now >= self._next_eval

    def step(self) -> bool:
        """Count one finished step; ``True`` while the loop may do another.

        The loop is stopped early enough that one more step and the final
        evaluation still fit in the budget.
        """
        now = _now()
        if self._calls:
            self.steps += 1
            took = now - self._last_call
            self._step_time = took if self.steps == 1 else max(took, 0.9 * self._step_time + 0.1 * took)
        self._calls += 1
        if self.stop_reason:
            return False
        if self._due(now):
            self.scheduled.append(self.steps)
            if self._wall_clock:
                self._read_clock(now)
            self.evaluate_now()
            now = _now()
            if self.stop_reason:
                return False
        if self.best_mse <= self.tolerance:
            self.stop_reason = "converged"
        elif self.work_limit is not None and self.steps >= self.work_limit:
            self.stop_reason = "max_steps"
        elif now + self._step_time + self._last_eval_cost >= self.deadline:
            self.stop_reason = "budget"
        self._last_call = _now()
        return self.stop_reason is None

    def _read_clock(self, now: float) -> None:
        """Anchor :meth:`fraction` at the time spent now, with the pace since the last anchor."""
        spent = (now - self.start) / max(self.deadline - self.start, 1e-9)
        step, fraction, pace = self.clock[-1]
        if step >= 0:  # the pace of the steps since the last anchor
            pace = (spent - fraction) / (self.steps - step)
        self.clock.append((self.steps, spent, pace))

    def fraction(self) -> float:
        """How much of the loop is done: of ``max_steps`` when set, else of
        the time to the deadline, as of the last scheduled evaluation and
        advanced since by its pace per step (see the class docstring)."""
        if self.max_steps is not None:
            return self.steps / self.max_steps
        now = self.steps if self._calls else -1  # -1: before the first call of step()
        while self._anchor + 1 < len(self.clock) and self.clock[self._anchor + 1][0] <= now:
            self._anchor += 1
        step, fraction, pace = self.clock[self._anchor]
        return fraction + (now - step) * pace

    def schedule(self) -> Schedule:
        """What a replay of this fit needs (see the class docstring)."""
        return Schedule(self.steps, tuple(self.scheduled), None if self.max_steps is not None else tuple(self.clock))

    def reserve(self, seconds: float) -> None:
        """Take ``seconds`` off the end of the budget (for work after the
        loop); nothing where the budget has no deadline."""
        if math.isfinite(seconds):
            self.deadline -= seconds

    def stop(self, reason: str) -> None:
        """Ask the loop to end (a method that knows it is done)."""
        self.stop_reason = self.stop_reason or reason

    def finish(self) -> None:
        """Evaluate the final state unless it was just evaluated."""
        if self._evaluated_at != self.steps and self.stop_reason != "non-finite training loss":
            self.evaluate_now()
