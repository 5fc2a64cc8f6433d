"""The residual loop keeps its budget on any machine: a round the budget ends in
is undone and the rounds before it are kept; a loop whose process is killed
returns the checkpoint that process wrote, under the limit of the phase it was
killed in; and a fit slower than expected still gives a result. The tests
control the clocks rather than rely on the machine's speed."""

from __future__ import annotations

from bench.core.budget import Budget
import re
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import bench.core.budget as budget_module
import bench.residual.loop as loop_module
import bench.residual.rollouts as rollouts_module
import bench.runner.job as runner_job
from bench.core.csv_format import write_csv
from bench.residual import residual_loop
from bench.residual.job import ResidualJob, run_residual
from bench.residual.model import Fitter
from bench.core.errors import CallFailed
from bench.runner.records import read_record, residual_fields
from tests.residual.test_loop import SYSID, data_with, quiet

ROOT = Path(__file__).resolve().parents[2]
HANG = str(ROOT / "tests" / "plugins" / "hang.py")
#: how much longer than its budget each fit takes in the slow machine's test
SLOWER = 1.6
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
    whole = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    assert whole.stopped is None and whole.effects and len(whole.rounds) >= 2
    assert whole.heldout_holds_out == "the model and its effects"
    _budget_ends_at(monkeypatch, "refitting jointly", 1)
    saved, lines = [], []
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=lines.append, checkpoint=saved.append)
    assert [r["round"] for r in out.rounds] == [0, 1]
    assert out.rounds[1]["stop"].startswith("stopped: the budget of") and "while refitting jointly" in out.stopped
    assert "round 1" in out.stopped and "the rounds before it are kept" in out.stopped
    assert out.effects == [] and out.mse_after == out.mse_before  # round 0's model, as it was
    assert any(line.startswith("round 1: stopped,") for line in lines)
    # a checkpoint after round 0, and one when the rounds ended, each the result as it stood
    assert [len(c.rounds) for c in saved] == [1, 2] and saved[-1].stopped == out.stopped
    assert all(c.rollout is None for c in saved)


def test_the_loops_progress_lines_give_no_test_figure_and_its_report_gives_each_rounds():
    """The loop chooses by its training and held-out figures; the test MSE of each round is the report's, once
    the loop has ended, and never a progress line's."""
    train, test = data_with(FRICTION, n=1000)
    lines = []
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=lines.append)
    tests = [r["mse"]["test"] for r in out.rounds]
    assert len(tests) >= 2 and all(t is not None for t in tests)
    assert lines and not [line for line in lines if re.search(r"\btest\s+[-\d.]", line)]
    assert not [line for line in lines for t in tests if f"{t:.4g}" in line]


def _jump_when_hanging(monkeypatch, folder: Path) -> None:
    """The runner's clock: the real one, until the loop's process marks that it hangs
    (tests/plugins/hang.py); from then on each reading is a day past the one before,
    so that the runner kills it at its next look, whatever the phase's limit."""
    real, mark, jumped = time.monotonic, folder / "hanging", [0.0]

    def monotonic():
        if mark.exists():
            jumped[0] += 86400.0
        return real() + jumped[0]

    monkeypatch.setattr(runner_job, "time", SimpleNamespace(monotonic=monotonic, sleep=time.sleep))


def _hanging_job(tmp_path: Path, place: str, monkeypatch) -> ResidualJob:
    """A loop on the double pendulum with friction, by work, whose process hangs at ``place``."""
    folder = tmp_path / place
    folder.mkdir()
    train, test = data_with(FRICTION, n=1000)
    n = len(test)  # test data with a recording's times, so that the loop runs its driven rollouts after the rounds
    write_csv(train, folder / "train.csv")
    write_csv(test.replace(recording=np.full(n, "r0"), trajectory=np.full(n, "b"), time=np.arange(n) * 0.01),
              folder / "test.csv")
    _jump_when_hanging(monkeypatch, folder)
    return ResidualJob.of("double_pendulum", "sysid", train_path=str(folder / "train.csv"),
                       test_path=str(folder / "test.csv"), budget_s=600.0, steps=SYSID, plugins=(HANG,),
                       json_path=str(folder / "out.json"), report_path=str(folder / "out.md"))


def test_a_loop_killed_in_a_round_returns_the_rounds_its_process_saved(monkeypatch, tmp_path):
    lines = []
    out = run_residual(_hanging_job(tmp_path, "round2", monkeypatch), lines.append)
    assert [r["round"] for r in out.rounds] == [0, 1] and out.effects and out.rollout is None
    assert out.stopped == ("the loop was still running at its ceiling of 600 s, in round 2, and was killed: the "
                           "rounds up to round 1 are kept")
    assert lines[-1] == f"stopped: {out.stopped}"
    written = residual_fields(read_record(tmp_path / "round2" / "out.json"))
    assert written["stopped"] == out.stopped and [r["round"] for r in written["rounds"]] == [0, 1]
    report = (tmp_path / "round2" / "out.md").read_text()
    assert "**Stopped early:**" in report and "![residuals" not in report  # no models: no plot


