"""The laws of the torque sensor and of the drive: a gain relative to a
reference joint, an offset beside it, a time shift between torque and state,
and a torque that repeats N times a revolution; each found with its
parameters, and none where it was not put in."""

from __future__ import annotations

from bench.core.budget import Budget
import numpy as np
import pytest

from bench.core.data import Dataset, add_noise, generate
from bench.physics.undeclared import add_effects, parse_effects
from bench.core.errors import ConfigError
from bench.tools.robot_log import simulate
from bench.residual import residual_loop
from bench.physics.sensor_laws import shifted
from bench.residual.sensors import Sensed, Sensor
from systems import get_system

#: every loop here is bounded by work (see tests/residual/test_loop.py)
SYSID = 1000


def quiet(_line):
    pass


def generated(items, n=3000, noise=0.0, seed=0):
    s = get_system("double_pendulum")
    fx = parse_effects(items, 2)
    train = add_effects(generate(s, n, seed), fx, s)
    test = add_effects(generate(s, n // 2, 1000 + seed), fx, s)
    if noise:
        train, test = add_noise(train, "indirect", noise, seed), add_noise(test, "indirect", noise, 1000 + seed)
    return train, test


def laws(out) -> dict:
    return {(e["name"], tuple(e["joints"])): e for e in out.effects if e["kind"] not in ("structural", "beyond_data",
                                                                                          "not_identified")}


def test_the_generator_applies_a_gain_to_the_torque_of_the_arm_and_its_other_effects():
    s = get_system("double_pendulum")
    clean = generate(s, 50, 0)
    both = add_effects(clean, parse_effects(["torque_gain=1,1.05", "offset=0,0.2"], 2), s)
    np.testing.assert_allclose(both.tau[:, 0], clean.tau[:, 0])
    np.testing.assert_allclose(both.tau[:, 1], 1.05 * (clean.tau[:, 1] + 0.2))
    np.testing.assert_allclose(both.L, clean.L)  # a sensor does not change the arm's L
    with pytest.raises(ConfigError, match=r"torque_gain needs 2 coefficients with g > 0, one per joint \(g = 1: none\)"):
        parse_effects(["torque_gain=1,0"], 2)
    with pytest.raises(ConfigError, match="robot-log --torque-delay"):
        parse_effects(["time_shift=0.01"], 2)


@pytest.mark.parametrize("method", ["sysid", "sparse"])
def test_a_sensor_that_reads_low_is_a_gain_within_one_percent_not_an_armature(method):
    train, test = generated(["torque_gain=1,0.96"], noise=0.01)
    out = residual_loop(method, train, test, budget=Budget(steps=SYSID), report=quiet)
    found = laws(out)
    assert list(found) == [("torque_gain", (2,))]
    gain = found[("torque_gain", (2,))]
    assert gain["reference_joint"] == 1 and "gauge" not in gain["reference"]  # the reason is in words
    assert gain["parameters"]["g"]["value"] == pytest.approx(0.96, rel=0.01)
    assert out.mse_after["test"] < out.mse_before["test"]


def test_a_gain_and_an_offset_on_one_joint_compose():
    train, test = generated(["torque_gain=1,1.05", "offset=0,0.2"], noise=0.01)
    found = laws(residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet))
    assert set(found) == {("torque_gain", (2,)), ("offset", (2,))}
    assert found[("torque_gain", (2,))]["parameters"]["g"]["value"] == pytest.approx(1.05, rel=0.01)
    assert found[("offset", (2,))]["parameters"]["tau_0"]["value"] == pytest.approx(0.2, rel=0.05)


def test_the_reference_is_the_joint_with_the_largest_torque_and_gains_are_relative_to_it():
    train, test = generated(["torque_gain=0.9,0.9"])  # a common gain: a rescaling of L, nothing to find
    assert Sensor.exact(train).reference == int(np.argmax(np.sqrt(np.mean(train.tau**2, axis=0))))
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    assert not laws(out) and out.mse_after["test"] < 1e-12


def test_a_periodic_torque_is_one_law_with_its_amplitude_periods_and_phase():
    train, test = generated(["periodic_torque=1:0.3,6,0.5"])
    found = laws(residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet))
    assert list(found) == [("periodic_torque", (1,))]
    p = {k: v["value"] for k, v in found[("periodic_torque", (1,))]["parameters"].items()}
    assert p["N"] == 6 and p["A"] == pytest.approx(0.3, rel=1e-6) and p["phi"] == pytest.approx(0.5, rel=1e-6)


