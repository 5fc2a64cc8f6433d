"""The residual loop keeps its budget on any machine: a round the budget ends in
is undone and the rounds before it are kept, a killed loop returns its last
checkpoint, and a fit slower than expected still gives a result."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import bench.residual.job as job_module
import bench.residual.loop as loop_module
from bench.residual import residual_loop
from bench.residual.job import ResidualJob, run_residual
from bench.runner.isolation import CallFailed, Outcome
from tests.commandline import cli
from tests.residual.test_loop import SYSID, data_with, quiet

ROOT = Path(__file__).resolve().parents[2]
FRICTION = {"viscous_friction": (0.8, 0.5), "coulomb_friction": (1.5, 0.7)}


def _budget_ends_at(monkeypatch, when: str, round_: int):
    """Make the budget end at the ``round_``-th time the loop asks at stage ``when``
    (under a work budget, so that everything else is the same on any machine)."""
    asked = []

    def in_budget(self, stage):
        asked.append(stage)
        if stage == when and asked.count(when) == round_:
            raise loop_module._BudgetSpent(stage)

    monkeypatch.setattr(loop_module._Loop, "in_budget", in_budget)
    return asked


def test_a_round_the_budget_ends_in_is_undone_and_the_rounds_before_it_are_kept(monkeypatch):
    train, test = data_with(FRICTION, n=1000)
    whole = residual_loop("sysid", train, test, steps=SYSID, report=quiet)
    assert whole.stopped is None and whole.effects and len(whole.rounds) >= 2
    assert whole.heldout_holds_out == "the model and its effects"
    _budget_ends_at(monkeypatch, "refitting jointly", 1)
    saved, lines = [], []
    out = residual_loop("sysid", train, test, steps=SYSID, report=lines.append, checkpoint=saved.append)
    assert [r["round"] for r in out.rounds] == [0, 1]
    assert out.rounds[1]["stop"].startswith("stopped: the budget of") and "while refitting jointly" in out.stopped
    assert "round 1" in out.stopped and "the rounds before it are kept" in out.stopped
    assert out.effects == [] and out.mse_after == out.mse_before  # round 0's model, as it was
    assert any(line.startswith("round 1: stopped,") for line in lines)
    # a checkpoint after round 0, and one when the rounds ended, each the result as it stood
    assert [len(c.rounds) for c in saved] == [1, 2] and saved[-1].stopped == out.stopped
    assert all(c.rollout is None for c in saved)


def _killed_in(phase: str, checkpoint: dict | None):
    """A ``run_call`` whose child left ``checkpoint`` and was killed in ``phase``."""

    def run_call(call, result_file, work, name, limits, echo=None):
        if checkpoint is not None:
            Path(call.payload["checkpoint_path"]).write_text(json.dumps(checkpoint))
        return Outcome(None, phase, killed=True)

    return run_call


def test_a_killed_loop_returns_the_rounds_that_finished_with_where_it_stopped(monkeypatch, tmp_path):
    train, test = data_with(FRICTION, n=1000)
    saved = []
    residual_loop("sysid", train, test, steps=SYSID, report=quiet, checkpoint=saved.append)
    job = ResidualJob("double_pendulum", "sysid", budget_s=10.0, json_path=str(tmp_path / "out.json"),
                      report_path=str(tmp_path / "out.md"))
    lines = []
    monkeypatch.setattr(job_module, "run_call", _killed_in("loop", saved[1].to_json()))
    out = run_residual(job, lines.append)
    assert "was still running at 1.5 x its budget of 10 s, in round 2, and was killed" in out.stopped
    assert "the rounds up to round 1 are kept" in out.stopped and lines[-1] == f"stopped: {out.stopped}"
    written = json.loads((tmp_path / "out.json").read_text())
    assert written["stopped"] == out.stopped and [r["round"] for r in written["rounds"]] == [0, 1]
    report = (tmp_path / "out.md").read_text()
    assert "**Stopped early:**" in report and "![residuals" not in report  # no models: no plot
    assert not (tmp_path / "out_residuals.png").exists()
    # killed in the driven rollouts: every round, no rollouts
    monkeypatch.setattr(job_module, "run_call", _killed_in("evaluate", saved[-1].to_json()))
    out = run_residual(job, quiet)
    assert out.rounds == saved[-1].to_json()["rounds"] and out.rollout is None
    assert out.stopped.startswith("the driven rollouts after the rounds were still running after 120 s")
    # killed before round 0 ended: nothing to return
    monkeypatch.setattr(job_module, "run_call", _killed_in("loop", None))
    with pytest.raises(CallFailed, match="in round 0; killed"):
        run_residual(job, quiet)


def test_a_fit_slower_than_expected_still_returns_the_rounds_that_finished(tmp_path):
    # the fit takes 1.4 x its half of the budget, so the rounds have less than a third of it: the loop
    # returns the rounds that finished in time, and where the budget ended it early it says where. How
    # many rounds finish depends on the machine; that a result comes back does not
    for name, n, seed in (("train", 1000, 0), ("test", 500, 1000)):
        r = cli("data", "--system", "double_pendulum", "--n", str(n), "--seed", str(seed),
                "--out", str(tmp_path / f"{name}.csv"), "--effects", "viscous_friction=0.8,0.5", "coulomb_friction=1.5,0.7")
        assert r.returncode == 0, r.stderr
    r = cli("residual", "--system", "double_pendulum", "--method", "slow_sysid", "--plugin",
            str(ROOT / "tests" / "plugins" / "slow.py"), "--train", str(tmp_path / "train.csv"),
            "--test", str(tmp_path / "test.csv"), "--budget", "2", "--json", str(tmp_path / "out.json"),
            "--report", str(tmp_path / "out.md"))
    assert r.returncode == 0, r.stdout + r.stderr
    out = json.loads((tmp_path / "out.json").read_text())
    assert out["rounds"][0]["round"] == 0 and (tmp_path / "out.md").is_file()
    finished = out["rounds"][-1].get("stop") is None and "nothing significant left" in r.stdout
    assert finished or (f"stopped early: {out['stopped']}" in r.stdout and "the budget of 2 s" in out["stopped"])


def test_an_error_in_a_later_round_or_the_rollouts_keeps_the_rounds_that_finished(monkeypatch):
    train, test = data_with(FRICTION, n=1000)
    real_round = loop_module._Loop.round

    def round_(self, k, *args, **kwargs):
        if k == 2:
            raise RuntimeError("a term's column overflowed\nsecond line")
        return real_round(self, k, *args, **kwargs)

    monkeypatch.setattr(loop_module._Loop, "round", round_)
    lines = []
    out = residual_loop("sysid", train, test, steps=SYSID, report=lines.append)
    assert [r["round"] for r in out.rounds] == [0, 1, 2] and out.effects  # round 1's laws stand
    assert out.stopped == ("round 2 failed (RuntimeError: a term's column overflowed): the round is undone, and the "
                           "rounds before it are kept")
    assert out.mse_after["test"] < out.mse_before["test"] and any(l.startswith("round 2: stopped,") for l in lines)
    monkeypatch.setattr(loop_module._Loop, "round", real_round)

    def broken(*args, **kwargs):
        raise ValueError("no windows")

    monkeypatch.setattr(loop_module, "driven_entry", broken)
    n = len(test)  # test data with a recording's times, so that the loop runs its driven rollouts after the rounds
    timed = test.replace(recording=np.full(n, "r0"), trajectory=np.full(n, "b"), time=np.arange(n) * 0.01)
    out = residual_loop("sysid", train, timed, steps=SYSID, report=quiet)
    assert out.effects and out.rollout is None and out.mse_after["test"] < out.mse_before["test"]
    assert out.stopped == "the driven rollouts after the rounds failed (ValueError: no windows): the rounds are kept"
