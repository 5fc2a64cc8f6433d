import math

import numpy as np
import pytest

from bench.core.data import generate
from bench.physics.effects import EFFECTS
from bench.core.errors import ConfigError
from bench.physics.laws import FAMILIES, LAWS, Part, group, led_by, one_law_per_family
from bench.physics.undeclared import GENERATOR_LAWS, add_effects, parse_effects
from systems import get_system


def test_every_law_is_made_of_named_effects_and_its_simpler_laws_exist():
    for law in LAWS.arm.values():
        assert set(law.members) <= set(EFFECTS), law.name
        assert set(law.simpler) <= set(LAWS.arm), law.name
        for part, limits in law.limits.items():
            assert EFFECTS[part].shaped and part in law.required
            assert all(set(limit) <= set(EFFECTS) for limit in limits)
    assert set(FAMILIES.values()) == {"friction", "inertia", "spring", "offset", "periodic"}


def test_only_the_stribeck_law_names_stribeck():
    named = [n for n in list(LAWS.arm) + list(EFFECTS) if "stribeck" in n]
    assert named == ["stribeck_friction", "stribeck_hump"]
    assert led_by("stribeck_hump") is LAWS.arm["stribeck_friction"] and led_by("coulomb_friction") is None


@pytest.mark.parametrize(
    "parts, laws",
    [
        ({"coulomb_friction", "viscous_friction"}, ["coulomb_viscous_friction"]),
        ({"coulomb_friction", "viscous_friction", "stribeck_hump"}, ["stribeck_friction"]),
        ({"stribeck_hump"}, ["stribeck_friction"]),
        ({"smooth_coulomb", "viscous_friction"}, ["smooth_coulomb"]),
        ({"spring", "offset", "armature"}, ["offset_spring", "armature"]),
        ({"coulomb_friction"}, ["coulomb_friction"]),
    ],
)
def test_a_joints_parts_make_the_laws_a_physicist_would_write(parts, laws):
    found = group({n: Part(n, 1.0, 0.3 if EFFECTS[n].shaped else None) for n in sorted(parts)})
    assert sorted(law.name for law, _ in found) == sorted(laws)
    assert sum(len(members) for _, members in found) == len(parts)
    assert one_law_per_family(parts)


def test_two_friction_laws_on_one_joint_are_flagged():
    assert not one_law_per_family({"smooth_coulomb", "stribeck_hump"})
    assert not one_law_per_family({"smooth_coulomb", "coulomb_friction"})


def test_the_reported_parameters_come_from_the_parts():
    stribeck = LAWS.arm["stribeck_friction"].parameters_of({
        "coulomb_friction": Part("coulomb_friction", 1.0, stderr=0.03), "stribeck_hump": Part("stribeck_hump", 1.0, 0.5, 0.04, 0.01)})
    assert stribeck["F_s"] == (2.0, pytest.approx(0.05)) and stribeck["b"] == (0.0, 0.0) and stribeck["v_s"] == (0.5, 0.01)
    spring = LAWS.arm["offset_spring"].parameters_of({"spring": Part("spring", 2.0, stderr=0.1), "offset": Part("offset", -0.6)})
    assert spring["k"] == (2.0, 0.1) and spring["q0"][0] == pytest.approx(0.3)
    assert spring["q0"][1] == pytest.approx(math.hypot(0, 0.6 * 0.1 / 4))


def test_the_generator_adds_a_smoothed_coulomb_law_and_a_spring_at_its_rest_angle():
    data = generate(get_system("double_pendulum"), 300, 0)
    fx = parse_effects(["smooth_coulomb=2:0.7,0.05,0.2", "offset_spring=1:2.0,0.3"], 2)
    assert fx == {"smooth_coulomb": {(1,): (0.7, 0.05, 0.2)}, "offset_spring": {(0,): (2.0, 0.3)}}
    tau = add_effects(data, fx).tau - data.tau
    np.testing.assert_allclose(tau[:, 1], 0.7 * np.tanh(data.qd[:, 1] / 0.05) + 0.2 * data.qd[:, 1], atol=1e-12)
    np.testing.assert_allclose(tau[:, 0], 2.0 * (data.q[:, 0] - 0.3), atol=1e-12)
    assert set(GENERATOR_LAWS) >= {"stribeck_friction", "smooth_coulomb", "offset_spring", "coulomb_viscous_friction"}


@pytest.mark.parametrize(
    "items, message",
    [
        (["smooth_coulomb=1:0.7,0,0"], "not physical: it needs F_c >= 0, v_s > 0"),
        (["smooth_coulomb=1:0.7,0.1"], "needs j:F_c,v_s,b items"),
        (["offset_spring=1:-1,0.2"], "not physical: it needs k >= 0"),
        (["coulomb_viscous_friction=2:1,nan"], "finite numbers"),
    ],
)
def test_a_law_with_wrong_parameters_is_refused_with_one_line(items, message):
    with pytest.raises(ConfigError, match=message):
        parse_effects(items, 2)


def test_a_periodic_torque_is_amplitude_periods_and_phase_of_its_two_parts():
    law = LAWS.arm["periodic_torque"]
    parts = {p.name: p for p in law.parts(0.3, 6, 0.5)}
    assert parts["periodic_sin"].shape == parts["periodic_cos"].shape == 6
    got = law.parameters_of(parts)
    assert got["A"][0] == pytest.approx(0.3) and got["N"][0] == 6 and got["phi"][0] == pytest.approx(0.5)
    # the cosine part alone is the same law at phase pi/2
    (only,) = group({"periodic_cos": Part("periodic_cos", 0.2, 4)})
    assert only[0].name == "periodic_torque"
    assert only[0].parameters_of(only[1])["phi"][0] == pytest.approx(math.pi / 2)
    # the generated torque is A sin(N q + phi) on its joint
    s = get_system("double_pendulum")
    clean = generate(s, 100, 0)
    data = add_effects(clean, parse_effects(["periodic_torque=2:0.3,6,0.5"], 2), s)
    np.testing.assert_allclose(data.tau[:, 1] - clean.tau[:, 1], 0.3 * np.sin(6 * clean.q[:, 1] + 0.5), atol=1e-12)
    np.testing.assert_allclose(data.tau[:, 0], clean.tau[:, 0], atol=1e-12)