def test_coulomb_friction_that_entered_alone_takes_its_viscous_part_at_five_percent_noise():
    # the viscous part is a small share of a residual that is mostly noise: the held-out gain it
    # brings is a few rows' worth, not 1 % of the residual
    train, test = generated(["viscous_friction=0.8,0.5", "coulomb_friction=1.5,0.7"], n=4000, noise=0.05)
    found = laws(residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet))
    assert set(found) == {("coulomb_viscous_friction", (1,)), ("coulomb_viscous_friction", (2,))}
    for j, (F_c, b) in ((1, (1.5, 0.8)), (2, (0.7, 0.5))):
        p = found[("coulomb_viscous_friction", (j,))]["parameters"]
        assert p["F_c"]["value"] == pytest.approx(F_c, rel=0.15) and p["b"]["value"] == pytest.approx(b, rel=0.15)


def test_shifted_states_are_the_recording_at_an_earlier_time():
    t = np.arange(400) / 100.0
    q = np.sin(t)[:, None]
    data = Dataset(q, np.cos(t)[:, None], -np.sin(t)[:, None], np.zeros((400, 1)), None, "x", "x",
                   recording=np.asarray(["a"] * 400), time=t)
    moved = shifted(data, 0.005)
    inner = slice(1, -1)  # held at the recording's first sample
    np.testing.assert_allclose(moved.q[inner, 0], np.sin(t[inner] - 0.005), atol=2e-5)
    np.testing.assert_allclose(moved.qd[inner, 0], np.cos(t[inner] - 0.005), atol=2e-5)
    assert moved.tau is data.tau


def test_a_five_millisecond_delay_of_a_logged_torque_is_found_within_one_millisecond():
    def log(seeds):
        parts = []
        for k in seeds:
            time, d = simulate("double_pendulum", 8.0, 100.0, 0.2, [], 0.01, k, torque_delay=0.005)
            parts.append(d.replace(recording=np.asarray([f"r{k}"] * len(d)), trajectory=np.asarray([f"r{k}"] * len(d)),
                                   time=time))
        return _stack(parts)

    train = log([0, 1, 2])
    out = residual_loop("sysid", train, None, budget=Budget(steps=SYSID), report=quiet)  # no test: no driven rollouts to wait for
    shift = laws(out)[("time_shift", (1, 2))]
    assert shift["parameters"]["delta"]["value"] == pytest.approx(0.005, abs=0.001)
    assert set(shift["per_recording"]) == {"r0", "r1", "r2"}
    assert out.mse_after["train"] < 0.5 * out.mse_before["train"]
    # the model it ends with predicts the measured torque: the arm's, delayed
    assert isinstance(out.models[1], Sensed) and out.models[1].sensor.laws[-1].value == shift["parameters"]["delta"]["value"]


def _stack(parts: list[Dataset]) -> Dataset:
    first = parts[0]
    join = lambda name: np.concatenate([getattr(p, name) for p in parts])  # noqa: E731
    return Dataset(join("q"), join("qd"), join("qdd"), join("tau"), None, first.system, first.source,
                   recording=join("recording"), trajectory=join("trajectory"), time=join("time"))


def test_a_gain_the_residual_asks_to_be_far_from_one_is_a_finding_not_a_law():
    # a torque on joint 2 that the model's own torque there does not resemble, five times as large
    train, test = generated(["torque_gain=1,6"])
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    assert ("torque_gain", (2,)) not in laws(out)


