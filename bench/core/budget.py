"""A run's budget: wall-clock seconds, or a count of its method's work.

A **time budget** (``Budget(seconds=60)``) is what a benchmark compares
methods by: each gets the same wall-clock time, and what it reaches in it
depends on the machine and its load. A **work budget** (``Budget(steps=N)``)
bounds a run by the work its method does instead: gradient steps, GP
generations, solves, whatever the method counts as one step of its loop
(:class:`methods.progress.Progress`). A run under a work budget has no
wall-clock deadline and is a pure function of its seed and configuration,
so it gives the same numbers on any machine; its ``seconds``, where given,
is only a ceiling past which the run is killed and recorded as a time-out,
never a point at which it stops early with a different result.

A run under a time budget records the work it did and when it looked at
the clock (:class:`Schedule`), so that it can be replayed under a work
budget: ``Budget(steps=S, schedule=...)`` repeats the same steps, the same
evaluations of the training error and the same reading of the clock, and
ends where the original ended (``python -m bench rerun``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from bench.core.errors import ConfigError

#: seconds of a fit, a run or a residual loop where neither a budget nor a count of steps is given
DEFAULT_BUDGET_S = 60.0

#: the kinds of budget
SECONDS, STEPS = "seconds", "steps"

#: the clock every time budget is read on; the budget tests put a clock of their own here
_clock = time.perf_counter


def now() -> float:
    """Seconds on the clock that time budgets are read on (:func:`time.perf_counter`)."""
    return _clock()


@dataclass(frozen=True)
class Schedule:
    """What a time-budgeted fit did that depends on the clock, for its replay.

    Attributes
    ----------
    steps
        The steps the fit did before its time ran out (or it stopped itself).
    evaluations
        The step counts at which the fit's scheduled evaluations of its
        training error ran (the evaluations pick the state that is kept).
    clock
        ``(step, fraction, fraction per step)`` anchors: at each scheduled
        evaluation, the share of the fit's time spent and the pace since
        the previous one. Between anchors the fraction of the budget that a
        method reads (:meth:`methods.progress.Progress.fraction`) advances by
        the anchor's pace per step, so it is a function of the step count
        that a replay can repeat. ``None`` where the fit read its fraction
        from a step limit instead.
    """

    steps: int
    evaluations: tuple[int, ...]
    clock: tuple[tuple[int, float, float], ...] | None = None

    def to_json(self) -> dict:
        return {"steps": self.steps, "evaluations": list(self.evaluations),
                "clock": None if self.clock is None else [list(a) for a in self.clock]}

    @classmethod
    def from_json(cls, obj: dict) -> "Schedule":
        try:
            clock = obj.get("clock")
            return cls(int(obj["steps"]), tuple(int(s) for s in obj["evaluations"]),
                       None if clock is None else tuple((int(s), float(f), float(r)) for s, f, r in clock))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise ConfigError(f"not a replay schedule ({type(exc).__name__}: {exc})") from None


@dataclass(frozen=True)
class Budget:
    """Seconds of wall-clock time, or ``steps`` of the method's work.

    With ``steps``, ``seconds`` is an optional ceiling (``None``: none) and
    ``schedule`` replays a time-budgeted run (see the module docstring).
    """

    seconds: float | None = None
    steps: int | None = None
    schedule: Schedule | None = None

    def __post_init__(self):
        if self.steps is None and self.seconds is None:
            raise ConfigError("a budget needs seconds or steps")
        if self.seconds is not None and not (self.seconds > 0):
            raise ConfigError(f"a budget's seconds must be positive, got {self.seconds}")
        least = 0 if self.schedule is not None else 1  # a replayed fit may have ended before its first step
        if self.steps is not None and (isinstance(self.steps, bool) or not isinstance(self.steps, int) or self.steps < least):
            raise ConfigError(f"a budget's steps must be a whole number >= {least}, got {self.steps!r}")
        if self.schedule is not None and self.steps != self.schedule.steps:
            raise ConfigError("a replayed budget's steps are its schedule's")

    @classmethod
    def of(cls, seconds: float | None = None, steps: int | None = None) -> "Budget":
        """``Budget(seconds=...)`` or, with ``steps``, a work budget with ``seconds`` as its ceiling."""
        return cls(seconds=seconds, steps=steps)

    @classmethod
    def replaying(cls, schedule: Schedule, ceiling_s: float | None = None) -> "Budget":
        return cls(seconds=ceiling_s, steps=schedule.steps, schedule=schedule)

    @property
    def kind(self) -> str:
        return STEPS if self.steps is not None else SECONDS

    @property
    def fit_seconds(self) -> float:
        """The wall-clock time the method may plan for: the budget's seconds,
        or unlimited under a work budget (its ceiling is not for planning)."""
        return math.inf if self.steps is not None else float(self.seconds)

    @property
    def ceiling_s(self) -> float:
        """Seconds after which the run is killed: under a time budget the
        budget itself (callers scale it), under a work budget its ceiling."""
        return math.inf if self.seconds is None else float(self.seconds)

    def describe(self) -> str:
        if self.steps is None:
            return f"{self.seconds:g} s"
        text = f"{self.steps} steps" + (" (a replay)" if self.schedule is not None else "")
        return text + (f", at most {self.seconds:g} s" if self.seconds is not None else "")

    def scaled(self, share: float) -> "Budget":
        """``share`` of a time budget; a work budget is not divided (each
        stage that runs a method gives it the whole count)."""
        if self.steps is not None:
            return Budget(seconds=self.seconds, steps=self.steps)
        return Budget(seconds=share * self.seconds)

    def to_json(self) -> dict:
        out: dict = {"kind": self.kind}
        if self.steps is not None:
            out["steps"] = self.steps
        out["seconds" if self.steps is None else "ceiling_s"] = self.seconds
        if self.schedule is not None:
            out["schedule"] = self.schedule.to_json()
        return out

    @classmethod
    def from_json(cls, obj: dict) -> "Budget":
        if not isinstance(obj, dict) or obj.get("kind") not in (SECONDS, STEPS):
            raise ConfigError(f"not a budget: {obj!r}"[:200])
        if obj["kind"] == SECONDS:
            return cls(seconds=obj.get("seconds"))
        schedule = obj.get("schedule")
        return cls(seconds=obj.get("ceiling_s"), steps=obj.get("steps"),
                   schedule=None if schedule is None else Schedule.from_json(schedule))
