"""The long-log study: its log is a measured arm of LONG trajectories, the
last the test, each of its own seed, and its page reports from select's JSON
whether every candidate finished, the loop's rounds and the regret."""

from __future__ import annotations

import numpy as np
import pytest

from bench.runner.records import Record, record_path, write_record
from bench.runner.spec import RunSpec
from bench.studies import long_log, selection_benchmark as sb


def test_the_long_layout_is_LONG_trajectories_the_last_the_test(tmp_path, monkeypatch):
    from systems import get_system
    from systems.measured_arm import register_measured

    assert sb.LONG * sb.LONG_SECONDS * sb.RATE_HZ == pytest.approx(70_080)
    monkeypatch.setitem(sb.LOGS, "long", (sb.LONG, 0.5))
    case = sb.Case("ur5", "long", "drive", 3)
    system = get_system(register_measured(f"measured:{sb.make(case, tmp_path)}"))
    train, test = system.load("train"), system.load("test")
    per = int(0.5 * sb.RATE_HZ)
    assert train.trajectories() == [f"A{k}" for k in range(sb.LONG - 1)] and len(train) == (sb.LONG - 1) * per
    assert test.trajectories() == ["T"] and len(test) == per
    starts = [train.q[train.trajectory == name][0] for name in train.trajectories()] + [test.q[0]]
    assert len({tuple(np.round(s, 9)) for s in starts}) == sb.LONG  # each trajectory its own


def test_the_seven_layout_is_seven_training_trajectories_of_2000_samples_and_a_test(tmp_path, monkeypatch):
    from systems import get_system
    from systems.measured_arm import register_measured

    assert sb.SEVEN_SECONDS * sb.RATE_HZ == pytest.approx(2_000) and long_log.CASES["seven"].layout == "seven"
    monkeypatch.setitem(sb.LOGS, "seven", (sb.SEVEN + 1, 0.5))
    system = get_system(register_measured(f"measured:{sb.make(sb.Case('ur5', 'seven', 'drive', 3), tmp_path)}"))
    train, test = system.load("train"), system.load("test")
    assert train.trajectories() == [f"A{k}" for k in range(sb.SEVEN)] and len(train) == sb.SEVEN * 50
    assert test.trajectories() == ["T"] and len(test) == 50


def test_the_page_says_what_finished_the_loops_rounds_the_seconds_and_the_regret(tmp_path):
    def entry(name, validation, test, status="ok", work=None):
        return {"name": name, "status": status, "model": f"{name}.npz", "validation_mse": validation,
                "test_mse": test, "test_over_standard": None if test is None else test / 0.05, "work": work or {}}

    result = {"chosen": {"name": "loop"},
              "candidates": [entry("standard", 0.9, 0.05), entry("loop", 0.2, 0.008, work={"fold_steps": [2, 2, 3, 2],
                                                                                           "final_steps": 2}),
                             entry("loop+gp", 0.3, 0.007, work={"fold_steps": [2, 2, 2, 2], "final_steps": 2}),
                             entry("feasible+delan", None, None, status="timeout")]}
    for e in result["candidates"]:
        e.update(run_id=f"arm__{e['name']}__indirect__seed0__tuned", budget="2 steps, at most 900 s")
    runs = tmp_path / "runs"
    loop_spec = RunSpec(system="arm", method="loop", experiment="indirect", seed=0, steps=2, budget_s=900.0, tune=True)
    record = Record.new(loop_spec, "ok", train_mse=0.1, test_mse=0.008, fit_seconds=30.25, details={"tuning": {"search_seconds": 100.0}})
    runs_record = record_path(runs, result["candidates"][1]["run_id"])
    runs_record.parent.mkdir(parents=True)
    write_record(runs_record, record)
    s = long_log.summary(result, runs)
    assert s["status"]["feasible+delan"] == "timeout" and not s["all_ok"]
    assert s["work"]["loop"] == {"folds": [2, 2, 3, 2], "final": 2, "budget": "2 steps, at most 900 s", "seconds": 130.2}
    assert s["work"]["standard"]["seconds"] is None  # no record
    assert s["chosen"] == "loop" and s["best"] == "loop+gp" and s["regret"] == pytest.approx(0.008 / 0.007)
    text = long_log.page({"command": "c", "case": "x", "effects": ["a=1"], "noise": 0.02, "trajectories": 12,
                          "seconds": 58.4, "rate_hz": 100.0, "samples": 70080, "select": "s", "select_seconds": 60.0,
                          "cpus": 2, "select_page": "p/select.md", "summary": s})
    assert "3 of 4 candidates finished" in text and "| loop | ok | [2, 2, 3, 2] → 2 | 2 steps, at most 900 s | 130.2 |" in text
    assert "regret 1.143" in text and "70,080 samples" in text and "kept busy" not in text
    busy = long_log.page({"command": "c", "case": "x", "effects": ["a=1"], "noise": 0.02, "trajectories": 12,
                          "seconds": 58.4, "rate_hz": 100.0, "samples": 70080, "select": "s", "select_seconds": 60.0,
                          "cpus": 2, "busy": 1, "select_page": "p/select.md", "summary": s})
    assert "on 2 cores, 1 of them kept busy beside it (`yes > /dev/null`)" in busy


def test_a_select_that_fails_is_one_line_and_writes_no_page(tmp_path, monkeypatch):
    import subprocess
    from types import SimpleNamespace

    from bench.core.errors import UserError

    monkeypatch.setitem(sb.LOGS, "long", (sb.LONG, 0.2))
    monkeypatch.setattr(long_log, "CASES", {"long": sb.Case("ur5", "long", "drive", 1)})
    monkeypatch.setattr(subprocess, "run", lambda command: SimpleNamespace(returncode=2))
    out = tmp_path / "long_log.md"
    with pytest.raises(UserError, match=r"python -m bench select --system measured:.* failed; its output is above"):
        long_log.main(SimpleNamespace(out=out, busy=0, layout="long", invocation="python -m bench study long-log"))
    assert not out.exists() and not out.with_suffix(".json").exists()