def test_on_one_measured_trajectory_a_sensor_law_is_judged_on_held_out_regions_of_its_states():
    # one trajectory has no other to confirm a gain by; the loop's held-out regions of its states do: a gain
    # the arm's torque holds predicts the regions it was not fitted on, and stays with its value
    time, d = simulate("double_pendulum", 8.0, 100.0, 0.2, ["torque_gain=1,0.9"], 0.01, 0)
    one = d.replace(recording=np.asarray(["r0"] * len(d)), trajectory=np.asarray(["A"] * len(d)), time=time)
    out = residual_loop("sysid", one, None, budget=Budget(steps=SYSID), report=quiet)
    gain = laws(out)[("torque_gain", (2,))]
    assert gain["kind"] == "sensor" and gain["parameters"]["g"]["value"] == pytest.approx(0.9, abs=0.01)


def test_the_generator_adds_load_dependent_friction_to_the_arm_torque_before_the_gain():
    s = get_system("double_pendulum")
    clean = generate(s, 50, 0)
    both = add_effects(clean, parse_effects(["load_friction=0.1,0", "torque_gain=1,1.05", "offset=0.2,0"], 2), s)
    arm = clean.tau[:, 0] + 0.2
    np.testing.assert_allclose(both.tau[:, 0], arm + 0.1 * np.abs(arm) * np.sign(clean.qd[:, 0]))
    np.testing.assert_allclose(both.tau[:, 1], 1.05 * clean.tau[:, 1])


@pytest.mark.parametrize("method", ["sysid", "sparse"])
def test_a_coulomb_level_that_grows_with_the_load_is_load_dependent_friction(method):
    train, test = generated(["load_friction=0.1,0"], noise=0.01)
    out = residual_loop(method, train, test, budget=Budget(steps=SYSID), report=quiet)
    found = laws(out)
    assert list(found) == [("load_friction", (1,))]
    entry = found[("load_friction", (1,))]
    assert entry["kind"] == "drive" and "|tau_1|*sign(qd_1)" in entry["law"]
    assert entry["parameters"]["mu"]["value"] == pytest.approx(0.1, rel=0.05)
    assert out.mse_after["test"] < 0.05 * out.mse_before["test"]
    # the model it ends with reads the arm's torque through the drive: the measured torque
    np.testing.assert_allclose(out.models[1].predict_torque(test), test.tau, atol=5 * np.sqrt(out.mse_after["test"]))


def test_a_coulomb_level_that_does_not_grow_with_the_load_stays_coulomb_friction():
    train, test = generated(["coulomb_friction=1.5,0.7"], noise=0.01)
    found = laws(residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet))
    assert set(found) == {("coulomb_friction", (1,)), ("coulomb_friction", (2,))}


def test_a_friction_that_falls_with_the_load_is_a_finding_not_a_law():
    # the torque a drive reads is less where it moves the load than where the load moves it: no
    # friction does that, so a negative mu is reported and not added
    s = get_system("double_pendulum")
    train, test = generate(s, 3000, 0), generate(s, 1500, 1000)
    train, test = (d.replace(tau=d.tau - 0.15 * np.abs(d.tau) * np.sign(d.qd) * np.asarray([1.0, 0.0]))
                   for d in (train, test))
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    assert ("load_friction", (1,)) not in laws(out)
    (entry,) = [e for e in out.effects if e["name"] == "load_friction"]
    assert entry["kind"] == "structural" and "0 <= mu <= 0.5" in entry["finding"]


def test_a_drive_law_found_first_is_settled_again_when_a_later_round_adds_friction_beside_it():
    # load-dependent friction enters first and takes the constant Coulomb level in as well (mu too high);
    # when Coulomb friction enters in the next round, mu must be fitted again beside it, or the loop ends
    # with both wrong on noise-free data
    train, test = generated(["load_friction=0.1,0", "coulomb_friction=0.5,0"])
    out = residual_loop("sysid", train, test, budget=Budget(steps=SYSID), report=quiet)
    found = laws(out)
    assert found[("load_friction", (1,))]["parameters"]["mu"]["value"] == pytest.approx(0.1, rel=1e-6)
    assert found[("coulomb_friction", (1,))]["parameters"]["F_c"]["value"] == pytest.approx(0.5, rel=1e-6)
    assert out.mse_after["test"] < 1e-12


