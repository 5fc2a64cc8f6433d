"""The extension path on the command line: ``--plugin`` on every command that
takes a method or a system, ``--set METHOD.NAME=VALUE`` in a matrix, and the
hint when a method's file was not given."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import tests.test_extension  # noqa: F401  (registers toy_mass_spring and toy_quadratic here, as --plugin does)
from bench.cli import build_parser
from bench.cli.parser import UsageError
from bench.cli.options import hyperparameters
from bench.core.csv_format import read_csv
from tests.commandline import cli

ROOT = Path(__file__).resolve().parent.parent
PLUGIN = ROOT / "tests" / "test_extension.py"


def _options(command: str) -> set[str]:
    (sub,) = [a for a in build_parser()._actions if a.dest == "command"]
    return {s for a in sub.choices[command]._actions for s in a.option_strings}


@pytest.mark.parametrize("command", ["list", "run", "data", "fit", "residual"])
def test_every_command_that_takes_a_method_or_a_system_takes_plugins(command):
    assert "--plugin" in _options(command)


def test_a_fresh_process_lists_a_plugin_and_writes_its_systems_data(tmp_path):
    out = tmp_path / "toy.csv"
    code = ("from bench.cli import main; import sys; "
            f"a = main(['list', '--plugin', {str(PLUGIN)!r}]); "
            f"b = main(['data', '--plugin', {str(PLUGIN)!r}, '--system', 'toy_mass_spring', '--n', '32', '--seed', '3', "
            f"'--out', {str(out)!r}]); sys.exit(a or b)")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "toy_mass_spring" in r.stdout and "toy_quadratic" in r.stdout
    data = read_csv(out)
    assert data.dof == 1 and len(data) == 32


def test_a_method_prefix_sets_that_method_only():
    overrides = [("lr", 0.1), ("mlp.hidden", 8), ("mlp.lr", 0.2), ("sysid.ridge", 1.0)]
    methods = ["mlp", "sysid"]
    assert hyperparameters(overrides, "mlp", methods) == {"lr": 0.2, "hidden": 8}
    assert hyperparameters(overrides, "sysid", methods) == {"lr": 0.1, "ridge": 1.0}
    with pytest.raises(UsageError, match="'sgp' is not a method of this command"):
        hyperparameters([("sgp.alpha", 1)], "mlp", methods)


def test_a_matrix_sets_one_methods_hyperparameter_and_leaves_the_others(tmp_path):
    out = tmp_path / "run"
    r = cli("run", "--systems", "toy_mass_spring", "--methods", "toy_quadratic,mlp", "--experiments", "direct",
            "--seeds", "0", "--steps", "2", "--smoke", "--n-train", "64", "--n-test", "32", "--workers", "1",
            "--no-rollout", "--plugin", PLUGIN, "--set", "toy_quadratic.ridge=0.5", "--set", "mlp.hidden=8", "--out", out)
    assert r.returncode == 0, r.stderr
    records = {json.loads(p.read_text())["method"]: json.loads(p.read_text()) for p in (out / "records").glob("*.json")}
    assert records["toy_quadratic"]["hyperparameters"]["ridge"] == 0.5
    assert "hidden" not in records["toy_quadratic"]["hyperparameters"]
    assert records["mlp"]["hyperparameters"]["hidden"] == 8
    assert "ridge" not in records["mlp"]["hyperparameters"]


def test_a_set_for_a_method_outside_the_matrix_is_one_line(tmp_path):
    r = cli("run", "--methods", "sysid", "--seeds", "0", "--steps", "1", "--set", "mlp.hidden=8", "--out", tmp_path / "run")
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "--set mlp.hidden: 'mlp' is not a method of this command" in r.stderr


def test_an_unknown_method_that_a_file_here_registers_hints_at_plugin(tmp_path):
    (tmp_path / "my_ridge.py").write_text('from methods import METHODS\n\n@METHODS.add("my_ridge", "symbolic")\nclass R: ...\n')
    r = cli("fit", "--system", "double_pendulum", "--method", "my_ridge", "--experiment", "indirect", cwd=tmp_path)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "unknown method 'my_ridge'" in r.stderr
    assert "my_ridge.py names it: add --plugin my_ridge.py" in r.stderr
    hybrid = cli("fit", "--system", "double_pendulum", "--method", "standard+my_ridge", "--experiment", "indirect",
                 cwd=tmp_path)  # the residual is the name the file registers
    assert hybrid.returncode == 2 and hybrid.stderr.count("\n") == 1
    assert "unknown residual learner" in hybrid.stderr and "add --plugin my_ridge.py" in hybrid.stderr
    elsewhere = cli("fit", "--system", "double_pendulum", "--method", "my_ridge", "--experiment", "indirect", cwd=tmp_path.parent)
    assert "needs --plugin FILE.py" in elsewhere.stderr


def test_a_plugin_file_already_imported_by_another_name_or_link_is_not_imported_again(tmp_path):
    """A plugin file that this process imported already (a test runner's import, through a link of another name)
    is the same file: its registrations stand, and importing it as a plugin registers nothing twice."""
    import importlib.util

    from bench.runner.plugins import import_plugins
    from methods import METHODS

    plugin = tmp_path / "my_once_method.py"
    plugin.write_text("from methods.base import METHODS\nfrom tests.test_extension import QuadraticLagrangian\n\n"
                      "METHODS.add('toy_once')(type('ToyOnce', (QuadraticLagrangian,), {}))\n")
    link = tmp_path / "elsewhere.py"
    link.symlink_to(plugin)
    spec = importlib.util.spec_from_file_location("elsewhere_module", link)
    module = importlib.util.module_from_spec(spec)
    sys.modules["elsewhere_module"] = module
    spec.loader.exec_module(module)
    try:
        import_plugins([str(plugin)])  # the same file: not imported again, so 'toy_once' is not registered twice
        assert "toy_once" in METHODS.names()
    finally:
        del sys.modules["elsewhere_module"]
        METHODS.remove("toy_once")
