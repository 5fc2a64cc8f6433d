"""The command line: help, listing, data, fit, run, table, and bad input."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench.cli import build_parser, main

ROOT = Path(__file__).resolve().parent.parent


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "bench", *args], capture_output=True, text=True, cwd=cwd or ROOT)


COMMANDS = ("list", "run", "table", "data", "fit", "residual", "convert", "leaderboard",
            "adaptation", "residual-acceptance", "overhead", "dfki-filter")


def _subparsers():
    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return sub


def test_help_lists_every_command():
    text = build_parser().format_help()
    for command in COMMANDS:
        assert command in text
    assert set(_subparsers().choices) == set(COMMANDS)
    fit_help = cli("fit", "--help").stdout
    assert "--train" in fit_help and "--json" in fit_help


def test_every_option_of_every_command_has_a_help_text():
    sub = _subparsers()
    assert all(action.help for action in sub._choices_actions)
    missing = [f"{name} {'/'.join(a.option_strings) or a.dest}" for name, parser in sub.choices.items()
               for a in parser._actions if not isinstance(a, argparse._HelpAction) and not a.help]
    assert missing == []


def test_list_shows_systems_and_methods_with_availability(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "double_pendulum" in out and "dof=2" in out
    assert "mlp" in out and "sysid" in out and "available" in out


def test_data_then_fit_on_the_csv(tmp_path):
    train, test, out = tmp_path / "train.csv", tmp_path / "test.csv", tmp_path / "run.json"
    assert main(["data", "--system", "double_pendulum", "--n", "200", "--seed", "1", "--out", str(train)]) == 0
    assert main(["data", "--system", "double_pendulum", "--n", "100", "--seed", "2", "--out", str(test)]) == 0
    r = cli("fit", "--system", "double_pendulum", "--method", "sysid", "--experiment", "indirect",
            "--train", str(train), "--test", str(test), "--smoke", "--budget", "5", "--json", str(out))
    assert r.returncode == 0, r.stderr
    line = r.stdout.strip()
    assert line.startswith("double_pendulum sysid indirect seed=0: ok | train MSE ") and "test MSE" in line
    record = json.loads(out.read_text())
    assert record["status"] == "ok" and record["details"]["train_source"] == str(train)
    assert record["details"]["n_test"] == 100


def test_fit_without_test_data_reports_none(tmp_path, capsys):
    train = tmp_path / "train.csv"
    main(["data", "--system", "double_pendulum", "--n", "64", "--seed", "1", "--out", str(train)])
    assert main(["fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct",
                 "--train", str(train), "--smoke"]) == 0
    assert "test MSE n/a (no test data)" in capsys.readouterr().out


@pytest.mark.parametrize(
    "content, message",
    [
        ("q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1\n1,2,3,4,5,6,7\n", "missing column(s) tau_2"),
        ("q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2\n1,2,3,4,5,6,7,nan\n", "column tau_2 has a NaN"),
        ("q_1,qd_1,qdd_1,tau_1\n1,2,3,4\n", "1 degrees of freedom"),
        ("q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2\n", "no rows"),
        ("q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2\n1,2,3,4,5,6,7,8\n", "direct experiment needs column 'L'"),
    ],
)
def test_bad_csv_exits_2_with_one_line_and_writes_nothing(tmp_path, content, message):
    bad, out = tmp_path / "bad.csv", tmp_path / "run.json"
    bad.write_text(content)
    r = cli("fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct",
            "--train", str(bad), "--json", str(out), "--smoke")
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: ") and str(bad) in r.stderr
    assert message in r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert not out.exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["fit", "--system", "double_pendulm", "--method", "mlp", "--experiment", "direct"], "did you mean 'double_pendulum'"),
        (["fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct", "--set", "hiden=3"],
         "did you mean 'hidden'"),
        (["run", "--methods", "mlp", "--experiments", "sideways", "--out", "x"], "unknown experiment 'sideways'"),
        (["table", "nowhere"], "no records found"),
        (["fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct", "--test", "t.csv"],
         "--test needs --train"),
        (["run", "--methods", "mlp", "--noise", "-0.1", "--out", "x"], "a noise level is a fraction"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(tmp_path, args, message):
    r = cli(*args, cwd=tmp_path)
    assert r.returncode == 2, r.stdout
    assert message in r.stderr and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_run_writes_records_and_tables_and_resumes(tmp_path):
    out = tmp_path / "m"
    args = ["run", "--methods", "mlp,sysid", "--seeds", "0,1", "--budget", "2", "--smoke",
            "--n-train", "64", "--n-test", "32", "--out", str(out), "--workers", "2"]
    r = cli(*args)
    assert r.returncode == 0, r.stderr
    assert len(list((out / "records").glob("*.json"))) == 8
    table = (out / "tables.md").read_text()
    assert "## double_pendulum, direct experiment (MSE of L)" in table
    assert "| Group | Split | mlp | sysid |" in table and "| Runs | | 2/2 ok | 2/2 ok |" in table
    assert "] 8/8 done" in r.stdout
    again = cli(*args)
    assert "8 run(s) already have records" in again.stdout and "0 run(s) to do" in again.stdout


def test_noise_levels_are_a_dimension_of_the_matrix(tmp_path):
    out = tmp_path / "n"
    r = cli("run", "--methods", "sysid", "--experiments", "indirect", "--seeds", "0", "--budget", "2", "--smoke",
            "--n-train", "64", "--n-test", "32", "--noise", "0", "0.1", "--no-rollout", "--out", str(out))
    assert r.returncode == 0, r.stderr
    names = sorted(p.name for p in (out / "records").glob("*.json"))
    assert names == ["double_pendulum__sysid__indirect__seed0.json", "double_pendulum__sysid__indirect__seed0__noise0.1.json"]
    table = (out / "tables.md").read_text()
    assert "## double_pendulum, indirect experiment (MSE of τ), training targets with 10 % noise (test targets clean)" in table