def test_a_sensed_models_mass_matrix_and_bias_read_the_arms_own_through_the_sensor():
    """Read through a gain and a load-dependent friction (not affine in the torque), the measured torque's M and
    c are what the torque at dof + 1 accelerations a state gives; the arm's torques there come from its own M
    and c, never from its torque. A time shift leaves states without time stamps as they are."""
    from bench.physics.models import FittedModel
    from bench.physics.sensor_laws import LoadFriction, TimeShift, TorqueGain

    class Arm(FittedModel):  # tau = M(q) qdd + c(q, qd), counting what it is asked
        asked = {"torque": 0, "mass_and_bias": 0}

        def parts(self, q, qd):
            M = np.stack([np.stack([2 + np.cos(q[:, 1]), 0.3 + 0 * q[:, 0]], -1),
                          np.stack([0.3 + 0 * q[:, 0], 1 + 0.5 * np.sin(q[:, 0]) ** 2], -1)], 1)
            c = np.stack([qd[:, 0] * qd[:, 1] - 9.8 * np.sin(q[:, 0]), qd[:, 0] ** 2 + 2 * np.cos(q[:, 1])], -1)
            return M, c

        def predict_torque(self, data):
            self.asked["torque"] += 1
            M, c = self.parts(data.q, data.qd)
            return np.einsum("nij,nj->ni", M, data.qdd) + c

        def mass_and_bias(self, q, qd):
            self.asked["mass_and_bias"] += 1
            return self.parts(q, qd)

        def predict_lagrangian(self, data):
            raise NotImplementedError

    rng = np.random.default_rng(0)
    q, qd = rng.normal(size=(40, 2)), rng.normal(size=(40, 2))
    sensor = Sensor(0, (TorqueGain(1, 1.07), LoadFriction(0, 0.2), TimeShift(None, 0.01)))
    sensed = Sensed(Arm(), sensor)
    M, c = sensed.mass_and_bias(q, qd)
    assert Arm.asked == {"torque": 0, "mass_and_bias": 1}
    M_ref, c_ref = FittedModel.mass_and_bias(sensed, q, qd)  # the torque at dof + 1 accelerations a state
    np.testing.assert_allclose(M, M_ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(c, c_ref, rtol=1e-12, atol=1e-12)
    assert np.abs(M - Arm().parts(q, qd)[0]).max() > 0.01  # the sensor's laws are in it
    plain = Sensed(Arm(), Sensor(0)).mass_and_bias(q, qd)  # a sensor without laws: the arm's own
    np.testing.assert_array_equal(plain[0], Arm().parts(q, qd)[0])
    np.testing.assert_array_equal(plain[1], Arm().parts(q, qd)[1])


def test_a_sensed_model_predicts_a_sealed_test_split_without_reading_its_targets():
    """A law of the sensor that reads the torque (a gain, load-dependent friction) reads the torques the model
    predicts, never the test split's own, and a time shift moves its states without reading them: predicting
    a sealed split outside scoring gives the plain split's torques, and the states moved stay sealed."""
    from bench.core.sealed import SealedRead, SealedSplit, seal
    from bench.physics.models import ExpressionModel
    from bench.physics.sensor_laws import LoadFriction, TimeShift, TorqueGain

    system = get_system("double_pendulum")
    time, test = simulate("double_pendulum", 2.0, 100.0, 0.5, [], 0.0, 3)
    test = test.replace(recording=np.full(len(test), "r0"), time=time)
    arm = ExpressionModel(system.lagrangian_sympy, 2)
    sensed = Sensed(arm, Sensor(0, (TorqueGain(1, 1.07), LoadFriction(0, 0.2), TimeShift(None, 0.02))))
    expected = sensed.predict_torque(test)
    np.testing.assert_array_equal(sensed.predict_torque(seal(test)), expected)
    assert np.abs(expected - arm.predict_torque(test)).max() > 0.01  # the laws are in it
    moved = shifted(seal(test), 0.02)
    assert isinstance(moved, SealedSplit) and not np.array_equal(moved.q, test.q)
    with pytest.raises(SealedRead):
        moved.tau
