"""Isolated calls: results, phases and their limits, echoed output, and jobs run side by side."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from bench.runner.isolation import Call, CallFailed, run_call
from bench.runner.job import run_isolated, run_jobs
from tests.runner.jobs import Echo, Sleep


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
    results = run_jobs({"a": Echo(1), "b": Echo(2)}, 2, lambda r: f"x^2 = {r['squared']}", lines.append)
    assert results == {"a": {"x": 1, "squared": 1}, "b": {"x": 2, "squared": 4}} and list(results) == ["a", "b"]
    assert sorted(line.split("] ")[1] for line in lines) == ["a: x^2 = 1", "b: x^2 = 4"]
    assert lines[-1].startswith("[2/2, ")
    with pytest.raises(CallFailed, match="1 of 2 job.s. did not finish: slow"):
        run_jobs({"quick": Sleep(0, 60.0), "slow": Sleep(60, 1.0)}, 2, str, lines.append)
    assert any("slow: did not finish (killed in its run phase)" in line for line in lines)


def test_a_job_is_made_again_from_its_fields_in_its_own_process_and_finishes_in_the_callers(tmp_path):
    lines = []
    assert run_isolated(Echo(5), tmp_path, "five", echo=lines.append) == {"x": 5, "squared": 25}
    assert "working on 5" in lines and (tmp_path / "five.call.json").is_file()
    with pytest.raises(CallFailed, match="killed in its run phase"):
        run_isolated(Sleep(60, 0.5))


def test_the_fork_server_is_reaped_when_its_caller_exits_so_its_runs_cpu_is_the_callers(tmp_path):
    """The caller's exit ends the fork server and waits for it: the server does not outlive it, and the CPU the
    server and the runs forked from it used joins the caller's children's (what ``time`` and ``getrusage`` read),
    where before it was lost with a server that ended after its caller."""
    script = f"""
import os, resource, sys
from multiprocessing import forkserver
from bench.runner import isolation
assert isolation.fork_server() is not None
out = isolation.run_call(isolation.Call("tests.runner.jobs:echo", {{"x": 2}}), {str(tmp_path / "r.json")!r},
                         {str(tmp_path)!r}, "echo", {{"run": 600}})
assert out.result == {{"x": 2, "squared": 4}}
pid = forkserver._forkserver._forkserver_pid
before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime
isolation._stop_fork_server(os.getpid())
after = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime
print(pid, os.path.exists(f"/proc/{{pid}}"), before, after, forkserver._forkserver._forkserver_pid)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])})
    assert done.returncode == 0, done.stderr
    pid, exists, before, after, left = done.stdout.split()
    assert exists == "False" and left == "None"  # reaped: no process, not even a zombie, and nothing to reap again
    assert float(after) > float(before)  # the server imported torch and the suite: its CPU is now the caller's
