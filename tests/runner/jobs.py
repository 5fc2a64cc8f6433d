"""Jobs for the runner's tests (made again from their fields, by name, in the child)."""

from __future__ import annotations

import time
from dataclasses import dataclass

from bench.runner.job import Job


def echo(payload, on_phase):
    on_phase("run")
    print(f"working on {payload['x']}", flush=True)
    return {"x": payload["x"], "squared": payload["x"] ** 2}


def sleep(payload, on_phase):
    on_phase("run")
    time.sleep(payload["seconds"])
    return {"slept": payload["seconds"]}


@dataclass(frozen=True)
class Echo(Job):
    """:func:`echo` as a job, under a limit of 60 s."""

    x: int

    def limits(self):
        return {"run": 60.0}

    def run(self, on_phase):
        return echo({"x": self.x}, on_phase)


@dataclass(frozen=True)
class Sleep(Job):
    """:func:`sleep` as a job, killed after ``limit`` seconds."""

    seconds: float
    limit: float

    def limits(self):
        return {"run": self.limit}

    def run(self, on_phase):
        return sleep({"seconds": self.seconds}, on_phase)


@dataclass(frozen=True)
class Tally(Job):
    """Adds a line to the file ``tally`` each time it runs, and returns ``x``."""

    tally: str
    x: int

    def limits(self):
        return {"run": 60.0}

    def run(self, on_phase):
        on_phase("run")
        with open(self.tally, "a") as f:
            f.write(f"{self.x}\n")
        return {"x": self.x}


@dataclass(frozen=True)
class Forked(Job):
    """Whether it runs in a process forked from the fork server, which imported :mod:`bench.runner.preload`
    before forking (a fresh interpreter has not imported it)."""

    def limits(self):
        return {"run": 60.0}

    def run(self, on_phase):
        import sys

        on_phase("run")
        return {"forked": "bench.runner.preload" in sys.modules}
