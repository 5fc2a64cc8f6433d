"""Makes the residual loop's own process hang, and leave a mark beside its
training file when it does, at the place the training file's folder is named
for: ``round0`` (round 0's fit), ``round2`` (round 2) or ``rollouts`` (the driven
rollouts after the rounds); or fail, at ``outputs`` (writing the outputs
after the rounds, with an error that is not the user's). Imported as a plugin by the budget tests, in the
loop's process (the plugins of the job's ``RunSpec``); the tests' clock reads the mark."""

from __future__ import annotations

import time
from pathlib import Path

import bench.residual.job as job
import bench.residual.loop as loop
import bench.residual.rollouts as rollouts
from bench.residual.model import Fitter

#: the mark a hanging process leaves beside its training file
MARK = "hanging"

_given_data, _round, _fit, _driven = job.given_data, loop._Loop.round, Fitter.fit, rollouts.driven_entry
_write_outputs = job.write_outputs
_where: dict[str, Path] = {}


def _hang(place: str) -> None:
    if _where.get("folder") is not None and _where["folder"].name == place:
        (_where["folder"] / MARK).write_text(place)
        time.sleep(3600)


def given_data(system, train_path, *args, **kwargs):
    _where["folder"] = Path(train_path).parent
    return _given_data(system, train_path, *args, **kwargs)


def fit(self, train):
    _hang("round0")
    return _fit(self, train)


def round_(self, k, *args, **kwargs):
    if k == 2:
        _hang("round2")
    return _round(self, k, *args, **kwargs)


def driven_entry(*args, **kwargs):
    _hang("rollouts")
    return _driven(*args, **kwargs)


def write_outputs(*args, **kwargs):
    if _where.get("folder") is not None and _where["folder"].name == "outputs":
        raise RuntimeError("the outputs could not be written")
    return _write_outputs(*args, **kwargs)


job.given_data, loop._Loop.round, Fitter.fit, rollouts.driven_entry = given_data, round_, fit, driven_entry
job.write_outputs = write_outputs
