"""The command line: help, listing, data, fit, run, table, and bad input."""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from bench.cli import build_parser, main
from bench.core.fileio import file_digest, write_json
from bench.runner import job
from bench.runner.records import Record
from bench.runner.spec import RunSpec
from tests.commandline import cli

ROOT = Path(__file__).resolve().parent.parent


#: the user's verbs, and the one verb of the project's studies
COMMANDS = ("list", "run", "table", "data", "fit", "predict", "select", "residual", "convert", "robot-log", "rerun", "leaderboard", "index",
            "study")
STUDIES = ("gpu", "adaptation", "residual-acceptance", "residual-dfki", "overhead", "dfki-filter", "scaling", "syrenets-speed",
           "syrenets-profile", "stacking-speed", "generalisation", "trajectories", "selection", "long-log",
           "selection-rerun", "standard-model", "loop-speed")


def _subparsers_of(parser):
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sub


class _Leaves:
    """Every command's parser, a study's as ``study NAME``: ``.choices`` and ``._choices_actions`` as argparse's."""

    def __init__(self):
        top = _subparsers_of(build_parser())
        study = _subparsers_of(top.choices["study"])
        self.choices = {**{k: v for k, v in top.choices.items() if k != "study"},
                        **{f"study {k}": v for k, v in study.choices.items()}}
        self._choices_actions = [*top._choices_actions, *study._choices_actions]


def _subparsers():
    return _Leaves()


def test_help_lists_the_users_verbs_and_one_verb_for_the_studies():
    text = build_parser().format_help()
    for command in COMMANDS:
        assert command in text
    assert set(_subparsers_of(build_parser()).choices) == set(COMMANDS)
    assert not any(f"    {s} " in text for s in STUDIES)
    studies = cli("study", "--help").stdout
    assert all(s in studies for s in STUDIES)
    assert set(_subparsers().choices) == {c for c in COMMANDS if c != "study"} | {f"study {s}" for s in STUDIES}
    fit_help = cli("fit", "--help").stdout
    assert "--train" in fit_help and "--json" in fit_help


#: what reading and refusing a user's file needs none of: the libraries and the suite's modules that compute
#: (the registries' packages, ``methods`` and ``systems``, cost nothing until a name is looked up)
ENGINES = ("torch", "sympy", "pinocchio", "methods.base", "systems.base", "bench.physics", "bench.runner.run")
#: what the help texts need none of besides (pandas reads a measured arm's logs)
HEAVY = ENGINES + ("pandas", "scipy")


def _among(module: str, names) -> bool:
    return any(module == n or module.startswith(n + ".") for n in names)


def _loaded(argv, cwd=ROOT):
    """The heavy modules, studies and command modules that ``python -m bench ARGV`` imported, its exit code and
    its output."""
    code = ("import sys\nfrom bench.cli import main\ntry:\n    code = main(sys.argv[1:])\nexcept SystemExit as e:\n"
            "    code = e.code\nprint(' '.join(sorted(m for m in sys.modules if m.split('.')[0] in "
            f"{HEAVY!r} or m in {HEAVY!r} or any(m.startswith(h + '.') for h in {HEAVY!r}) or "
            "m.startswith('bench.studies.') or m.startswith('bench.cli.'))), file=sys.stderr)\n"
            "sys.exit(code)")
    r = subprocess.run([sys.executable, "-c", code, *argv], cwd=cwd, capture_output=True, text=True, timeout=300)
    *lines, modules = r.stderr.splitlines() or [""]
    return set(modules.split()), r.returncode, r.stdout, "\n".join(lines)


@pytest.mark.parametrize("argv", [["--help"], ["study", "--help"], ["fit", "--help"], ["run", "--help"],
                                  ["residual", "--help"], ["select", "--help"]])
def test_help_imports_only_the_command_it_names(argv):
    """A command's modules are imported when it is parsed: ``--help``, ``study --help`` and a command's
    ``--help`` import none of the heavy libraries, the methods or the systems, and no study."""
    loaded, code, out, _ = _loaded(argv)
    assert "usage: python -m bench" in out and code == 0
    assert not {m for m in loaded if _among(m, HEAVY)}, loaded
    assert not {m for m in loaded if m.startswith("bench.studies.")}, loaded
    if argv[0] != "--help" and argv[0] != "study":
        assert f"bench.cli.{argv[0]}" in loaded and not {f"bench.cli.{c}" for c in COMMANDS if c != argv[0]} & loaded
    else:
        assert loaded <= {"bench.cli.parser", "bench.cli.study"}, loaded


