"""A study's ledger: the jobs that finished are kept as they finish, and the
same jobs run again by the same code are taken from it instead of run again."""

from __future__ import annotations

import json

import pytest

from bench.core.errors import CallFailed
from bench.runner.schedule import run_jobs
from bench.runner.ledger import Ledger, suite_code
from tests.runner.jobs import Forked, Sleep, Tally


def test_a_study_stopped_part_way_resumes_with_the_jobs_that_did_not_finish(tmp_path):
    tally, lines = tmp_path / "tally", []
    ledger = Ledger(tmp_path / "page.md")
    assert ledger.path == tmp_path / "page.partial.jsonl" and suite_code() is not None
    with pytest.raises(CallFailed, match="1 of 2 job.s. did not finish: slow"):
        run_jobs({"quick": Tally(str(tally), 1), "slow": Sleep(60, 1.0)}, 2, str, lines.append, ledger)
    assert tally.read_text() == "1\n"

    lines.clear()
    results = run_jobs({"quick": Tally(str(tally), 1), "slow": Sleep(0, 60.0)}, 2, str, lines.append, ledger)
    assert results == {"quick": {"x": 1}, "slow": {"slept": 0}} and list(results) == ["quick", "slow"]
    assert tally.read_text() == "1\n"  # quick was not run again
    assert lines[0] == f"1 of 2 job(s) finished before, by this code: taken from {ledger.path}"
    assert [line.split("] ")[1] for line in lines[1:]] == ["slow: {'slept': 0}"] and lines[1].startswith("[1/1, ")

    # a job whose fields changed is run again, under the same name
    assert run_jobs({"quick": Tally(str(tally), 2)}, 1, str, lines.append, ledger) == {"quick": {"x": 2}}
    assert tally.read_text() == "1\n2\n"

    ledger.close()
    assert not ledger.path.exists()


def test_a_ledger_keeps_nothing_from_other_code_or_a_torn_line(tmp_path):
    tally = tmp_path / "tally"
    ledger = Ledger(tmp_path / "page.md")
    run_jobs({"a": Tally(str(tally), 1)}, 1, str, lambda line: None, ledger)
    with open(ledger.path, "a") as f:
        f.write('{"name": "b", "fields": ')  # the process killed while writing its line
    jobs = {"a": Tally(str(tally), 1), "b": Tally(str(tally), 2)}
    assert ledger.finished(jobs) == ({"a": {"x": 1}}, 0)
    (entry,) = [json.loads(line) for line in ledger.path.read_text().splitlines()[:1]]
    assert entry["code"] == suite_code() and entry["fields"] == {"job": "tests.runner.jobs:Tally",
                                                                  "fields": {"tally": str(tally), "x": 1}}

    ledger.path.write_text(json.dumps({**entry, "code": "a digest of other code"}) + "\n")
    assert ledger.finished(jobs) == ({}, 1)
    lines = []
    run_jobs({"a": Tally(str(tally), 1)}, 1, str, lines.append, ledger)
    assert tally.read_text() == "1\n1\n"
    assert lines[0] == f"1 job(s) in {ledger.path} were made by other code or with other fields: they run again"


@pytest.mark.xdist_group("dask")
def test_a_studys_jobs_run_on_a_dask_cluster_and_resume_from_the_same_ledger(tmp_path, dask_client):
    """The one scheduler hands a study's jobs to a cluster as it runs them locally: the ledger keeps what
    finished, a job killed at its limit on its worker is named, and the same jobs run again resume."""
    tally, lines = tmp_path / "tally", []
    ledger = Ledger(tmp_path / "page.md")
    with pytest.raises(CallFailed, match="1 of 2 job.s. did not finish: slow"):
        run_jobs({"quick": Tally(str(tally), 3), "slow": Sleep(60, 1.0)}, 2, str, lines.append, ledger,
                 cluster=dask_client)
    assert tally.read_text() == "3\n" and any(line.endswith("quick: {'x': 3}") for line in lines)
    assert any("slow: did not finish (killed in its run phase)" in line for line in lines)
    lines.clear()
    assert run_jobs({"quick": Tally(str(tally), 3)}, 1, str, lines.append, ledger) == {"quick": {"x": 3}}
    assert tally.read_text() == "3\n" and lines == [f"1 of 1 job(s) finished before, by this code: taken from {ledger.path}"]
    # the workers of a local cluster are not daemonic processes: a job there forks from a fork server, as it does
    # here, instead of starting a fresh interpreter
    assert run_jobs({"forked": Forked()}, 1, str, lines.append, cluster=dask_client) == {"forked": {"forked": True}}
