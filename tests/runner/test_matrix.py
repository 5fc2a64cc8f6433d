"""The harness: process isolation, timeouts, failures, records, resuming."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from bench.evaluation.scores import MAX_EXPRESSION_CHARS, clip
from bench.runner import job, matrix, run
from bench.runner.run import execute, load_data, make_system, preflight, raised
from bench.runner.isolation import fork_server
from bench.runner.progress import print_now, quiet
from bench.runner.spec import RunSpec, build_specs
from bench.runner.records import SCHEMA, Record, read_record, read_records, record_path
from methods.saving import load_model
from tests.commandline import cli

PLUGIN = str(Path(__file__).resolve().parents[1] / "plugins" / "faulty.py")


def specs(methods, experiments=("indirect",), seeds=(0,), budget=1.0, **kw):
    kw.setdefault("n_train", 64)
    kw.setdefault("n_test", 32)
    return build_specs(["double_pendulum"], methods, experiments, seeds, budget, plugins=(PLUGIN,), **kw)


def test_statuses_for_every_way_a_run_can_end(tmp_path):
    todo = specs(["toy_constant", "toy_sleeper", "toy_crasher", "toy_exit", "toy_nan", "toy_unavailable", "toy_direct_only"])
    records = {r.method: r for r in matrix.run_matrix(todo, tmp_path, workers=2, report=quiet)}
    assert records["toy_constant"].status == "ok"
    assert records["toy_constant"].train_mse > 0 and records["toy_constant"].test_mse > 0
    assert records["toy_sleeper"].status == "timeout"
    assert "1.5 x its 1 s budget" in records["toy_sleeper"].error
    assert records["toy_crasher"].status == "failed"
    assert records["toy_crasher"].error == "RuntimeError: the toy fell over"
    assert records["toy_exit"].status == "failed"
    assert "exited with code 3" in records["toy_exit"].error and "about to vanish" in records["toy_exit"].error
    assert records["toy_nan"].status == "failed" and "non-finite" in records["toy_nan"].error
    assert records["toy_unavailable"].status == "unavailable"
    assert records["toy_unavailable"].error == "needs a runtime this machine lacks"
    assert records["toy_direct_only"].status == "not_applicable"
    on_disk = read_records(tmp_path)
    assert len(on_disk) == 7 and all(r.schema == SCHEMA for r in on_disk)
    assert not list((tmp_path / "records").glob(".*.tmp"))
    # errors are the runs whose code raised or whose worker died; a time limit, a diverged fit, an
    # unavailable or inapplicable method are outcomes a benchmark records
    assert sorted(m for m, r in records.items() if raised(r)) == ["toy_crasher", "toy_exit"]


def test_a_matrix_exits_1_and_names_the_runs_that_raised_after_writing_its_tables(tmp_path):

    plugin = str(Path(__file__).resolve().parents[1] / "plugins" / "faulty.py")
    common = ("--experiments", "indirect", "--seeds", "0,1", "--n-train", "64", "--n-test", "32", "--no-rollout",
              "--plugin", plugin)
    bad = cli("run", "--methods", "toy_constant,toy_crasher", "--budget", "5", "--out", tmp_path / "bad", *common)
    assert bad.returncode == 1 and (tmp_path / "bad" / "tables.md").exists()
    lines = [line for line in bad.stderr.splitlines() if line.startswith("error: ")]
    assert len(lines) == 2 and all("toy_crasher indirect" in line and "RuntimeError: the toy fell over" in line
                                   and "(log: " in line for line in lines)
    good = cli("run", "--methods", "toy_constant,toy_nan,toy_unavailable", "--budget", "5", "--out", tmp_path / "good",
               *common)
    assert good.returncode == 0 and "error: " not in good.stderr


def test_record_holds_configuration_results_and_provenance(tmp_path):
    todo = specs(["sysid"], experiments=("direct",), profile="smoke", budget=None, steps=20)
    (r,) = matrix.run_matrix(todo, tmp_path, workers=1, report=quiet)
    assert r.status == "ok", r.error
    assert r.target == "L" and r.budget == {"kind": "steps", "steps": 20, "ceiling_s": None} and r.seed == 0
    assert r.budget_s is None and r.describe_budget() == "20 steps" and r.code["files"]["methods/sysid.py"]
    assert r.hyperparameters["max_steps"] == 20 and r.hyperparameters["lr"] == 1e-3
    assert r.steps == 20 and r.curve and r.expression.count("qd_1") >= 1
    assert r.details["n_train"] == 64 and r.details["test_source"].endswith("seed=1000")
    p = r.provenance
    assert {"commit", "dirty", "packages", "threads", "cpu", "utc"} <= set(p)
    assert p["threads"]["OMP_NUM_THREADS"] == "1" and p["threads"]["torch_intra_op"] == 1
    assert p["packages"]["torch"]


def test_resume_skips_finished_runs(tmp_path):
    todo = specs(["toy_constant"], seeds=(0, 1))
    matrix.run_matrix(todo, tmp_path, workers=1, report=quiet)
    paths = sorted((tmp_path / "records").glob("*.json"))
    stamps = [p.stat().st_mtime_ns for p in paths]
    lines = []
    matrix.run_matrix(todo + specs(["toy_constant"], seeds=(2,)), tmp_path, workers=1, report=lines.append)
    assert [p.stat().st_mtime_ns for p in paths] == stamps
    assert any("2 run(s) already have records" in line for line in lines)
    assert len(list((tmp_path / "records").glob("*.json"))) == 3


def test_progress_lines_count_and_estimate(tmp_path):
    lines = []
    matrix.run_matrix(specs(["toy_constant", "toy_crasher"]), tmp_path, workers=1, report=lines.append)
    assert lines[0] == "2 run(s) to do on 1 worker(s)"
    assert lines[1].startswith("[##########..........] 1/2 done, 0 not ok, 1 left, ~")
    assert lines[2].startswith("[####################] 2/2 done, 1 not ok, 0 left, ~")
    assert "toy_crasher" in lines[2] and "failed (RuntimeError" in lines[2]
    assert "matrix done" in lines[-1]


def test_progress_bar_on_a_terminal(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("sys.stderr.isatty", lambda: True)
    matrix.run_matrix(specs(["toy_constant", "toy_crasher"]), tmp_path, workers=1, report=print_now)
    err = capsys.readouterr().err
    assert "2/2" in err and "failed=1" in err  # tqdm's bar, with the failed count


def test_execute_in_process_matches_the_record_format(tmp_path):
    spec = specs(["toy_constant"])[0]
    record = execute(spec)
    assert record.status == "ok" and record.schema == SCHEMA
    json.dumps(record.to_json())  # serialisable


def test_long_expressions_are_clipped_in_records():
    text = clip("x + " * 10000)
    assert len(text) < MAX_EXPRESSION_CHARS + 100 and text.endswith("[cut: 40000 characters in all]")
    assert clip("q_1 + 1") == "q_1 + 1"


def test_progress_tells_resumed_from_unrunnable_runs(tmp_path):
    lines = []
    matrix.run_matrix(specs(["toy_unavailable", "toy_constant"]), tmp_path, workers=1, report=lines.append)
    assert lines[0] == "1 run(s) recorded without running (method unavailable here or not applicable)"
    lines.clear()
    matrix.run_matrix(specs(["toy_constant"]), tmp_path, workers=1, report=lines.append)
    assert lines[0] == "resuming: 1 run(s) already have records"


def test_measured_systems_use_their_packaged_splits_and_skip_the_direct_experiment():
    direct, indirect = build_specs(["delan_characters"], ["sparse"], ["direct", "indirect"], [0], 5.0)
    record = preflight(direct)
    assert record.status == "not_applicable" and "only the indirect experiment applies" in record.error
    assert preflight(indirect) is None
    train, test = load_data(indirect, make_system(indirect))
    assert len(train) == 2459 and len(test) == 454 and "trajectories e, q, v" in test.source


@pytest.mark.xdist_group("dask")
def test_matrix_on_a_real_dask_local_cluster(tmp_path, dask_client):
    todo = specs(["toy_constant", "toy_crasher"], budget=10.0, rollout=False)
    lines = []
    records = matrix.run_matrix(todo, tmp_path, workers=2, report=lines.append, cluster=dask_client)
    assert [r.run_id for r in records] == [s.run_id for s in todo]
    assert [r.status for r in records] == ["ok", "failed"]
    assert records[1].error == "RuntimeError: the toy fell over"
    assert len(read_records(tmp_path)) == 2 and any("2/2 done, 1 not ok" in line for line in lines)
    again = matrix.run_matrix(todo, tmp_path, workers=2, report=lines.append, cluster=dask_client)
    assert [r.provenance for r in again] == [r.provenance for r in records]  # resumed, not run again


@pytest.mark.xdist_group("dask")
def test_a_model_file_written_on_a_clusters_worker_comes_back_to_where_the_caller_asked(tmp_path, dask_client):
    """On the worker the run writes under its scratch folder, removed after it (as on a worker without the
    caller's file system); the record and the model file are written here, naming the caller's path."""
    save = tmp_path / "models" / "sparse.npz"
    (spec,) = build_specs(["double_pendulum"], ["sparse"], ["indirect"], [0], None, steps=1, n_train=64, n_test=32,
                          save=str(save))
    (record,) = matrix.run_matrix([spec], tmp_path / "runs", workers=1, report=quiet, cluster=dask_client)
    assert record.status == "ok" and not record.failed_stages, record.error
    assert record.details["saved"]["path"] == str(save) and record.spec["save"] == str(save)
    assert save.is_file() and load_model(save) is not None
    assert read_record(record_path(tmp_path / "runs", spec.run_id)).details["saved"]["path"] == str(save)
    (again,) = matrix.run_matrix([spec], tmp_path / "runs", workers=1, report=quiet, cluster=dask_client)
    assert again.provenance == record.provenance  # resumed: the landed record stands for the caller's spec


def test_runs_fork_from_the_server_in_the_callers_directory(tmp_path, monkeypatch):
    from bench.core.data import generate
    from bench.core.csv_format import write_csv
    from systems import SYSTEMS

    data = generate(SYSTEMS["double_pendulum"](), 64, seed=0)
    write_csv(data, tmp_path / "train.csv")
    monkeypatch.chdir(tmp_path)  # relative paths are the caller's, not the fork server's
    (spec,) = specs(["toy_constant"], train_path="train.csv", test_path="train.csv")
    (r,) = matrix.run_matrix([spec], "out", workers=1, report=quiet)
    assert r.status == "ok", r.error
    assert r.details["train_source"].endswith("train.csv")
    assert fork_server() is not None
    fresh = run.run_one(spec, "fresh", fresh=True)
    assert fresh.status == "ok" and fresh.train_mse == r.train_mse


def test_data_the_caller_read_is_handed_to_the_run_which_reads_no_file(tmp_path):
    from bench.core.data import generate
    from systems import SYSTEMS

    system = SYSTEMS["double_pendulum"]()
    train, test = generate(system, 48, seed=1), generate(system, 24, seed=2)
    (spec,) = specs(["toy_constant"], train_path=str(tmp_path / "absent.csv"), test_path=str(tmp_path / "absent.csv"))
    r = run.run_one(spec, tmp_path, checked=True, data=(train, test))
    assert r.status == "ok", r.error
    assert r.details["n_train"] == 48 and r.details["n_test"] == 24
    assert not list(tmp_path.glob("*.pickle"))  # the hand-off file is gone after the run
    unread = run.run_one(spec, tmp_path / "again", checked=True)  # without it, the run reads the (absent) file
    assert unread.status == "failed" and "absent.csv" in unread.error


def test_a_hang_after_the_fit_is_a_timeout_at_the_evaluation_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(job, "EVALUATION_MIN_S", 2.0)
    (r,) = matrix.run_matrix(specs(["toy_slow_judge"]), tmp_path, workers=1, report=quiet)
    assert r.status == "timeout" and "evaluation after the fit still running after 2 s" in r.error  # not an hour
    assert job.evaluation_limit(60.0) == 60.0 and job.evaluation_limit(1.0) == 2.0


def test_records_made_outside_a_run_state_the_runs_threads(tmp_path):
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(2)  # this process's setting must not reach the records it writes for runs
    try:
        records = matrix.run_matrix(specs(["toy_sleeper", "toy_unavailable"], budget=0.5), tmp_path, workers=2,
                                     report=quiet)
    finally:
        torch.set_num_threads(threads)
    assert [r.status for r in records] == ["timeout", "unavailable"]
    for r in records:
        assert r.provenance["threads"]["torch_intra_op"] == 1 and r.provenance["threads"]["OMP_NUM_THREADS"] == "1"
    matrix.run_matrix(specs(["toy_constant"]), tmp_path, workers=1, report=quiet)
    from bench.reporting.tables import write_tables

    assert "; 1 thread(s) per run;" in write_tables(tmp_path, plots=False)


@pytest.mark.parametrize("content", ["x", "{}", '{"schema": "syrenets-bench/record/1", "status": "ok"}'])
def test_a_corrupt_record_is_moved_aside_and_its_run_redone(tmp_path, content):
    todo = specs(["toy_constant"], seeds=(0, 1))
    matrix.run_matrix(todo, tmp_path, workers=1, report=quiet)
    broken = tmp_path / "records" / f"{todo[1].run_id}.json"
    broken.write_text(content)
    lines = []
    records = matrix.run_matrix(todo, tmp_path, workers=1, report=lines.append)
    assert [r.status for r in records] == ["ok", "ok"]
    (warning,) = [line for line in lines if line.startswith("warning: ")]
    assert str(broken) in warning and "the run is redone" in warning
    assert any("1 run(s) already have records" in line for line in lines) and "1 run(s) to do" in "\n".join(lines)
    (moved,) = (tmp_path / "records" / "corrupt").iterdir()
    assert moved.read_text() == content and read_records(tmp_path)[1].status == "ok"


def test_a_second_matrix_on_the_same_folder_is_refused_until_the_first_ends(tmp_path):
    import os
    import signal
    import subprocess
    import sys

    from bench.core.errors import UserError

    out = tmp_path / "out"
    first = subprocess.Popen(
        [sys.executable, "-m", "bench", "run", "--methods", "toy_sleeper", "--plugin", PLUGIN, "--seeds", "0",
         "--budget", "100", "--experiments", "indirect", "--n-train", "64", "--n-test", "32", "--no-rollout",
         "--out", str(out)], cwd=Path(__file__).resolve().parents[2], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not any("fit" in p.read_text() for p in (out / "logs").glob("*.phase")) and time.monotonic() < deadline:
            time.sleep(0.1)
        with pytest.raises(UserError, match=f"another matrix is writing here \\(process {first.pid}, started "):
            matrix.run_matrix(specs(["toy_constant"]), out, workers=1, report=quiet)
    finally:
        os.kill(first.pid, signal.SIGKILL)
        first.wait()
    # the killed matrix's lock went with it
    (r,) = matrix.run_matrix(specs(["toy_constant"]), out, workers=1, report=quiet)
    assert r.status == "ok"


def test_a_stage_after_the_fit_that_fails_keeps_the_fit_and_names_the_stage(tmp_path):
    lines = []
    (r,) = matrix.run_matrix(specs(["toy_bad_expression"]), tmp_path, workers=1, report=lines.append)
    assert r.status == "ok" and r.train_mse > 0 and r.test_mse > 0 and r.steps > 0 and r.curve
    assert r.failed_stages == {"expression": "ValueError: no expression today",
                               "exact": "ValueError: no expression today"} and r.expression is None
    log = run.log_path(tmp_path, r.run_id)
    assert any("failed after the fit: expression, exact" in line and str(log) in line for line in lines), lines
    assert "Traceback" in log.read_text() and "no expression today" in log.read_text()
    from bench.reporting.tables import build_tables

    assert "1/1 ok (a stage after the fit failed: exact in 1, expression in 1)" in build_tables([r])


def test_the_method_prepares_before_its_budget_starts(tmp_path):
    (r,) = matrix.run_matrix(specs(["toy_prepared"]), tmp_path, workers=1, report=quiet)
    assert r.status == "ok" and r.details["prepared_before_the_budget"] is True
    assert r.details["prepare_seconds"] >= 0


PLUGIN_THAT_FAILS = """
import numpy as np

from methods import METHODS, Method, MethodConfig


@METHODS.add("toy_fixable", "toy")
class ToyFixable(Method):
    Config = MethodConfig

    def _fit(self, train, experiment, progress):
        {body}
        self.tau0 = train.tau.mean(axis=0)
        while progress.step():
            pass

    def _get_state(self):
        return self.tau0

    def _set_state(self, state):
        self.tau0 = state

    def predict_lagrangian(self, data):
        return np.zeros(len(data))

    def predict_torque(self, data):
        return np.tile(self.tau0, (len(data), 1))
"""


def test_a_failed_run_names_its_log_and_is_redone_once_its_plugin_is_fixed(tmp_path):
    plugin = tmp_path / "fixable.py"
    plugin.write_text(PLUGIN_THAT_FAILS.format(body='raise KeyError("a typo in the plugin")'))
    todo = build_specs(["double_pendulum"], ["toy_fixable"], ["indirect"], [0], 5.0, plugins=(str(plugin),),
                               n_train=64, n_test=32)
    lines = []
    (r,) = matrix.run_matrix(todo, tmp_path / "out", workers=1, report=lines.append)
    log = run.log_path(tmp_path / "out", r.run_id)
    assert r.status == "failed" and "a typo in the plugin" in r.error and r.code["files"][str(plugin)]
    assert any(f"log {log}" in line for line in lines), lines
    assert "Traceback" in log.read_text() and "KeyError: 'a typo in the plugin'" in log.read_text()
    lines.clear()
    (again,) = matrix.run_matrix(todo, tmp_path / "out", workers=1, report=lines.append)  # the same code: kept
    assert again.status == "failed" and "resuming: 1 run(s) already have records" in lines
    plugin.write_text(PLUGIN_THAT_FAILS.format(body="pass"))
    lines.clear()
    (fixed,) = matrix.run_matrix(todo, tmp_path / "out", workers=1, report=lines.append)
    assert fixed.status == "ok" and fixed.code["hash"] != r.code["hash"]
    assert "redoing 1 run(s) whose record was made by other code" in lines


def test_a_resume_redoes_runs_of_another_configuration_and_on_request_the_failed_ones(tmp_path):
    out = tmp_path / "out"
    matrix.run_matrix(specs(["toy_constant", "toy_crasher"]), out, workers=1, report=quiet)
    lines = []
    matrix.run_matrix(specs(["toy_constant", "toy_crasher"], budget=2.0), out, workers=1, report=lines.append)
    assert "redoing 2 run(s) whose record was made with another configuration" in lines
    lines.clear()
    records = matrix.run_matrix(specs(["toy_constant", "toy_crasher"], budget=2.0), out, workers=1,
                                 report=lines.append, retry_failed=True)
    assert "redoing 1 run(s) that failed" in lines and [r.status for r in records] == ["ok", "failed"]


def test_seeds_trained_stacked_give_the_records_they_give_one_by_one(tmp_path):
    # each stacked seed's record is its fit alone: the MLP's to the last bit on a CPU, DeLaN's (float32)
    # to its rounding, SyReNets' to 1e-12; sparse regression does not stack and runs as before
    common = dict(steps=20, n_train=256, n_test=64, rollout=False, profile="smoke")
    specs = build_specs(["double_pendulum"], ["mlp", "delan", "syrenets", "sparse"], ["indirect"], [0, 1, 2], None,
                        **common)
    stacked = matrix.run_matrix(specs, tmp_path / "stacked", workers=2, report=quiet, stack=True)
    alone = matrix.run_matrix(specs, tmp_path / "alone", workers=2, report=quiet)
    for a, b in zip(stacked, alone):
        assert a.status == b.status == "ok" and a.steps == b.steps == {"sparse": 1, "syrenets": 10}.get(a.method, 20)
        tolerance = {"mlp": 0.0, "delan": 1e-6, "syrenets": 1e-12, "sparse": 0.0}[a.method]
        assert abs(a.test_mse - b.test_mse) <= tolerance * b.test_mse and abs(a.train_mse - b.train_mse) <= tolerance * b.train_mse
        assert a.details.get("stacked") == (None if a.method == "sparse" else 3) and "stacked" not in b.details
    # a resume takes the stacked records for what they stand for
    again = matrix.run_matrix(specs, tmp_path / "stacked", workers=2, report=quiet, stack=True)
    assert [r.to_json() for r in again] == [r.to_json() for r in stacked]
    # a stacked record replays alone (bench rerun), the same up to the stated tolerance

    delan = tmp_path / "stacked" / "records" / "double_pendulum__delan__indirect__seed1.json"
    r = cli("rerun", delan)
    assert r.returncode == 0 and "the same up to a relative 1e-06, as the record trained stacked with 3 seeds" in r.stdout


def test_a_stack_that_fails_runs_each_of_its_seeds_alone(tmp_path):
    plugin = str(Path(__file__).resolve().parents[1] / "plugins" / "faulty.py")
    specs = build_specs(["double_pendulum"], ["toy_unstackable"], ["indirect"], [0, 1], None, steps=3, n_train=64,
                        n_test=32, rollout=False, plugins=(plugin,))
    records = matrix.run_matrix(specs, tmp_path, workers=1, report=quiet, stack=True)
    assert [r.status for r in records] == ["ok", "ok"] and all("stacked" not in r.details for r in records)
    assert "vmap" in (tmp_path / "logs" / "double_pendulum__toy_unstackable__indirect__seed0__stack2.log").read_text()


def test_one_edited_plugin_redoes_only_the_records_of_the_method_it_defines(tmp_path):
    plugin = tmp_path / "edited.py"
    text = PLUGIN_THAT_FAILS.replace("toy_fixable", "toy_edited")  # a name of its own: another test imports toy_fixable
    plugin.write_text(text.format(body="pass"))
    todo = build_specs(["double_pendulum"], ["toy_edited", "sparse"], ["indirect"], [0, 1], None, steps=3,
                       plugins=(str(plugin),), n_train=64, n_test=32, rollout=False)
    first = matrix.run_matrix(todo, tmp_path / "out", workers=1, report=quiet)
    plugin.write_text(text.format(body="pass  # one edited line"))
    lines = []
    again = matrix.run_matrix(todo, tmp_path / "out", workers=1, report=lines.append)
    assert "redoing 2 run(s) whose record was made by other code" in lines, lines
    assert [r.status for r in again] == ["ok"] * 4
    for a, b in zip(first, again):
        assert (a.code["hash"] == b.code["hash"]) == (a.method == "sparse")


def test_seeds_group_where_their_configuration_stacks_and_run_alone_where_it_does_not():
    from bench.runner.stacked import groups

    common = dict(steps=5, n_train=64, n_test=32, rollout=False)
    plain = build_specs(["double_pendulum"], ["syrenets", "sysid"], ["indirect"], [0, 1, 2], None, **common)
    assert sorted(len(g) for g in groups(plain)) == [1, 1, 1, 3]  # SyReNets' three seeds together, SysId's alone
    compiled = build_specs(["double_pendulum"], ["syrenets"], ["indirect"], [0, 1], None, profile="best-300s", **common)
    assert [len(g) for g in groups(compiled)] == [1, 1]  # compile=True: one network's compiled pass, each seed alone


def test_a_matrix_whose_code_changes_under_it_stops_before_its_next_run(tmp_path, monkeypatch):
    from bench.core.errors import UserError
    states = iter(["the code at the start", "the code at the start", "the code after a merge"])
    monkeypatch.setattr(matrix, "code_state", lambda: next(states))
    todo = specs(["toy_constant"], seeds=(0, 1))
    with pytest.raises(UserError, match=r"the code changed while this matrix ran .*stopped before "
                                        r"double_pendulum__toy_constant__indirect__seed1"):
        matrix.run_matrix(todo, tmp_path, workers=1, report=quiet)
    assert [p.name for p in (tmp_path / "records").glob("*.json")] == ["double_pendulum__toy_constant__indirect__seed0.json"]


def test_a_progress_line_names_a_runs_named_configuration():
    """Two configurations of one method (select's standard and feasible SysId) are two runs; each line of the
    matrix's progress says which it is, and a run in the method's defaults says nothing more."""
    named = Record.new(RunSpec("kuka_lwr4", "sysid", "indirect", 0, 5.0, profile="feasible"), "ok",
                       train_mse=0.5, test_mse=0.25)
    plain = Record.new(RunSpec("kuka_lwr4", "sysid", "indirect", 0, 5.0), "ok", train_mse=0.5, test_mse=0.25)
    assert matrix._describe(named) == "kuka_lwr4 sysid (feasible) indirect seed=0: ok train 0.5 test 0.25"
    assert matrix._describe(plain) == "kuka_lwr4 sysid indirect seed=0: ok train 0.5 test 0.25"


def test_a_tuned_runs_progress_line_gives_its_validation_not_its_test():
    """A tuned run (each of ``bench select``'s candidates) is judged by its validation: its line of progress gives
    that, and its test MSE waits for the page, after the choice."""
    tuned = Record.new(RunSpec("kuka_lwr4", "sysid", "indirect", 0, 5.0, tune=True), "ok", train_mse=0.5,
                       test_mse=0.25, details={"tuning": {"validation_mse": 0.75}})
    line = matrix._describe(tuned)
    assert line == "kuka_lwr4 sysid indirect seed=0: ok train 0.5 validation 0.75"
    assert "0.25" not in line and "test" not in line


def test_an_edited_recording_redoes_the_runs_that_read_it_and_no_other(tmp_path):
    """A run's code holds its measured arm's file, each recording and the URDF: a recording edited between two
    runs of one matrix into one folder redoes the arm's run; the pendulum's, which reads none of them, is kept."""
    import gzip
    import shutil

    from systems.urdf_arm import DATA_DIR

    arm = tmp_path / "arm"
    arm.mkdir()
    text = (DATA_DIR / "dfki_double_pendulum_arm.toml").read_text()
    text = text.split("[recordings]")[0].replace('test = ["03", "05"]', 'test = ["03"]').replace(
        'chosen_on = ["00", "01", "02", "04"]', 'chosen_on = ["00", "01"]')
    text += "[recordings]\n" + "".join(f'{k} = {{ file = "dfki_trajectory_{k}.csv.gz", trajectory = "{k}" }}\n'
                                       for k in ("00", "01", "03"))
    (arm / "edited_arm.toml").write_text(text)  # a name of its own: this process registers it
    for name in ("dfki_double_pendulum.urdf.gz", *(f"dfki_trajectory_{k}.csv.gz" for k in ("00", "01", "03"))):
        shutil.copy(DATA_DIR / name, arm / name)
    argv = ["run", "--systems", f"measured:{arm / 'edited_arm.toml'},double_pendulum", "--methods", "sysid",
            "--experiments", "indirect", "--seeds", "0", "--steps", "1", "--n-train", "64", "--n-test", "32",
            "--no-rollout", "--workers", "1", "--out", str(tmp_path / "out")]
    first = cli(*argv)
    assert first.returncode == 0, first.stderr
    records = {p.name: json.loads(p.read_text()) for p in (tmp_path / "out" / "records").glob("*.json")}
    assert len(records) == 2
    (arm_record,) = [r for r in records.values() if r["system"] != "double_pendulum"]
    assert str((arm / "dfki_trajectory_00.csv.gz").resolve()) in arm_record["code"]["files"]  # the record names it
    log = arm / "dfki_trajectory_00.csv.gz"
    rows = gzip.decompress(log.read_bytes()).decode().splitlines()
    rows[5] = rows[5].replace(rows[5].split(",")[-1], "0.125")  # one value of one row
    log.write_bytes(gzip.compress(("\n".join(rows) + "\n").encode()))
    again = cli(*argv)
    assert again.returncode == 0, again.stderr
    assert "redoing 1 run(s) whose record was made by other code" in again.stdout, again.stdout
    after = {p.name: json.loads(p.read_text()) for p in (tmp_path / "out" / "records").glob("*.json")}
    for name, record in after.items():
        changed = record["code"]["hash"] != records[name]["code"]["hash"]
        assert changed == (record["system"] != "double_pendulum"), name
