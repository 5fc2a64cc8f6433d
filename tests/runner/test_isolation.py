"""Isolated calls: results, phases and their limits, echoed output, and jobs run side by side."""

from __future__ import annotations

import os
from multiprocessing import forkserver
from pathlib import Path

import pytest

from bench.runner.isolation import stop_fork_server
from bench.core.errors import CallFailed
from bench.runner.job import run_isolated, run_watched
from bench.runner.schedule import run_jobs
from tests.runner.jobs import Echo, Sleep


def test_a_jobs_process_returns_its_result_and_echoes_its_output(tmp_path):
    lines = []
    outcome = run_watched(Echo(3), tmp_path, "echo", echo=lines.append)
    assert outcome.result == {"x": 3, "squared": 9} and outcome.phase == "run" and not outcome.killed
    assert "working on 3" in lines
    assert (tmp_path / "echo.call.json").is_file() and (tmp_path / "echo.result.json").is_file()


def test_a_jobs_process_is_killed_at_its_phases_limit(tmp_path):
    outcome = run_watched(Sleep(60, 0.5), tmp_path, "s")
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


def test_the_fork_server_is_reaped_when_its_caller_exits_so_its_runs_cpu_is_the_callers():
    """The caller's exit ends its fork server and waits for it (here a server of the test's own, so that the
    suite's stays): the server does not outlive it, and the CPU the server and the runs forked from it used
    joins the caller's children's (what ``time`` and ``getrusage`` read), where before it was lost with a server
    that ended after its caller."""
    server = forkserver.ForkServer()
    server.set_forkserver_preload([])
    server.ensure_running()
    pid = server._forkserver_pid
    stop_fork_server(os.getpid() + 1, server)  # not the process that started it (a forked copy): nothing
    assert server._forkserver_pid == pid and Path(f"/proc/{pid}").exists()
    stop_fork_server(os.getpid(), server)
    assert server._forkserver_pid is None and not Path(f"/proc/{pid}").exists()  # gone, not even a zombie
    with pytest.raises(ChildProcessError):
        os.waitpid(pid, os.WNOHANG)  # reaped here: its CPU and its children's are this process's children's
