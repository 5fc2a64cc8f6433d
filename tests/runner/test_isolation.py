"""Isolated calls: results, phases and their limits, echoed output, and jobs run side by side."""

from __future__ import annotations


import pytest

from bench.runner.isolation import Call, CallFailed, run_call, run_jobs


def test_a_call_returns_its_result_and_echoes_its_output(tmp_path):
    lines = []
    outcome = run_call(Call("tests.runner.jobs:echo", {"x": 3}), tmp_path / "r.json", tmp_path, "echo", {"run": 60},
                       echo=lines.append)
    assert outcome.result == {"x": 3, "squared": 9} and outcome.phase == "run" and not outcome.killed
    assert "working on 3" in lines
    assert (tmp_path / "echo.call.json").is_file() and (tmp_path / "r.json").is_file()


def test_a_call_is_killed_at_its_phases_limit(tmp_path):
    outcome = run_call(Call("tests.runner.jobs:sleep", {"seconds": 60}), tmp_path / "r.json", tmp_path, "s", {"run": 0.5})
    assert outcome.killed and outcome.phase == "run" and outcome.result is None  # killed, not waited for


def test_jobs_run_side_by_side_and_those_that_did_not_finish_are_named(tmp_path):
    lines = []
    results = run_jobs("tests.runner.jobs:echo", {"a": {"x": 1}, "b": {"x": 2}}, 60, 2, lambda r: f"x^2 = {r['squared']}",
                       lines.append)
    assert results == {"a": {"x": 1, "squared": 1}, "b": {"x": 2, "squared": 4}} and list(results) == ["a", "b"]
    assert sorted(line.split("] ")[1] for line in lines) == ["a: x^2 = 1", "b: x^2 = 4"]
    assert lines[-1].startswith("[2/2, ")
    with pytest.raises(CallFailed, match="1 of 2 job.s. did not finish: slow"):
        run_jobs("tests.runner.jobs:sleep", {"quick": {"seconds": 0}, "slow": {"seconds": 60}}, 1.0, 2, str, lines.append)
    assert any("slow: did not finish (killed)" in line for line in lines)