def test_a_refused_model_file_or_measured_arm_file_is_refused_before_the_engines_are_imported(tmp_path):
    """A file that is no model (predict), and a measured arm's file that does not parse (fit, run, select,
    residual), are refused in one line, exit 2, with nothing written, before torch, sympy, Pinocchio or a
    method is imported."""
    (tmp_path / "model.npz").write_bytes(b"not a model file")
    (tmp_path / "log.csv").write_text("q_1,qd_1,qdd_1\n0,0,0\n")
    (tmp_path / "arm.toml").write_text('urdf = "arm.urdf"\n[recordings\n')
    for argv, what in ((["predict", "--model", "model.npz", "--log", "log.csv", "--out", "out.csv"], "model.npz"),
                       (["fit", "--system", "measured:arm.toml", "--method", "sysid", "--experiment", "indirect"],
                        "arm.toml"),
                       (["run", "--systems", "measured:arm.toml", "--methods", "sysid", "--out", "ran"], "arm.toml"),
                       (["select", "--system", "measured:arm.toml", "--out", "chosen"], "arm.toml"),
                       (["residual", "--system", "measured:arm.toml", "--method", "sysid", "--json", "loop.json"],
                        "arm.toml")):
        loaded, code, _, err = _loaded(argv, cwd=tmp_path)
        assert code == 2 and err.startswith("error: ") and what in err and len(err.splitlines()) == 1, err
        assert not {m for m in loaded if _among(m, ENGINES)}, loaded
    assert {p.name for p in tmp_path.iterdir()} == {"model.npz", "log.csv", "arm.toml"}  # nothing written


