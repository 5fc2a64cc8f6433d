"""A model to keep: saved models give the fitted model's torques back, files
that are not such models are refused in one line with nothing written, and the
expressions in a file are read without eval."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
import sympy
from hypothesis import given, settings, strategies as st

from bench.core import expressions, modelfile
from bench.core.csv_format import write_csv
from bench.core.data import generate
from bench.core.expressions import expression_from_json, expression_to_json
from bench.core.modelfile import ModelFileError
from methods import METHODS
from methods.saving import TOLERANCE, held_out, load_model, save_model
from systems import SYSTEMS
from bench.core.scoring import opened
from tests.commandline import cli
from bench.core.budget import Budget

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def kuka():
    system = SYSTEMS["kuka_lwr4"]()
    return system, system.load("train").subset(slice(0, 600)), opened(system.load("test")).subset(slice(0, 300))


@pytest.mark.parametrize("name,settings_,steps", [
    ("sysid", {}, 1), ("sysid", {"feasible": False, "friction": True}, 1), ("feasible+gp", {"inducing": 8}, 3),
    ("standard+mlp", {"hidden": 8, "layers": 2}, 3), ("feasible+delan", {"hidden": 8, "compile": False}, 3),
    ("standard+sparse_torque", {}, 1)])
def test_a_saved_arm_model_predicts_the_fitted_torques(tmp_path, kuka, name, settings_, steps):
    system, train, test = kuka
    fitted = METHODS[name](**settings_).fit(train, "indirect", 0, budget=Budget(steps=steps), system=system)
    check = save_model(fitted, tmp_path / "m.npz", {"system": system.name, "method": name}, train, system)
    assert check["largest_relative_difference"] <= TOLERANCE
    loaded, header = load_model(tmp_path / "m.npz")
    expected = fitted.predict_torque(test)
    assert np.max(np.abs(loaded.predict_torque(test) - expected)) <= TOLERANCE * np.max(np.abs(expected))
    assert header["method"] == name and header["dof"] == 7


def test_a_tuned_models_file_keeps_its_held_out_predictions_and_predict_ignores_them(tmp_path, kuka):
    system, train, test = kuka
    fitted = METHODS["sysid"]().fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    kept = {"index": np.arange(5, dtype=np.int64), "fold": np.array([0, 0, 1, 1, 1]),
            "prediction": np.arange(35, dtype=np.float32).reshape(5, 7)}
    save_model(fitted, tmp_path / "m.npz", {"system": system.name, "method": "sysid"}, train, system, kept)
    back = held_out(tmp_path / "m.npz")
    for name, value in kept.items():
        np.testing.assert_array_equal(back[name], value)
    loaded, header = load_model(tmp_path / "m.npz")
    np.testing.assert_array_equal(loaded.predict_torque(test), fitted.predict_torque(test))
    save_model(fitted, tmp_path / "plain.npz", {"system": system.name, "method": "sysid"}, train, system)
    assert held_out(tmp_path / "plain.npz") is None  # an untuned fit keeps none
    # a file whose held-out arrays disagree in length is refused in one line
    short = dict(kept, fold=kept["fold"][:3])
    save_model(fitted, tmp_path / "bad.npz", {"system": system.name, "method": "sysid"}, train, system, short)
    with pytest.raises(ModelFileError, match="bad.npz: its held-out predictions' arrays differ in length"):
        held_out(tmp_path / "bad.npz")


GOOD = {"index": np.arange(4), "fold": np.array([0, 0, 1, 1]), "prediction": np.zeros((4, 7), np.float32)}


@pytest.mark.parametrize("crafted,why", [
    ({"index": np.array([0, -1, 2, 3])}, "its held-out index is not a list of sample numbers"),
    ({"index": np.arange(4.0)}, "its held-out index is not a list of sample numbers"),
    ({"fold": np.zeros((2, 2), np.int64)}, "its held-out fold is not a list of sample numbers"),
    ({"fold": np.array(["a", "b", "c", "d"])}, "its held-out fold is not a list of sample numbers"),
    ({"prediction": np.full((4, 7), np.nan)}, "its array a[0-9]+ holds a number that is not finite"),
    ({"prediction": np.zeros((4, 7, 1))}, "its held-out predictions are not finite numbers a sample"),
    ({"prediction": np.zeros((3, 7))}, "its held-out predictions' arrays differ in length"),
])
def test_crafted_held_out_predictions_are_refused_in_one_line(tmp_path, kuka, crafted, why):
    system, train, _ = kuka
    fitted = METHODS["sysid"]().fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    save_model(fitted, tmp_path / "m.npz", {"system": system.name, "method": "sysid"}, train, system, GOOD)
    header, arrays = _contents(tmp_path / "m.npz")
    for name, value in crafted.items():  # a stranger's arrays, the file sealed again
        arrays[header["held_out"][name]["$array"]] = value
    _write(tmp_path / "m.npz", header, arrays)
    with pytest.raises(ModelFileError, match=f"m.npz: {why}"):
        held_out(tmp_path / "m.npz")


def _contents(path: Path) -> tuple[dict, dict]:
    with zipfile.ZipFile(path) as z:
        header = json.loads(z.read(modelfile.HEADER))
        arrays = {n[:-4]: np.load(io.BytesIO(z.read(n)), allow_pickle=False) for n in z.namelist()
                  if n != modelfile.HEADER}
    return header, arrays


def _write(path: Path, header: dict, arrays: dict, seal: bool = True) -> None:
    """A model file of ``header`` and ``arrays``, its digest made again where ``seal`` (a stranger who edits a
    file and seals it), left as it was otherwise."""
    if seal:
        header = {**header, "digest": modelfile.digest(header, arrays)}
    with zipfile.ZipFile(path, "w") as z:
        z.writestr(modelfile.HEADER, json.dumps(header))
        for name, array in arrays.items():
            buffer = io.BytesIO()
            np.save(buffer, array, allow_pickle=False)
            z.writestr(f"{name}.npy", buffer.getvalue())


def test_a_model_file_edited_since_it_was_saved_or_with_absurd_numbers_predicts_nothing(tmp_path, kuka):
    """An edit the file was not saved with is refused by its digest; sealed again, coefficients of 1e200 are
    refused as past the bound a number may have, and coefficients times 1e3 by the torque bound the file
    states; predict writes nothing and says which, in one line."""
    system, train, test = kuka
    fitted = METHODS["sysid"]().fit(train, "indirect", 0, budget=Budget(steps=1), system=system)
    save_model(fitted, tmp_path / "m.npz", {"system": system.name, "method": "sysid"}, train, system)
    log = tmp_path / "log.csv"
    write_csv(test, log)
    good = cli("predict", "--model", tmp_path / "m.npz", "--log", log, "--out", tmp_path / "p.csv")
    assert good.returncode == 0, good.stderr
    header, arrays = _contents(tmp_path / "m.npz")
    assert len(header["torque_bound"]) == 7 and header["digest"] == modelfile.digest(header, arrays)
    np.testing.assert_allclose(header["torque_bound"], 100 * np.max(np.abs(train.tau), axis=0))
    largest = header["model"]["coef"]["$array"]  # the linear model's coefficients
    for factor, seal, why in ((1e3, False, "its contents differ from the digest it was saved with"),
                              (1e200, True, f"its array {largest} holds .*, past the 1e\\+12 a model's number may be"),
                              (1e3, True, "predicts .* on joint [0-9] at row [0-9]+ of .*, past the bound of .* its "
                                          "file states \\(100 times the largest torque")):
        edited = tmp_path / f"edited_{factor:g}_{seal}.npz"
        _write(edited, header, {**arrays, largest: arrays[largest] * factor}, seal=seal)
        out = tmp_path / "q.csv"
        r = cli("predict", "--model", edited, "--log", log, "--out", out)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and not out.exists(), (factor, seal, r.stderr)
        assert re.search(why, r.stderr), r.stderr


@pytest.mark.parametrize("name", ["sparse", "mggp", "mlp", "delan"])
def test_a_saved_lagrangian_predicts_the_fitted_torques(tmp_path, name):
    system = SYSTEMS["double_pendulum"]()
    train, test = generate(system, 200, 0), generate(system, 100, 1)
    smoke = {**METHODS[name].smoke_config(), **({"samples": 64} if name == "sparse" else {})}
    fitted = METHODS[name](**smoke).fit(train, "indirect", 0, budget=Budget(steps=smoke["max_steps"]))
    save_model(fitted, tmp_path / "m.npz", {"system": system.name, "method": name}, train, system)
    loaded, _ = load_model(tmp_path / "m.npz")
    expected = fitted.predict_torque(test)
    assert np.max(np.abs(loaded.predict_torque(test) - expected)) <= TOLERANCE * np.max(np.abs(expected))


def test_a_model_that_cannot_be_saved_writes_nothing(tmp_path):
    system = SYSTEMS["double_pendulum"]()
    train = generate(system, 64, 0)
    smoke = METHODS["syrenets"].smoke_config()
    fitted = METHODS["syrenets"](**smoke).fit(train, "indirect", 0, budget=Budget(steps=2))
    with pytest.raises(ValueError, match="cannot be saved"):
        save_model(fitted, tmp_path / "m.npz", {"system": system.name}, train, system)
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A saved model of the double pendulum, the generated test log, and the run's record."""
    folder = tmp_path_factory.mktemp("saved")
    for part, seed in (("train", 0), ("test", 1000)):
        assert cli("data", "--system", "double_pendulum", "--n", 300, "--seed", seed, "--out",
                   folder / f"{part}.csv").returncode == 0
    r = cli("fit", "--system", "double_pendulum", "--method", "sparse", "--experiment", "indirect", "--train",
            folder / "train.csv", "--test", folder / "test.csv", "--steps", 1, "--set", "samples=128",
            "--save", folder / "model.npz", "--json", folder / "run.json")
    assert r.returncode == 0 and "model written to" in r.stdout, r.stderr
    return folder


