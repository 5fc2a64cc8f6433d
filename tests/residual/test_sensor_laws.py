"""A law of the sensor or the drive is one class: a new one, in a plugin
file (tests/plugins/speed_loss.py, the example of docs/extending.md) and
nowhere in the loop, is offered, fitted, checked for its range and
reported by the loop as the built-in ones are."""

from __future__ import annotations

from bench.core.budget import Budget
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.core.data import generate
from bench.residual import residual_loop
from bench.physics.laws import LAWS
from bench.physics.sensor_laws import SensorLaw, register
from bench.residual.sensors import Sensed, Sensor
from systems import get_system

SYSID = 1000
PLUGIN = Path(__file__).parents[1] / "plugins" / "speed_loss.py"


@pytest.fixture
def speed_loss():
    """The plugin's law, registered for one test (importing the plugin registers it)."""
    sys.modules.pop("speed_loss_plugin", None)
    spec = importlib.util.spec_from_file_location("speed_loss_plugin", PLUGIN)
    module = importlib.util.module_from_spec(spec)
    sys.modules["speed_loss_plugin"] = module  # as a plugin is imported: once, so that --plugin finds it imported
    spec.loader.exec_module(module)
    yield module.SpeedLoss
    LAWS.remove(module.SpeedLoss.name)
    sys.modules.pop("speed_loss_plugin", None)


def drive(data, c):
    return data.replace(tau=data.tau * (1.0 + np.asarray(c) * np.abs(data.qd)))


def laws(out) -> dict:
    return {(e["name"], tuple(e["joints"])): e for e in out.effects
            if e["kind"] not in ("structural", "beyond_data", "not_identified")}


def test_a_registered_law_of_the_drive_is_found_with_its_value_and_read_through(speed_loss):
    s = get_system("double_pendulum")
    train, test = drive(generate(s, 3000, 0), [0.1, 0.0]), drive(generate(s, 1500, 1000), [0.1, 0.0])
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=lambda line: None)
    found = laws(out)
    assert list(found) == [("speed_loss", (1,))]
    entry = found[("speed_loss", (1,))]
    assert entry["kind"] == "drive" and entry["law"] == "tau_measured_1 = (1 + c*|qd_1|)*tau_1"
    assert entry["parameters"]["c"]["value"] == pytest.approx(0.1, rel=1e-4)
    assert out.mse_after["test"] < 1e-12 < out.mse_before["test"]
    assert isinstance(out.models[1], Sensed)
    np.testing.assert_allclose(out.models[1].predict_torque(test), test.tau, atol=1e-5)


def test_a_registered_law_outside_its_range_is_a_finding(speed_loss):
    s = get_system("double_pendulum")
    train, test = drive(generate(s, 3000, 0), [-0.1, 0.0]), drive(generate(s, 1500, 1000), [-0.1, 0.0])
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=lambda line: None)
    assert ("speed_loss", (1,)) not in laws(out)
    (entry,) = [e for e in out.effects if e["name"] == "speed_loss" and e["joints"] == [1]]
    assert entry["kind"] == "structural" and "0 <= c <= 0.5" in entry["finding"] and "c = -0.1" in entry["finding"]


def test_a_sensor_offers_each_registered_law_where_it_applies(speed_loss):
    train = generate(get_system("double_pendulum"), 50, 0)
    sensor = Sensor.exact(train)
    names = [(t.name, t.joint) for t in sensor.terms(train)]
    assert names == [("torque_gain", 1 - sensor.reference), ("load_friction", 0), ("load_friction", 1),
                     ("speed_loss", 0), ("speed_loss", 1)]  # no time stamps: no time shift


def test_a_sensor_law_is_declared_once_on_its_class_and_its_effect_follows_it():
    """The built-in laws' effects are their classes' (effects.py declares none of the sensor's); a class that
    carries an effect brings it with its registration and takes it away with its removal."""
    import sympy

    from bench.physics.effects import EFFECTS, Effect
    from bench.physics.sensor_laws import GAIN_RANGE, JointTorqueLaw, TorqueGain

    sensor = {name for name, e in EFFECTS.items() if e.sensor}
    assert sensor == {name for name, law in LAWS.sensor.items() if law.effect is not None} >= {
        "torque_gain", "load_friction", "time_shift"}
    assert all(EFFECTS[name] is LAWS.sensor[name].effect for name in sensor)
    assert GAIN_RANGE == TorqueGain.bounds == (0.8, 1.25) and TorqueGain.term(2, 7) == EFFECTS["torque_gain"].term(2)

    class Creep(JointTorqueLaw):
        effect = Effect("creep", lambda q, qd: sympy.Symbol("tau" + str(q[0])[1:], real=True), "sensor", "c",
                        "tau_measured = (1 + c)·tau", bounds=(0.0, 0.1))
        name, parameter = "creep", "c"

    register(Creep)
    try:
        assert EFFECTS["creep"] is Creep.effect and Creep.term(0, 2).name == "creep"
    finally:
        LAWS.remove("creep")
    assert "creep" not in EFFECTS and "creep" not in LAWS.sensor
    with pytest.raises(ValueError, match="its name and the place"):
        register(type("Mislabelled", (JointTorqueLaw,), {"name": "mislabelled", "effect": Creep.effect}))
    assert "mislabelled" not in LAWS.sensor


def test_a_law_needs_a_name_of_its_own():
    with pytest.raises(ValueError, match="name of its own"):
        register(type("Gain", (SensorLaw,), {"name": "torque_gain"}))
    with pytest.raises(ValueError, match="name of its own"):
        register(type("Offset", (SensorLaw,), {"name": "offset"}))


def test_a_registered_law_of_the_drive_goes_into_generated_data_as_the_loop_reads_it(speed_loss, tmp_path):
    from bench.core.csv_format import read_csv
    from bench.physics.undeclared import add_effects, parse_effects
    from tests.commandline import cli

    s = get_system("double_pendulum")
    clean = generate(s, 64, 0)
    np.testing.assert_allclose(add_effects(clean, parse_effects(["speed_loss=0.1,0"], 2), s).tau, drive(clean, [0.1, 0]).tau)
    r = cli("data", "--system", "double_pendulum", "--n", "64", "--seed", "0", "--plugin", PLUGIN,
            "--effects", "speed_loss=0.1,0", "--out", tmp_path / "d.csv")
    assert r.returncode == 0, r.stderr
    np.testing.assert_allclose(read_csv(tmp_path / "d.csv").tau, drive(clean, [0.1, 0]).tau, rtol=1e-9)
    bad = cli("data", "--system", "double_pendulum", "--n", "64", "--seed", "0", "--plugin", PLUGIN, "--effects", "speed_loss=0.9,0",
              "--out", tmp_path / "e.csv")
    assert bad.returncode == 2 and "speed_loss needs 2 coefficients with 0 <= c <= 0.5" in bad.stderr
    assert not (tmp_path / "e.csv").exists()