@pytest.mark.parametrize("command", [None, *COMMANDS, *(f"study {s}" for s in STUDIES)])
def test_every_help_renders(command, capsys):
    # argparse formats help texts with %: a stray "%" in one raises only when that help is printed
    with pytest.raises(SystemExit) as exit_:
        main(["--help"] if command is None else [*command.split(), "--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: python -m bench") and "--help" in out


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
    start, line = r.stdout.strip().splitlines()
    assert start == "double_pendulum sysid indirect seed=0: fitting within 5 s, then scoring"
    assert line.startswith("double_pendulum sysid indirect seed=0: ok | train MSE ") and "test MSE" in line
    record = json.loads(out.read_text())
    assert record["status"] == "ok" and record["details"]["train_source"] == str(train)
    assert record["details"]["n_test"] == 100


def test_fit_without_test_data_reports_none(tmp_path, capsys):
    train = tmp_path / "train.csv"
    main(["data", "--system", "double_pendulum", "--n", "64", "--seed", "1", "--out", str(train)])
    capsys.readouterr()
    assert main(["fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct",
                 "--train", str(train), "--smoke"]) == 0
    lines = capsys.readouterr().out.splitlines()
    # what it is about to do comes first, the summary when it ends
    assert lines[0] == "double_pendulum mlp direct seed=0: fitting within 60 s, then scoring"
    assert lines[1].startswith("double_pendulum mlp direct seed=0: ok") and "test MSE n/a (no test data)" in lines[1]


def test_rerun_replays_every_record_of_a_time_budgeted_matrix(tmp_path, capsys, monkeypatch):
    # each fit stops itself at its 1 s budget; the kill at KILL_FACTOR x it is the runner's backstop (a call
    # killed at its phase's limit: tests/runner/test_isolation.py), here out of reach, so that a busy machine,
    # where a fit stops late, cannot turn a run into a timeout
    monkeypatch.setattr(job, "KILL_FACTOR", 1000.0)
    out = tmp_path / "m"
    assert main(["run", "--methods", "mlp,mggp,sysid", "--experiments", "indirect", "--seeds", "0", "--budget", "1",
                 "--n-train", "256", "--n-test", "64", "--no-rollout", "--out", str(out)]) == 0
    records = sorted((out / "records").glob("*.json"))
    assert len(records) == 3
    for path in records:
        r = cli("rerun", path)
        assert r.returncode == 0, (r.stdout, r.stderr)
        text = r.stdout
        assert "the same up to a relative 1e-09" in text and "(recorded under 1 s, stopped by budget)" in text
        assert text.count("relative difference") == 1 and "train_mse" in text and "test_mse" in text


def test_a_failed_fit_names_the_log_that_holds_its_traceback(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the kept scratch folder goes with the test's
    plugin = str(ROOT / "tests" / "plugins" / "faulty.py")
    r = cli("fit", "--system", "double_pendulum", "--method", "toy_crasher", "--plugin", plugin, "--experiment",
            "indirect", "--n-train", "64", "--n-test", "32", "--steps", "1")
    assert r.returncode == 1 and "failed (RuntimeError: the toy fell over; traceback in " in r.stdout
    log = Path(r.stdout.strip().rsplit("traceback in ", 1)[1].rstrip(")"))
    assert log.is_relative_to(tmp_path)  # kept for the user to read: a scratch folder of bench fit's, not removed
    assert "Traceback (most recent call last)" in log.read_text() and "the toy fell over" in log.read_text()


def test_rerun_imports_a_records_plugins_only_where_the_user_names_the_same_files(tmp_path):
    """A record is data: the plugins its run imported run again only where --plugin names each, the same file
    by its sha256; a record edited to name another file, or a plugin edited since, is refused in one line."""
    plugin = tmp_path / "toys.py"
    # a name of its own: another test of this process may have registered faulty.py's
    plugin.write_text((ROOT / "tests" / "plugins" / "faulty.py").read_text().replace('"toy_', '"toy_rerun_'))
    record = tmp_path / "run.json"
    made = cli("fit", "--system", "double_pendulum", "--method", "toy_rerun_constant", "--plugin", plugin, "--experiment",
               "indirect", "--n-train", "64", "--n-test", "32", "--steps", "1", "--json", record)
    assert made.returncode == 0, made.stderr
    assert json.loads(record.read_text())["code"]["plugins"] == {str(plugin.resolve()): file_digest(plugin)}
    refused = cli("rerun", record)
    assert refused.returncode == 2 and refused.stdout == "" and refused.stderr.count("\n") == 1
    assert f"its run imported the plugin(s) {plugin.resolve()}, which run code" in refused.stderr
    assert f"--plugin {plugin.resolve()}" in refused.stderr
    assert cli("rerun", record, "--plugin", tmp_path / "other.py").returncode == 2
    again = cli("rerun", record, "--plugin", plugin)
    assert again.returncode == 0 and "the same up to" in again.stdout, (again.stdout, again.stderr)
    plugin.write_text(plugin.read_text() + "\n# edited\n")
    edited = cli("rerun", record, "--plugin", plugin)
    assert edited.returncode == 2 and f"plugin {plugin.resolve()} is not the file its run imported" in edited.stderr
    # a record edited to import another file than its run did: that file is never run unless named
    hostile = tmp_path / "hostile.py"
    hostile.write_text(f"open({str(tmp_path / 'ran')!r}, 'w').close()\n")
    data = json.loads(record.read_text())
    data["spec"]["plugins"] = [str(hostile)]
    write_json(record, data)
    assert cli("rerun", record).returncode == 2 and not (tmp_path / "ran").exists()


def test_rerun_refuses_in_one_line_what_it_cannot_replay(tmp_path, capsys):
    record = Record.new(RunSpec("double_pendulum", "mlp", "indirect", 0, 5.0), "failed", error="it broke")
    path = tmp_path / "failed.json"
    write_json(path, record.to_json())
    assert main(["rerun", str(path)]) == 2
    assert capsys.readouterr().err == f"error: {path}: the run's status is failed; only an ok run has numbers to repeat\n"
    write_json(path, record.replace(status="ok", train_mse=1.0).to_json())
    assert main(["rerun", str(path)]) == 2
    assert "written before runs recorded the work they did" in capsys.readouterr().err


def test_the_public_configuration_with_qdd_as_an_input_keeps_its_fit(capsys, tmp_path):
    # its expression holds qdd: exact recovery and the rollout do not apply, and say so
    out = tmp_path / "run.json"
    assert main(["fit", "--system", "double_pendulum", "--method", "syrenets", "--experiment", "direct", "--smoke",
                 "--steps", "10", "--n-train", "256", "--n-test", "64", "--set", "inputs=q_qd_qdd",
                 "--set", "refine=False", "--json", str(out)]) == 0
    record = json.loads(out.read_text())
    assert record["status"] == "ok" and record["test_mse"] > 0 and record["failed_stages"] == {}
    assert record["exact"] is None
    assert "qdd" in record["details"]["exact_not_applicable"] and record["rollout"]["status"] == "not_applicable"
    assert record["budget"] == {"kind": "steps", "steps": 10, "ceiling_s": None}


def test_fit_prints_each_variant_of_its_fit_or_why_it_has_none():
    from bench.cli.fit import variant_lines

    variants = {"pruned": {"status": "ok", "train_mse": 0.41713, "test_mse": 0.42244, "exact": False},
                "refined": {"status": "timeout", "error": "no refit finished: 8 terms: out of budget"}}
    record = Record.new(RunSpec("double_pendulum", "syrenets", "indirect", 0, 5.0), "ok", train_mse=0.38,
                        test_mse=0.39, details={"variants": variants})
    assert variant_lines(record) == ["  syrenets@pruned: train MSE 0.4171 | test MSE 0.4224 | not the true Lagrangian",
                                     "  syrenets@refined: timeout (no refit finished: 8 terms: out of budget)"]
    assert variant_lines(record.replace(status="failed", error="it broke")) == []


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


@pytest.mark.parametrize(
    "args, message",
    [
        (["data", "--system", "double_pendulum", "--n", "10", "--seed", "-1", "--out", "d.csv"], "a seed is a whole number >= 0"),
        (["fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct", "--seed", "-3"],
         "a seed is a whole number >= 0"),
        (["run", "--methods", "mlp", "--n-seeds", "20", "--out", "x"], "at most 10 (the tables' fixed seeds)"),
        (["run", "--methods", "mlp", "--seeds", "3-1", "--out", "x"], "the seed range 3-1 is empty"),
        (["run", "--methods", "mlp", "--seeds", "1,1", "--out", "x"], "a seed is given twice"),
        (["run", "--methods", "mlp", "--set", "batch_size=0", "--out", "x"], "batch_size must be at least 1, got 0"),
        (["run", "--methods", "loop,mlp", "--out", "x"],  # named, and applies to no system given: refused
         "loop: the prior loop is SysId identified on an arm's linear form (from its URDF), and double_pendulum has none"),
        (["run", "--methods", "standard+gp", "--out", "x"], "standard+gp: the prior standard is SysId identified"),
        (["run", "--methods", "mlp", "--set", "max_steps=-5", "--out", "x"], "max_steps must be at least 1, got -5"),
        (["fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct", "--set", "eval_samples=0"],
         "eval_samples must be at least 1, got 0"),
        (["fit", "--system", "double_pendulum", "--method", "mlp", "--experiment", "direct", "--train", "."],
         "is a folder, not a file"),
        (["convert", "--columns", "time=t,q_1=p", "raw.csv", "--out", "o.csv"], "missing qd_1, tau_1"),
        (["select", "--system", "kuka_lwr4", "--folds", "knndm", "--out", "sel"],
         "the training data hold one trajectory; name the states the model will be asked with --target-states"),
    ],
)
def test_what_users_type_wrong_is_refused_in_one_line(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    try:
        code = main(args)
    except SystemExit as exc:  # argparse's own exit, in one line (see _Parser)
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing written


def test_an_output_path_under_a_file_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    from bench.runner import run

    (tmp_path / "f").write_text("x")
    monkeypatch.setattr(run, "run_isolated", lambda *a, **k: pytest.fail("a run started before the refusal"))
    code = main(["fit", "--system", "double_pendulum", "--method", "sysid", "--experiment", "indirect", "--budget", "60",
                 "--json", str(tmp_path / "f" / "run.json")])
    err = capsys.readouterr().err
    assert code == 2 and "is a file, not a folder" in err and err.count("\n") == 1


def test_fit_pins_its_threads_and_accepts_booleans_as_typed(tmp_path):
    out = tmp_path / "run.json"
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    r = subprocess.run([sys.executable, "-m", "bench", "fit", "--system", "double_pendulum", "--method", "syrenets",
                        "--experiment", "indirect", "--smoke", "--set", "refine=FALSE", "--n-train", "64", "--n-test",
                        "32", "--steps", "10", "--json", str(out)], capture_output=True, text=True, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr
    record = json.loads(out.read_text())
    assert record["hyperparameters"]["refine"] is False
    threads = record["provenance"]["threads"]
    assert threads["OMP_NUM_THREADS"] == "1" and threads["torch_intra_op"] == 1 and threads["torch_inter_op"] == 1


def test_table_headers_state_the_sampling_range_noise_and_hyperparameters_set(tmp_path):
    out = tmp_path / "m"
    r = cli("run", "--methods", "mlp", "--experiments", "direct", "--seeds", "0", "--budget", "2", "--smoke",
            "--set", "hidden=8", "--n-train", "64", "--n-test", "32", "--no-rollout", "--noise", "0.01",
            "--domain-half-width", str(math.pi), "--out", str(out))
    assert r.returncode == 0, r.stderr
    table = (out / "tables.md").read_text()
    assert "Data: 64 training and 32 test samples, q, q̇, q̈ ~ U(−π, π); noise: 1 % of each target column's std" in table
    assert "Hyperparameters set beside each method's own: mlp: hidden=8." in table
    assert "configuration: smoke." in table


def dfki_raw(tmp_path, layout):
    import pandas as pd

    from systems.dfki_double_pendulum import LAYOUTS, trajectory_path

    frame = pd.read_csv(trajectory_path("03"))
    frame = frame.rename(columns=dict(zip(LAYOUTS[0].columns, layout)))
    path = tmp_path / f"raw_{len(list(tmp_path.iterdir()))}.csv"
    frame.to_csv(path, index=False)
    return path


def test_convert_reads_both_dfki_layouts_and_any_log_by_its_columns(tmp_path):
    from bench.core.csv_format import read_csv
    from systems.dfki_double_pendulum import LAYOUTS

    outputs = []
    for args in (["--format", "dfki", str(dfki_raw(tmp_path, LAYOUTS[0].columns))],
                 ["--format", "dfki", str(dfki_raw(tmp_path, LAYOUTS[1].columns))],
                 ["--columns", "time=t,q_1=a,q_2=b,qd_1=c,qd_2=d,tau_1=e,tau_2=f",
                  str(dfki_raw(tmp_path, ("t", "a", "b", "c", "d", "e", "f")))]):
        out = tmp_path / f"out{len(outputs)}.csv"
        r = cli("convert", *args, "--out", str(out))
        assert r.returncode == 0, r.stderr
        assert "zero-phase Butterworth low-pass of order 4 at 6 Hz" in r.stdout  # the converter states its filter
        outputs.append(read_csv(out, dof=2))
    for other in outputs[1:]:
        np.testing.assert_array_equal(other.qdd, outputs[0].qdd)


def test_convert_names_each_log_as_a_recording(tmp_path):
    from bench.core.csv_format import read_csv
    from systems.dfki_double_pendulum import LAYOUTS

    first, second = dfki_raw(tmp_path, LAYOUTS[0].columns), dfki_raw(tmp_path, LAYOUTS[1].columns)
    out = tmp_path / "both.csv"
    r = cli("convert", "--format", "dfki", str(first), str(second), "--out", str(out))
    assert r.returncode == 0 and "from 2 recording(s)" in r.stdout, r.stderr
    data = read_csv(out, dof=2)
    assert data.recordings() == [first.stem, second.stem]
    assert (data.recording == first.stem).sum() == (data.recording == second.stem).sum() == len(data) // 2
    same = tmp_path / "again" / first.name
    same.parent.mkdir()
    same.write_bytes(first.read_bytes())
    r = cli("convert", "--format", "dfki", str(first), str(same), "--out", str(tmp_path / "x.csv"))
    assert r.returncode == 2 and "the same recording" in r.stderr and not (tmp_path / "x.csv").exists()
    broken = tmp_path / "broken.csv"
    broken.write_text(_with_huge_cell(first.read_text()))
    r = cli("convert", "--format", "dfki", str(first), str(broken), "--out", str(tmp_path / "y.csv"))
    assert r.returncode == 2 and str(broken) in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "y.csv").exists()  # the good first log is not written alone


def test_convert_and_residual_refuse_values_whose_square_overflows(tmp_path):
    from systems.dfki_double_pendulum import LAYOUTS

    raw = dfki_raw(tmp_path, LAYOUTS[0].columns)
    raw.write_text(_with_huge_cell(raw.read_text()))
    r = cli("convert", "--format", "dfki", str(raw), "--out", str(tmp_path / "o.csv"))
    assert r.returncode == 2 and "too large to compute with" in r.stderr and r.stderr.count("\n") == 1
    assert not (tmp_path / "o.csv").exists()
    train = tmp_path / "train.csv"
    train.write_text("q_1,q_2,qd_1,qd_2,qdd_1,qdd_2,tau_1,tau_2\n" + "0.1,0.2,0.3,0.4,0.5,0.6,1e200,0.8\n" * 20)
    r = cli("residual", "--system", "double_pendulum", "--method", "sparse", "--train", str(train), "--budget", "5")
    assert r.returncode == 2 and "too large to compute with" in r.stderr and r.stderr.count("\n") == 1


def _with_huge_cell(text: str) -> str:
    header, first, rest = text.split("\n", 2)
    cells = first.split(",")
    cells[1] = "1e308"
    return "\n".join([header, ",".join(cells), rest])


def _numeric_options():
    """(command, option, bad value) for every option typed as a count, a duration or a fraction."""
    from bench.core.arguments import noise_level, nonnegative, nonnegative_int, positive, positive_int
    from bench.runner.spec import seed_count

    bad = {positive: "0", positive_int: "0", nonnegative: "-1", nonnegative_int: "-1", seed_count: "11",
           noise_level: "10"}
    return [(name, action.option_strings[-1], bad[action.type])
            for name, parser in _subparsers().choices.items() for action in parser._actions
            if action.type in bad]


def test_no_option_takes_an_unchecked_number():
    sub = _subparsers()
    bare = [f"{name} {a.option_strings[-1]}" for name, parser in sub.choices.items() for a in parser._actions
            if a.type in (int, float)]
    assert bare == []
    commands = {name for name, _, _ in _numeric_options()}
    assert {"study syrenets-speed", "study syrenets-profile", "study overhead", "study adaptation",
            "study residual-acceptance", "study residual-dfki", "study scaling", "run", "fit", "convert"} <= commands


@pytest.mark.parametrize("command, option, value", _numeric_options())
def test_a_bad_number_is_refused_in_one_line_naming_the_option(tmp_path, monkeypatch, capsys, command, option, value):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main([*command.split(), option, value])
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert f"argument {option}" in err and f"got {value}" in err and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []


def test_no_effect_line_of_the_residual_command_ends_in_an_empty_description():
    from bench.cli.residual import effect_line

    law = {"name": "spring", "kind": "conservative", "joints": [2], "parameters": {"k": {"value": 2.0, "stderr": 0.01}}}
    assert effect_line(law) == "spring (conservative) on joint 2: k = 2 ± 0.01"
    bare = {"name": "spring", "kind": "structural", "joints": [2], "parameters": {}, "law": "L += -k*q_2**2/2"}
    assert effect_line(bare) == "spring (structural) on joint 2: L += -k*q_2**2/2"
    assert not effect_line({**bare, "law": ""}).endswith(": ")


def test_every_command_that_runs_jobs_takes_a_cluster_and_select_hands_it_to_its_matrix(tmp_path, monkeypatch):
    from bench.cli import build_parser
    from bench.runner import matrix

    parser = build_parser()
    for argv in (["run", "--systems", "double_pendulum", "--out", "x"], ["select", "--system", "kuka_lwr4", "--out", "x"],
                 *(["study", name] for name in ("adaptation", "generalisation", "residual-acceptance", "residual-dfki",
                                                "scaling", "selection"))):
        args = parser.parse_args([*argv, "--workers", "3", "--cluster", "tcp://scheduler:8786"])
        assert (args.cluster, args.workers) == ("tcp://scheduler:8786", 3), argv

    class Handed(Exception):
        pass

    def run_matrix(specs, out, *, workers=None, cluster=None, **kw):
        raise Handed(cluster, workers, [s.method for s in specs])

    monkeypatch.setattr(matrix, "run_matrix", run_matrix)
    with pytest.raises(Handed) as handed:
        main(["select", "--system", "kuka_lwr4", "--candidates", "standard", "--steps", "1", "--out",
              str(tmp_path / "sel"), "--workers", "3", "--cluster", "tcp://scheduler:8786"])
    assert handed.value.args == ("tcp://scheduler:8786", 3, ["sysid"])


def test_residual_builds_its_system_once_before_its_loop_starts(monkeypatch, tmp_path, system_builds):
    """``bench residual`` builds the system once, of the split it was given, for the checks of its names and of
    the method; the loop's own process builds its own."""
    from bench.residual import job as job_module

    class Started(Exception):
        pass

    def started(job, checked=False, **kwargs):
        raise Started(job.run_spec.system, job.run_spec.split, checked)

    monkeypatch.setattr(job_module, "run_residual", started)
    with pytest.raises(Started) as ran:
        main(["residual", "--system", "kuka_lwr4", "--split", "swapped", "--method", "sysid",
              "--json", str(tmp_path / "loop.json")])
    assert system_builds == [("kuka_lwr4", "swapped")] and ran.value.args == ("kuka_lwr4", "swapped", True)