def test_a_loop_killed_in_its_driven_rollouts_keeps_every_round_under_the_rollouts_own_limit(monkeypatch, tmp_path):
    out = run_residual(_hanging_job(tmp_path, "rollouts", monkeypatch), quiet)
    assert out.rounds[-1].get("stop") is None and out.effects and out.rollout is None
    assert out.stopped == (f"the driven rollouts after the rounds were still running after "
                           f"{ResidualJob.of('double_pendulum', 'sysid', budget_s=600.0).limits()['evaluate']:g} s; killed: the result has every round and no rollouts")


def test_a_loop_killed_before_round_0_ended_has_nothing_to_return(monkeypatch, tmp_path):
    with pytest.raises(CallFailed, match="in round 0; killed"):
        run_residual(_hanging_job(tmp_path, "round0", monkeypatch), quiet)
    assert not (tmp_path / "round0" / "out.json").exists()


def test_a_fit_slower_than_expected_still_returns_the_rounds_that_finished(monkeypatch):
    # the clock moves a millisecond each time it is read, and each fit takes 1.6 x its budget on it: the loop
    # stops itself where the budget ends, with the rounds that finished, the same on any machine
    train, test = data_with(FRICTION, n=1000)
    clock = [0.0]

    def tick():
        clock[0] += 1e-3
        return clock[0]

    monkeypatch.setattr(budget_module, "_clock", tick)
    real_fit = Fitter.fit

    def slow_fit(self, data):
        began = clock[0]
        fitted = real_fit(self, data)
        clock[0] = max(clock[0], began + SLOWER * self.budget.seconds)
        return fitted

    monkeypatch.setattr(Fitter, "fit", slow_fit)
    lines = []
    out = residual_loop("sysid", train, test, budget=Budget(seconds=2.0), report=lines.append)
    last = out.rounds[-1]["round"]
    assert [r["round"] for r in out.rounds] == list(range(last + 1)) and last >= 2 and out.effects
    assert out.stopped.startswith(f"the budget of 2 s ran out in round {last}'s trace before it found anything")
    assert lines[-1].startswith(f"round {last}: the loop's budget ran out before the trace found anything")


def test_an_error_in_a_later_round_or_the_rollouts_keeps_the_rounds_that_finished(monkeypatch):
    train, test = data_with(FRICTION, n=1000)
    real_round = loop_module._Loop.round

    def round_(self, k, *args, **kwargs):
        if k == 2:
            raise RuntimeError("a term's column overflowed\nsecond line")
        return real_round(self, k, *args, **kwargs)

    monkeypatch.setattr(loop_module._Loop, "round", round_)
    lines = []
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=lines.append)
    assert [r["round"] for r in out.rounds] == [0, 1, 2] and out.effects  # round 1's laws stand
    assert out.stopped == ("round 2 failed (RuntimeError: a term's column overflowed): the round is undone, and the "
                           "rounds before it are kept")
    assert out.mse_after["test"] < out.mse_before["test"] and any(l.startswith("round 2: stopped,") for l in lines)
    monkeypatch.setattr(loop_module._Loop, "round", real_round)

    def broken(*args, **kwargs):
        raise ValueError("no windows")

    monkeypatch.setattr(rollouts_module, "driven_entry", broken)
    n = len(test)  # test data with a recording's times, so that the loop runs its driven rollouts after the rounds
    timed = test.replace(recording=np.full(n, "r0"), trajectory=np.full(n, "b"), time=np.arange(n) * 0.01)
    out = residual_loop("sysid", train, timed, budget=Budget(steps=SYSID), report=quiet)
    assert out.effects and out.rollout is None and out.mse_after["test"] < out.mse_before["test"]
    assert out.stopped == "the driven rollouts after the rounds failed (ValueError: no windows): the rounds are kept"


def test_a_loop_whose_process_fails_after_its_rounds_keeps_the_rounds_it_saved(monkeypatch, tmp_path):
    lines = []
    out = run_residual(_hanging_job(tmp_path, "outputs", monkeypatch), lines.append)
    assert len(out.rounds) >= 2 and out.effects
    assert out.stopped.startswith(f"the loop's process failed after round {out.rounds[-1]['round']} (")
    assert "the outputs could not be written" in out.stopped and lines[-1] == f"stopped: {out.stopped}"
    written = residual_fields(read_record(tmp_path / "outputs" / "out.json"))
    assert written["stopped"] == out.stopped and len(written["rounds"]) == len(out.rounds)
