"""Targets for isolated calls in the runner's tests (imported by name in the child)."""

from __future__ import annotations

import time


def echo(payload, on_phase):
    on_phase("run")
    print(f"working on {payload['x']}", flush=True)
    return {"x": payload["x"], "squared": payload["x"] ** 2}


def sleep(payload, on_phase):
    on_phase("run")
    time.sleep(payload["seconds"])
    return {"slept": payload["seconds"]}