def test_predict_gives_the_runs_test_mse_and_writes_the_torques(saved, tmp_path):
    r = cli("predict", "--model", saved / "model.npz", "--log", saved / "test.csv", "--out", tmp_path / "p.csv")
    assert r.returncode == 0, r.stderr
    record = json.loads((saved / "run.json").read_text())
    shown = float(r.stdout.split("torque MSE ")[1].split()[0])
    assert shown == pytest.approx(record["test_mse"], rel=1e-5)
    assert record["details"]["saved"]["largest_relative_difference"] <= TOLERANCE
    header = (tmp_path / "p.csv").read_text().splitlines()[0]
    assert header == "tau_hat_1,tau_hat_2" and len((tmp_path / "p.csv").read_text().splitlines()) == 301


def test_predict_imports_the_plugin_that_registers_the_models_method(saved, tmp_path):
    plugin = ROOT / "tests" / "plugins" / "penalised.py"
    model = tmp_path / "penalised.npz"
    r = cli("fit", "--system", "double_pendulum", "--method", "penalised_mlp", "--experiment", "indirect", "--train",
            saved / "train.csv", "--steps", 2, "--plugin", plugin, "--save", model)
    assert r.returncode == 0, r.stderr
    # in a fresh interpreter: this one has imported the plugin for the fit
    p = subprocess.run([sys.executable, "-m", "bench", "predict", "--model", str(model), "--log",
                        str(saved / "test.csv"), "--out", str(tmp_path / "p.csv"), "--plugin", str(plugin)],
                       capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0, p.stderr
    assert len((tmp_path / "p.csv").read_text().splitlines()) == 301


def test_predict_refuses_a_system_the_model_was_not_fitted_on_in_one_line(saved, tmp_path):
    urdf = ROOT / "systems" / "data" / "ur5_robot.urdf.gz"
    r = cli("predict", "--model", saved / "model.npz", "--log", saved / "test.csv", "--out", tmp_path / "p.csv",
            "--system", f"urdf:{urdf}")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "the model was fitted on 'double_pendulum', not on --system's 'urdf_ur5_robot" in r.stderr
    assert not (tmp_path / "p.csv").exists()


def _refused(path, log, tmp_path):
    out = tmp_path / "p.csv"
    r = cli("predict", "--model", path, "--log", log, "--out", out)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and str(path) in r.stderr
    assert not out.exists()
    return r.stderr


def test_a_truncated_a_broken_and_a_foreign_file_are_each_refused_in_one_line(saved, tmp_path):
    whole = (saved / "model.npz").read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(whole[: len(whole) // 2])
    assert "truncated" in _refused(truncated, saved / "test.csv", tmp_path)
    broken = tmp_path / "broken.npz"  # the archive is whole, its description no longer parses
    with zipfile.ZipFile(saved / "model.npz") as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            dst.writestr(item, data[:-20] if item == modelfile.HEADER else data)
    assert "does not parse" in _refused(broken, saved / "test.csv", tmp_path)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, weights=np.ones(3))
    assert "not a model file" in _refused(foreign, saved / "test.csv", tmp_path)
    assert "not a model file" in _refused(saved / "test.csv", saved / "test.csv", tmp_path)
    hostile = tmp_path / "hostile.npz"  # an expression naming a function outside the fixed list
    header, arrays = _contents(saved / "model.npz")
    header["model"]["expression"] = {"op": "__import__", "args": [{"symbol": "os"}]}
    _write(hostile, header, arrays, seal=False)
    assert "differ from the digest it was saved with" in _refused(hostile, saved / "test.csv", tmp_path)
    _write(hostile, header, arrays)  # sealed again by whoever wrote it: the expression's own check refuses it
    assert "which is no operation a model file may hold" in _refused(hostile, saved / "test.csv", tmp_path)


_symbols = [sympy.Symbol(n, real=True) for n in ("q_1", "q_2", "qd_1", "qd_2")]


def _apply(name: str, arg):
    """``name(arg)``, or ``arg`` where sympy refuses the value (Heaviside of a complex number)."""
    try:
        return expressions.FUNCTIONS[name](arg)
    except (ValueError, TypeError):
        return arg


_leaves = st.one_of(st.sampled_from(_symbols), st.floats(-1e6, 1e6, allow_nan=False).map(sympy.Float),
                    st.integers(-50, 50).map(sympy.Integer), st.fractions(max_denominator=9).map(sympy.Rational))
_expressions = st.recursive(_leaves, lambda inner: st.one_of(
    st.tuples(inner, inner).map(lambda a: a[0] + a[1]), st.tuples(inner, inner).map(lambda a: a[0] * a[1]),
    st.tuples(inner, st.integers(-3, 3)).map(lambda a: a[0] ** a[1]),
    st.tuples(st.sampled_from(sorted(expressions.FUNCTIONS)), inner).map(lambda a: _apply(*a))),
    max_leaves=8)


@settings(max_examples=60, deadline=None)
@given(expr=_expressions)
def test_an_expression_reads_back_exactly_from_its_json(expr):
    try:
        tree = expression_to_json(expr)
    except ValueError:  # zoo, nan, a float beyond a double: refused by name
        return
    assert expression_from_json(json.loads(json.dumps(tree))) == expr


def test_a_float_beyond_a_double_is_refused_at_once_without_its_digits():
    huge = sympy.Float(1e6) ** 3 ** 6  # a float of 10^4374: printing its digits takes minutes
    with pytest.raises(ValueError, match=r"holds a float about 10\^4374, beyond a double"):
        expression_to_json(huge * _symbols[0])


def test_an_expression_node_outside_the_fixed_list_is_refused():
    for tree in ({"op": "eval", "args": []}, {"symbol": "__class__.__bases__"}, {"float": "1e999x"}, [1, 2],
                 {"symbol": "q_1", "assumptions": {"commutative": "yes"}}):
        with pytest.raises(ModelFileError):
            expression_from_json(tree)


def test_every_named_law_of_the_arm_saves_and_reads_back():
    # the residual loop's model file holds each law's expression: a law the vocabulary lacks (the Stribeck
    # hump's erf) would fail the loop's save after its fit
    from bench.physics.effects import EFFECTS
    from bench.physics.models import term_from_json, term_to_json

    for name, effect in EFFECTS.items():
        if effect.arity == 0 or effect.sensor:  # a law of the whole system, or of the sensor: no term of a joint
            continue
        shape = None if not effect.shaped else 3.0 if effect.shaped == "N" else 0.1  # a period count is whole
        term = effect.term(*range(effect.arity), shape=shape)
        back = term_from_json(json.loads(json.dumps(term_to_json(term))), "test")
        assert back.expr == term.expr, name
