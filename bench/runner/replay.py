"""Replaying a recorded run with the work it did (``python -m bench rerun``).

A run under a work budget is replayed by running its spec again. A run
under a time budget is replayed under the work budget its record gives
(a tuned run: the hyperparameters its search chose, and its final fit's work)
(``replay``: the steps it reached, the steps of its evaluations and its
reading of the clock, :class:`~bench.core.budget.Schedule`), with the same
data, seed and configuration. Either way the replay repeats the fit step for
step, and its train and test MSE equal the record's up to round-off
(:data:`RELATIVE_TOLERANCE`) on a machine with the same arithmetic.
"""

from __future__ import annotations

import dataclasses
import math

from bench.core.budget import STEPS, Schedule
from bench.core.errors import UserError
from bench.runner.plugins import code_plugins, plugin_digest, plugin_key
from bench.runner.records import Record
from bench.runner.spec import RunSpec

#: the largest relative difference of an MSE that counts as round-off (float64)
RELATIVE_TOLERANCE = 1e-9
#: the same for a run trained with other seeds as one stacked model (``run --stack-seeds``), replayed
#: alone: its batched products round differently, which a float32 fit carries into its MSE
#: (tests/runner/test_matrix.py checks stacked records against one-by-one ones to this)
STACKED_TOLERANCE = 1e-6


def tolerance(record: Record) -> float:
    """The relative difference of the MSEs that counts as round-off when ``record`` is replayed alone."""
    return STACKED_TOLERANCE if (record.details or {}).get("stacked") else RELATIVE_TOLERANCE


def replay_spec(record: Record, source: str = "record", ceiling_s: float | None = None) -> RunSpec:
    """The spec that repeats ``record``'s run; :class:`UserError` naming
    ``source`` where it cannot be replayed. ``ceiling_s`` bounds the replay's
    fit (``None``: no bound; a replay on a slower machine takes longer)."""
    if record.status != "ok":
        raise UserError(f"{source}: the run's status is {record.status}; only an ok run has numbers to repeat")
    if not record.spec:
        raise UserError(f"{source}: the record has no spec to run again")
    spec = RunSpec.from_dict(record.spec)
    if record.budget_kind == STEPS:
        return dataclasses.replace(spec, budget_s=ceiling_s)
    replay = record.replay
    if replay is None:
        raise UserError(f"{source}: the record was written before runs recorded the work they did; it cannot be replayed")
    if "unavailable" in replay:
        raise UserError(f"{source}: {record.method} cannot be replayed: {replay['unavailable']}")
    schedule = Schedule.from_json(replay)
    if spec.tune:  # the search read the clock: its choice is replayed, and the final fit step for step
        chosen = (record.details.get("tuning") or {}).get("chosen", {})
        spec = dataclasses.replace(spec, tune=False, hyperparameters={**spec.hyperparameters, **chosen})
    return dataclasses.replace(spec, budget_s=ceiling_s, steps=schedule.steps, schedule=schedule.to_json())


def check_plugins(record: Record, given: list[str], source: str = "record") -> None:
    """A :class:`UserError` naming ``source`` unless ``given`` (the user's ``--plugin``) names every plugin the
    record's run imported that runs code, each the same file as the run's (its sha256, where the record holds it;
    a record made before records held it is taken on the user's naming): a record is data, and the code it names
    runs only where the user names it too."""
    spec = record.spec or {}
    needed = code_plugins(spec.get("plugins") or ())
    if not needed:
        return
    named = {plugin_key(p) for p in given}
    missing = [p for p in needed if plugin_key(p) not in named]
    if missing:
        raise UserError(f"{source}: its run imported the plugin(s) {', '.join(missing)}, which run code; a rerun "
                        f"imports them only where you name them too: "
                        + " ".join(f"--plugin {p}" for p in missing))
    recorded = (record.code or {}).get("plugins") or {}
    for plugin in needed:
        want, now = recorded.get(plugin), plugin_digest(plugin)
        if want is not None and now != want:
            raise UserError(f"{source}: plugin {plugin} is not the file its run imported (sha256 "
                            f"{(now or 'none')[:12]}, the record's {want[:12]}); the replay would run other code")


def relative_difference(a: float | None, b: float | None) -> float:
    """``|a - b| / max(|a|, |b|)``; 0 where both are equal or both absent, inf where one is."""
    if a is None or b is None:
        return 0.0 if a is b else math.inf
    if a == b:
        return 0.0
    return abs(a - b) / max(abs(a), abs(b))


def compare(recorded: Record, replayed: Record) -> list[tuple[str, float | None, float | None, float]]:
    """``(what, recorded, replayed, relative difference)`` for the train and test MSE."""
    return [(name, getattr(recorded, name), getattr(replayed, name),
             relative_difference(getattr(recorded, name), getattr(replayed, name)))
            for name in ("train_mse", "test_mse")]
